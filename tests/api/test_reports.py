"""Reports of plans through REST: an inspection with findings,
a photo and a real emulator execution in one self-contained HTML page (its
picture a valid PNG, stored strings escaped, the same bytes twice), as PDF,
for every kind crews use, and the 404 / 422 / 503 answers."""

from __future__ import annotations

import base64
import contextlib
import io
import re
import zlib
from html.parser import HTMLParser

import pytest
from PIL import Image

from tests.api.test_dispatch import wait_execution

SCRIPT_NOTE = "paint blistered <script>alert('x')</script> & flaking"


class Page(HTMLParser):
    """The images (by id and class) and table classes of a report page."""

    def __init__(self) -> None:
        super().__init__()
        self.images: list[dict[str, str]] = []
        self.tables: list[str] = []
        self.ids: set[str] = set()

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = {k: v or "" for k, v in attrs}
        if "id" in a:
            self.ids.add(a["id"])
        if tag == "img":
            self.images.append(a)
        if tag == "table":
            self.tables.append(a.get("class", ""))


def parsed(text: str) -> Page:
    p = Page()
    p.feed(text)
    return p


def png_of(uri: str) -> Image.Image:
    head, data = uri.split(",", 1)
    assert head == "data:image/png;base64", head
    raw = base64.b64decode(data)
    assert raw.startswith(b"\x89PNG\r\n\x1a\n")
    im = Image.open(io.BytesIO(raw))
    im.verify()
    return Image.open(io.BytesIO(raw))


def photo_bytes() -> bytes:
    im = Image.new("RGB", (640, 480), (180, 90, 40))
    for x in range(0, 640, 40):
        for y in range(480):
            im.putpixel((x, y), (30, 30, 30))
    buf = io.BytesIO()
    im.save(buf, format="JPEG", quality=80)
    return buf.getvalue()


def pdf_pages(pdf: bytes) -> int:
    """Page objects in a PDF, in its plain text and in its deflated (object) streams."""
    text = [pdf]
    for m in re.finditer(rb"stream\r?\n(.*?)endstream", pdf, re.S):
        with contextlib.suppress(zlib.error):  # a stream that is not deflated
            text.append(zlib.decompressobj().decompress(m.group(1)))
    return sum(len(re.findall(rb"/Type\s*/Page(?![a-zA-Z])", t)) for t in text)


@pytest.fixture
def dapi(make_api):
    api = make_api(emulators=True, emulator_time_scale=40.0)
    eng = api.services.dispatch
    assert eng.wait_connected("ara", 20)
    return api


