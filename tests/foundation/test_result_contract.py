"""planners.result: the one result contract between planners and kinds."""

from __future__ import annotations

import math

import numpy as np

from planners.result import Check, PlanResult, check_ge, check_le
from server.kinds.base import Check as StoredCheck
from server.kinds.base import KindOutput


def test_check_le_and_ge_on_hand_cases() -> None:
    ok = check_le("speed", 0.5, 1.0, "largest speed", " m/s")
    assert ok.passed and ok.value == 0.5 and ok.limit == 1.0
    assert ok.message == "largest speed 0.5 m/s ≤ 1 m/s"
    bad = check_le("speed", 1.5, 1.0, "largest speed", " m/s")
    assert not bad.passed and bad.message == "largest speed 1.5 m/s > 1 m/s"
    assert check_ge("gap", 0.003, 0.002, "gap", " mm", scale=1e3).message == "gap 3 mm ≥ 2 mm"
    assert not check_ge("gap", 0.001, 0.002, "gap", " mm", scale=1e3).passed
    # the boundary passes both ways; a non-finite value never passes
    assert check_le("x", 1.0, 1.0, "x").passed and check_ge("x", 1.0, 1.0, "x").passed
    for v in (math.nan, math.inf, -math.inf):
        assert not check_le("x", v, 1.0, "x").passed
        assert not check_ge("x", v, 1.0, "x").passed


def test_kind_output_passes_the_planner_result_through() -> None:
    r = PlanResult(
        summary={"route": [1, 2]},
        arrays={"xyz": np.zeros((3, 3))},
        checks=[Check("a", True, 1.0, 2.0, "fine"), check_le("b", 3.0, 2.0, "b")],
        metrics={"n": np.float64(4.0)},
    )
    assert not r.passed
    out = KindOutput.from_result(r)
    assert out.result is r.summary and out.arrays is r.arrays
    assert [c.name for c in out.checks] == ["a", "b"]
    assert all(isinstance(c, StoredCheck) for c in out.checks)
    assert out.checks[1] == StoredCheck(
        name="b", passed=False, value=3.0, limit=2.0, message="b 3 > 2"
    )
    assert out.metrics == {"n": 4.0} and type(out.metrics["n"]) is float
    assert PlanResult().passed  # no checks: nothing failed
