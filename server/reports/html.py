"""A plan's report as one self-contained HTML page.

Small string templates with :func:`html.escape` on every stored string
(Jinja2 is not a dependency of the service); the picture and the photos are
inline ``data:`` URIs, the style is inline, so the page needs nothing else —
the same page is what WeasyPrint turns into the PDF.  Sections carry ids
(``#header``, ``#picture``, ``#metrics``, ``#checks``, ``#findings``,
``#withdrawn``, ``#executions``, ``#audit``) for tests and links.
"""

from __future__ import annotations

import base64
import json
import math
from collections.abc import Iterable, Sequence
from html import escape
from typing import Any

from server.reports.data import ExecutionData, FindingData, ReportData

#: Longest parameter value shown in full (characters).
PARAM_TEXT_MAX = 300

STYLE = """
@page { size: A4; margin: 14mm 12mm; }
body { font-family: "DejaVu Sans", "Liberation Sans", Arial, sans-serif; font-size: 10pt;
       color: #1b1b1b; margin: 16px auto; max-width: 1200px; line-height: 1.35; }
h1 { font-size: 17pt; margin: 0 0 4px; }
h2 { font-size: 13pt; margin: 18px 0 6px; border-bottom: 1px solid #bbb; padding-bottom: 2px; }
h3 { font-size: 11pt; margin: 10px 0 4px; }
table { border-collapse: collapse; width: 100%; margin: 4px 0 8px; }
th, td { border: 1px solid #ccc; padding: 3px 6px; text-align: left; vertical-align: top; }
th { background: #eef1f4; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
.muted { color: #666; }
.pass { color: #1b5e20; font-weight: bold; }
.fail { color: #b71c1c; font-weight: bold; }
.cs { display: inline-block; min-width: 1.6em; text-align: center; border-radius: 3px;
      color: #fff; padding: 0 4px; font-weight: bold; }
.cs1 { background: #2e7d32; } .cs2 { background: #f9a825; color: #000; }
.cs3 { background: #ef6c00; } .cs4 { background: #c62828; }
figure { margin: 6px 0; } figure img { max-width: 100%; border: 1px solid #ddd; }
img.photo { max-width: 240px; max-height: 240px; margin: 2px 4px 2px 0; border: 1px solid #ccc; }
.photos figure { display: inline-block; vertical-align: top; margin: 0 6px 4px 0; }
.photos figcaption { font-size: 8pt; color: #555; max-width: 240px; }
pre.notes { white-space: pre-wrap; font-family: inherit; margin: 0; }
tr { page-break-inside: avoid; }
.cols { display: flex; gap: 16px; align-items: flex-start; }
.cols > div { flex: 1 1 0; min-width: 0; }
.cols h3 { margin-top: 0; }
table.facts, .cols table { font-size: 9pt; }
"""


def esc(value: Any) -> str:
    """Any stored value as escaped text (None as an em dash)."""
    if value is None:
        return "—"
    return escape(str(value), quote=True)