def test_report_of_an_inspection_with_findings_photo_and_execution(dapi) -> None:
    plan = dapi.wait(dapi.submit("ara.navigate")["id"], timeout=120)
    assert plan["state"] == "planned", plan.get("error")
    pid = plan["id"]
    c0, c1 = plan["result"]["clusters"][:2]
    kept = dapi.post(
        "/api/v1/findings",
        json={
            "plan_id": pid,
            "cluster_id": c0["id"],
            "point_m": c0["centre"],
            "type": "corrosion",
            "condition_state": 3,
            "notes": SCRIPT_NOTE,
        },
    ).json()
    r = dapi.post(
        f"/api/v1/findings/{kept['id']}/photos",
        files={"file": ("rust.jpg", photo_bytes(), "image/jpeg")},
        data={"caption": "rust at <b>cross</b>"},
    )
    assert r.status_code == 201, r.text
    gone = dapi.post(
        "/api/v1/findings",
        json={
            "plan_id": pid,
            "cluster_id": c1["id"],
            "point_m": c1["centre"],
            "type": "crack",
            "condition_state": 4,
            "notes": "a scratch, not a crack",
        },
    ).json()
    assert dapi.delete(f"/api/v1/findings/{gone['id']}?reason=paint scratch").status_code == 200

    assert dapi.post(f"/api/v1/plans/{pid}/approve").status_code == 200
    r = dapi.post(f"/api/v1/plans/{pid}/dispatch", json={"robot": "ara"})
    assert r.status_code == 201, r.text
    ex = wait_execution(dapi, r.json()["id"], ("completed",), timeout=120)

    r = dapi.get(f"/api/v1/reports/{pid}", "viewer")
    assert r.status_code == 200, r.text
    assert r.headers["content-type"].startswith("text/html")
    text = r.text
    page = parsed(text)
    assert {"header", "picture", "metrics", "checks", "findings", "withdrawn", "executions"} <= (
        page.ids
    )
    assert "audit" in page.ids

    # Header: id, kind, state, who approved, parameters.
    approved = dapi.get(f"/api/v1/plans/{pid}").json()
    assert pid in text and "ara.navigate" in text and "completed" in text
    assert approved["approved_by"] in text and approved["approved_at"] in text
    assert "motion_model" in text and "differential" in text

    # The picture is a valid PNG; the photo is embedded as a thumbnail.
    pic = next(i for i in page.images if i.get("id") == "structure-picture")
    im = png_of(pic["src"])
    assert im.size[0] > 600 and im.size[1] > 300
    photos = [i for i in page.images if "photo" in i.get("class", "")]
    assert len(photos) == 1
    assert max(png_of(photos[0]["src"]).size) <= 480
    assert "rust at &lt;b&gt;cross&lt;/b&gt;" in text and "<b>cross</b>" not in text

    # Metrics and checks with their verdict.
    assert "route_length_m" in text and "bars_covered" in text and "PASS" in text

    # Findings: location, type, condition (number + word), notes escaped.
    assert "findings" in page.tables
    assert kept["id"] in text and f"cluster {c0['id']}" in text and "corrosion" in text
    assert '<span class="cs cs3">3</span> poor' in text
    assert "<script>" not in text
    assert "paint blistered &lt;script&gt;alert(&#x27;x&#x27;)&lt;/script&gt; &amp; flaking" in text
    # The withdrawn one, with who and why, is listed apart.
    withdrawn = text[text.index('id="withdrawn"') : text.index('id="executions"')]
    assert gone["id"] in withdrawn and "paint scratch" in withdrawn and "severe" in withdrawn
    findings = text[text.index('id="findings"') : text.index('id="withdrawn"')]
    assert gone["id"] not in findings

    # The execution: robot, state, counts; the audit: who approved and dispatched.
    execs = text[text.index('id="executions"') : text.index('id="audit"')]
    assert ex["id"] in execs and "ara" in execs and "completed" in execs
    assert f"{ex['total']} / {ex['total']}" in execs
    audit = text[text.index('id="audit"') :]
    for action in ("approve", "dispatch", "create", "photo", "delete", "complete"):
        assert f"<td>{action}</td>" in audit, action
    assert "test-operator" in audit

    # Deterministic: the same stored data, the same bytes.
    assert dapi.get(f"/api/v1/reports/{pid}", "viewer").content == r.content

    # As PDF.
    r = dapi.get(f"/api/v1/reports/{pid}?format=pdf", "viewer")
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == "application/pdf"
    assert r.content.startswith(b"%PDF") and pdf_pages(r.content) >= 1


def test_every_kind_crews_use_has_a_report(make_api) -> None:
    api = make_api()
    ids = {k: api.submit(k)["id"] for k in ("ara.inspect", "sbg.inspect", "blast", "demo.route")}
    for kind, pid in ids.items():
        plan = api.wait(pid, timeout=120)
        assert plan["state"] in ("planned", "rejected"), (kind, plan.get("error"))
        r = api.get(f"/api/v1/reports/{pid}", "viewer")
        assert r.status_code == 200, (kind, r.text)
        page = parsed(r.text)
        pic = next(i for i in page.images if i.get("id") == "structure-picture")
        png_of(pic["src"])
        assert "checks" in page.tables and kind in r.text
        for c in plan["checks"]:
            assert c["name"] in r.text, (kind, c["name"])
        assert '<p class="muted">none</p>' in r.text  # no findings, no executions


def test_report_errors(api, monkeypatch) -> None:
    assert api.get("/api/v1/reports/pl_nope", "viewer").status_code == 404
    assert api.get("/api/v1/reports/pl_nope?format=pdf", "viewer").status_code == 404
    assert api.client.get("/api/v1/reports/pl_nope").status_code == 401
    pid = api.wait(api.submit("demo.route")["id"])["id"]
    r = api.get(f"/api/v1/reports/{pid}?format=docx", "viewer")
    assert r.status_code == 422
    (err,) = r.json()["detail"]
    assert err["loc"] == ["query", "format"] and "'html' or 'pdf'" in err["msg"]

    import server.reports.pdf as pdf

    def broken() -> None:
        raise OSError("cannot load library 'libpango-1.0-0': no such file")

    monkeypatch.setattr(pdf, "_import_weasyprint", broken)
    r = api.get(f"/api/v1/reports/{pid}?format=pdf", "viewer")
    assert r.status_code == 503
    assert r.headers["content-type"] == "application/json"
    assert "WeasyPrint" in r.json()["detail"] and "libpango" in r.json()["detail"]
    assert api.get(f"/api/v1/reports/{pid}", "viewer").status_code == 200  # HTML still served
