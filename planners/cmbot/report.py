"""The stored form shared by the CMBOT plans: the guardrail
and the arm's cuboids as a drawer redraws them, and the simulation gate's
report (seed §4: "the movement must be checked by the simulation system
before the robot starts to work") as plan checks, violations and summary.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from planners.cmbot.distance import Cuboid
from planners.cmbot.guardrail import Guardrail
from planners.cmbot.simulate import GateReport
from planners.result import Check

#: samples of a console plot (the CMBOT runs are long and fine-stepped)
PLOT_SAMPLES = 600


def guardrail_summary(g: Guardrail) -> dict[str, Any]:
    """What a drawer needs to redraw the guardrail (segments, posts, gaps, params)."""
    p = g.params
    return {
        "segments": g.segments.tolist(),
        "posts": g.posts.tolist(),
        "gaps": g.gaps.tolist(),
        "params": {k: getattr(p, k) for k in p.__dataclass_fields__},
    }


def boxes_summary(boxes: Sequence[Cuboid]) -> list[dict[str, Any]]:
    """The cuboids (name, group, centre, half extents, rotation) as JSON lists."""
    return [
        {
            "name": b.name,
            "group": b.group,
            "center": b.center.tolist(),
            "half": b.half.tolist(),
            "rotation": b.rotation.tolist(),
        }
        for b in boxes
    ]


def gate_checks(gate: GateReport, prefix: str = "") -> list[Check]:
    """The simulation gate's checks as plan checks (a failed one rejects the
    plan); a failed check's message names its first violation (time and
    place) unless it already says when."""
    out = []
    for c in gate.checks:
        where = [v for v in gate.violations if v.check == c.name]
        msg = c.message
        if where and "at t =" not in msg:
            msg += f" (first at t = {where[0].t_s:.3f} s: {where[0].where})"
        out.append(
            Check(
                name=prefix + c.name,
                passed=c.passed,
                value=float(c.value) if math.isfinite(c.value) else None,
                limit=float(c.limit),
                message=msg,
            )
        )
    return out


def violations_summary(gate: GateReport) -> list[dict[str, Any]]:
    """Every listed violation (check, t_s, value, limit, where) as a dict."""
    return [vars(v) for v in gate.violations]


def gate_summary(gate: GateReport) -> dict[str, Any]:
    """The gate's sample time, sample count and one-line summary."""
    return {"dt_s": gate.dt_s, "samples": gate.samples, "summary": gate.summary()}


def finite_metrics(metrics: dict[str, float]) -> dict[str, float]:
    """The finite metrics as floats (a NaN metric, e.g. a check that did not run, is left out)."""
    return {k: float(v) for k, v in metrics.items() if math.isfinite(v)}