def num(value: Any) -> str:
    """A number in six significant digits (text for anything else), escaped."""
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return esc(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            return esc(value)
        return esc(f"{value:.6g}")
    return esc(value)


def _rows(head: Sequence[str], rows: Iterable[Sequence[str]], cls: str = "") -> str:
    """A table of already-escaped cells under escaped headings."""
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>\n" for r in rows)
    if not body:
        return '<p class="muted">none</p>'
    th = "".join(f"<th>{esc(h)}</th>" for h in head)
    attr = f' class="{cls}"' if cls else ""
    return f"<table{attr}><thead><tr>{th}</tr></thead><tbody>\n{body}</tbody></table>"


def _flatten(prefix: str, value: Any) -> Iterable[tuple[str, Any]]:
    if isinstance(value, dict) and value:
        for k, v in value.items():
            yield from _flatten(f"{prefix}.{k}" if prefix else str(k), v)
    else:
        yield prefix, value


def _param_text(value: Any) -> str:
    if value is None:
        return "— (default)"
    text = value if isinstance(value, str) else json.dumps(value, separators=(", ", ": "))
    if len(text) > PARAM_TEXT_MAX:
        text = text[:PARAM_TEXT_MAX] + f"… ({len(text)} characters)"
    return esc(text)


def _header(d: ReportData) -> str:
    p = d.plan
    facts = [
        ("plan", esc(p.id)),
        ("kind", esc(p.kind)),
        ("state", esc(p.state)),
        ("revision of", esc(p.parent_id)),
        ("created", f"{esc(p.created_at)} by {esc(p.created_by)}"),
        (
            "approved",
            f"{esc(p.approved_at)} by {esc(p.approved_by)}" if p.approved_by else "not approved",
        ),
        ("last change", esc(p.updated_at)),
        ("error", esc(p.error)),
    ]
    rows = [(f"<th>{esc(k)}</th>", v) for k, v in facts]
    table = "".join(f"<tr>{k}<td>{v}</td></tr>\n" for k, v in rows)
    params = _rows(
        ("parameter", "value"),
        ((esc(k), _param_text(v)) for k, v in _flatten("", p.params)),
    )
    return (
        f'<section id="header"><h1>Inspection report — plan {esc(p.id)}</h1>\n'
        f'<p class="muted">{esc(p.kind)}, {esc(p.state)}; data as of {esc(d.as_of)}</p>\n'
        f'<div class="cols"><div><table class="facts">{table}</table></div>\n'
        f"<div><h3>Parameters</h3>\n{params}</div></div></section>\n"
    )


def _picture(png: bytes | None) -> str:
    if png is None:
        return (
            '<section id="picture"><h2>Structure</h2>'
            '<p class="muted">this plan stored nothing to draw</p></section>\n'
        )
    uri = "data:image/png;base64," + base64.b64encode(png).decode("ascii")
    return (
        '<section id="picture"><h2>Structure</h2><figure>'
        f'<img id="structure-picture" alt="structure, route and findings" src="{uri}">'
        '<figcaption class="muted">Cloud (thinned), structure model, route; findings '
        "numbered as in the table, coloured by condition state.</figcaption>"
        "</figure></section>\n"
    )


def _metrics(d: ReportData) -> str:
    res = d.plan.result or {}
    summary: list[tuple[str, Any]] = []
    route = res.get("route")
    if isinstance(route, dict):
        summary += [(f"route.{k}", v) for k, v in route.items() if _scalar(v)]
    summary += [(k, v) for k, v in res.items() if _scalar(v)]
    metric_rows = [
        (esc(k), f'<span class="num">{num(v)}</span>') for k, v in d.plan.metrics.items()
    ]
    out = '<section id="metrics"><h2>Route and metrics</h2>\n'
    if summary:
        out += "<h3>Result summary</h3>\n" + _rows(
            ("item", "value"), ((esc(k), num(v)) for k, v in summary)
        )
    out += "<h3>Metrics</h3>\n" + _rows(("metric", "value"), metric_rows)
    return out + "</section>\n"


def _scalar(v: Any) -> bool:
    return isinstance(v, int | float | str | bool)


def checks_table(checks: Sequence[dict[str, Any]]) -> str:
    """The plan's checks with PASS / FAIL, value, limit and message."""
    rows = []
    for c in checks:
        ok = bool(c.get("passed"))
        verdict = '<span class="pass">PASS</span>' if ok else '<span class="fail">FAIL</span>'
        rows.append(
            (esc(c.get("name")), verdict, num(c.get("value")), num(c.get("limit")),
             esc(c.get("message", "")))
        )  # fmt: skip
    return _rows(("check", "result", "value", "limit", "message"), rows, "checks")


def _checks(d: ReportData) -> str:
    failed = len(d.plan.failed_checks)
    total = len(d.plan.checks)
    verdict = (
        f'<span class="pass">all {total} pass</span>'
        if failed == 0
        else f'<span class="fail">{failed} of {total} fail</span>'
    )
    return (
        f'<section id="checks"><h2>Checks</h2><p>{verdict}</p>\n'
        f"{checks_table(d.plan.checks)}</section>\n"
    )


def _condition(f: FindingData) -> str:
    return f'<span class="cs cs{f.condition_state}">{f.condition_state}</span> {esc(f.condition)}'


def render_linked_plans(f: FindingData) -> str:
    """The maintenance plans a finding links to (empty when it links none)."""
    if not f.linked_plans:
        return ""
    items = []
    for p in f.linked_plans:
        bits = [esc(p["plan_id"]), esc(p["kind"]), esc(p["state"] or "deleted")]
        if p.get("outcome"):
            bits.append(f"— run {esc(p['outcome'])}")
        if p.get("spots_planned"):
            bits.append(f"{esc(p['spots_done'])} of {esc(p['spots_planned'])} spots")
        if p.get("coverage_pct") is not None:
            bits.append(f"coverage {p['coverage_pct']:.2f} %")
        if p.get("review_requested_at") and not p.get("reviewed_at"):
            bits.append("(new condition state awaited)")
        items.append(" ".join(bits))
    return '<ul class="linked-plans">' + "".join(f"<li>{i}</li>" for i in items) + "</ul>"


def _photos(f: FindingData) -> str:
    out = []
    for ph in f.photos:
        caption = f"{esc(ph.filename)} — {esc(ph.created_by)}, {esc(ph.created_at)}"
        if ph.data_uri is not None:
            out.append(
                f'<figure><img class="photo" alt="{esc(ph.filename)}" src="{ph.data_uri}">'
                f"<figcaption>{caption}</figcaption></figure>"
            )
        else:
            out.append(f"<figure><figcaption>{caption}: {esc(ph.note)}</figcaption></figure>")
    return f'<div class="photos">{"".join(out)}</div>' if out else ""


def _findings(d: ReportData) -> str:
    rows = []
    for f in d.findings:
        edited = f"<br>edited {esc(f.updated_at)} by {esc(f.updated_by)}" if f.updated_by else ""
        rows.append(
            (
                esc(f.number),
                f"{esc(f.id)}<br>{esc(f.created_at)} by {esc(f.created_by)}{edited}",
                esc(f.location),
                esc(f.type),
                _condition(f),
                f'<pre class="notes">{esc(f.notes)}</pre>{_photos(f)}',
                render_linked_plans(f),
            )
        )
    table = _rows(
        ("#", "finding", "location", "type", "condition state", "notes and photos", "plans"),
        rows,
        "findings",
    )
    counts = {s: sum(1 for f in d.findings if f.condition_state == s) for s in (1, 2, 3, 4)}
    summary = ", ".join(f"{n} in state {s}" for s, n in counts.items() if n)
    return (
        f'<section id="findings"><h2>Findings ({len(d.findings)})</h2>\n'
        + (f"<p>{esc(summary)}</p>\n" if summary else "")
        + f"{table}</section>\n"
    )


def _withdrawn(d: ReportData) -> str:
    if not d.withdrawn:
        return ""
    rows = [
        (
            esc(f.number),
            esc(f.id),
            esc(f.location),
            esc(f.type),
            _condition(f),
            f"{esc(f.deleted_at)} by {esc(f.deleted_by)}",
            esc(f.deleted_reason),
        )
        for f in d.withdrawn
    ]
    return (
        f'<section id="withdrawn"><h2>Withdrawn findings ({len(d.withdrawn)})</h2>\n'
        + _rows(("#", "finding", "location", "type", "condition state", "withdrawn", "why"), rows)
        + "</section>\n"
    )


def _duration(e: ExecutionData) -> str:
    if e.duration_s is None:
        return "—"
    s = e.duration_s
    return esc(f"{int(s // 60)} min {s % 60:.1f} s" if s >= 60 else f"{s:.1f} s")


def _executions(d: ReportData) -> str:
    rows = []
    for e in d.executions:
        r = e.record
        problem = " ".join(x for x in (r.error, r.fault) if x)
        rows.append(
            (
                esc(r.id),
                esc(r.robot),
                esc(r.state),
                f"{esc(r.acked)} / {esc(r.total)}",
                f"{esc(r.created_at)} by {esc(r.created_by)}",
                esc(r.updated_at),
                _duration(e),
                esc(problem or None),
            )
        )
    table = _rows(
        ("execution", "robot", "state", "commands acked", "dispatched", "last change",
         "duration", "error / fault"),
        rows,
        "executions",
    )  # fmt: skip
    return (
        f'<section id="executions"><h2>Executions ({len(d.executions)})</h2>\n{table}\n'
        + (
            '<p class="muted">Each execution ran this plan\'s program under the checks above.</p>\n'
            if d.executions
            else ""
        )
        + "</section>\n"
    )


def _audit(d: ReportData) -> str:
    rows = [
        (
            esc(a.ts),
            esc(a.actor),
            f"{esc(a.entity)} {esc(a.entity_id)}",
            esc(a.action),
            f"{esc(a.from_state)} → {esc(a.to_state)}" if a.from_state or a.to_state else "",
            esc(a.reason),
        )
        for a in d.audit
    ]
    return (
        '<section id="audit"><h2>Audit trail</h2>\n'
        + _rows(("when", "who", "what", "action", "state", "reason"), rows, "audit")
        + "</section>\n"
    )


def render_html(d: ReportData, png: bytes | None) -> str:
    """The whole report page."""
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">\n'
        f"<title>SteelPath report — {esc(d.plan.kind)} {esc(d.plan.id)}</title>\n"
        f"<style>{STYLE}</style></head>\n<body>\n"
        + _header(d)
        + _picture(png)
        + _metrics(d)
        + _checks(d)
        + _findings(d)
        + _withdrawn(d)
        + _executions(d)
        + _audit(d)
        + '<p class="muted">SteelPath — every entry above comes from stored data '
        f"as of {esc(d.as_of)}.</p>\n</body></html>\n"
    )
