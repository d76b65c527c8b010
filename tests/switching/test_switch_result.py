"""planners.switching.switch_result: the ``ara.switch`` entry point's stored
form, checked against independent recomputations from the
returned arrays and the decision planner called on its own."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest

import planners.switching.switch_plan as switch_plan
from planners.errors import InfeasibleError
from planners.result import PlanResult
from planners.switching import SwitchingParams, decide_mode
from planners.switching.jump import JumpParams
from planners.switching.scenes import make_scene
from planners.switching.switch_result import plan_switch_result

DECISION_ARRAYS = [
    "points",
    "plane_labels",
    "boundary",
    "boundary_plane",
    "rect_corners",
    "rect_passed",
    "rect_plane",
]


@pytest.fixture(scope="module")
def ara() -> Any:
    from robots import load_robot

    return load_robot("ara")


def _foot(ara: Any) -> tuple[float, float]:
    return float(ara.params["foot"]["length_m"]), float(ara.params["foot"]["width_m"])


def _plan(ara: Any, scene_name: str, jump: JumpParams | None) -> tuple[PlanResult, Any]:
    scene = make_scene(scene_name, 0)
    r = plan_switch_result(
        ara,
        scene.points,
        camera_to_base=scene.camera_to_base,
        base_height=0.0,
        foot=_foot(ara),
        params=SwitchingParams(),
        jump=jump,
    )
    return r, scene


def _strict_json(summary: dict[str, Any]) -> dict[str, Any]:
    """The summary survives strict JSON unchanged (what the store writes)."""
    text = json.dumps(summary, allow_nan=False)
    back = json.loads(text)
    assert back == summary
    return back


def _assert_decision_form(r: PlanResult, ara: Any, scene: Any) -> None:
    """Summary, arrays and metrics of the decision agree with each other and
    with ``decide_mode`` called on its own."""
    s = _strict_json(r.summary)
    alone = decide_mode(
        scene.points,
        camera_to_base=scene.camera_to_base,
        base_height=0.0,
        foot=_foot(ara),
        params=SwitchingParams(),
    )
    assert s["decision"] == json.loads(json.dumps(alone.summary()))
    assert s["foot_m"] == list(_foot(ara))
    np.testing.assert_allclose(s["camera_to_base"], scene.camera_to_base, atol=5e-7)
    assert list(r.arrays)[: len(DECISION_ARRAYS)] == DECISION_ARRAYS
    a = r.arrays
    assert a["points"].dtype == np.float32 and a["points"].shape == (len(alone.points), 3)
    np.testing.assert_allclose(a["points"], alone.points, atol=1e-6)
    assert a["plane_labels"].dtype == np.int32 and a["plane_labels"].shape == (len(alone.points),)
    assert a["boundary"].dtype == np.float32 and a["boundary_plane"].dtype == np.int32
    assert a["rect_plane"].dtype == np.int32 and a["rect_passed"].dtype == bool
    planes = s["planes"]
    # Each plane's point count is the number of points labelled with it.
    for pl in planes:
        assert int((a["plane_labels"] == pl["index"]).sum()) == pl["n_points"]
    assert set(np.unique(a["plane_labels"])) <= {-1, *(pl["index"] for pl in planes)}
    # The rectangle arrays are the summary's rectangles, plane by plane.
    rects = [(pl["index"], rc) for pl in planes for rc in pl["rectangles"]]
    assert a["rect_corners"].shape == (len(rects), 4, 3)
    assert a["rect_plane"].tolist() == [k for k, _ in rects]
    assert a["rect_passed"].tolist() == [rc["passed"] for _, rc in rects]
    if rects:
        np.testing.assert_allclose(
            a["rect_corners"], [rc["corners"] for _, rc in rects], atol=5.1e-6
        )
    assert set(np.unique(a["boundary_plane"])) == set(range(len(planes)))
    m = r.metrics
    assert m["planes_found"] == len(planes) == s["decision"]["n_planes"]
    # Alg. 2's counts are those of the chosen plane's rectangles.
    chosen = s["decision"]["plane_index"]
    on_chosen = a["rect_plane"] == (-2 if chosen is None else chosen)
    assert m["rectangles_total"] == int(on_chosen.sum()) == s["decision"]["rectangles_total"]
    assert m["rectangles_passed"] == int(a["rect_passed"][on_chosen].sum())
    assert m["points_input"] == len(scene.points)
    assert m["points_processed"] == len(a["points"])
    assert np.isfinite(m["planning_time_s"]) and m["planning_time_s"] > 0
    safe = r.checks[0]
    assert safe.name == "safe_surface" and safe.value == alone.mode
    assert safe.passed == (alone.mode != "none") and safe.message == alone.message


def test_mobile_decision_has_no_jump(ara: Any) -> None:
    r, scene = _plan(ara, "same_height", JumpParams())
    _assert_decision_form(r, ara, scene)
    assert r.summary["decision"]["mode"] == "mobile" and r.summary["jump"] is None
    assert [c.name for c in r.checks] == ["safe_surface"] and r.passed
    assert abs(r.metrics["height_error_m"]) <= SwitchingParams().height_tolerance_m
    assert r.metrics["height_error_m"] == r.summary["decision"]["height_error_m"]
    assert "joint_trajectory" not in r.arrays


def test_no_surface_fails_the_safe_surface_check(ara: Any) -> None:
    r, scene = _plan(ara, "no_surface", JumpParams())
    _assert_decision_form(r, ara, scene)
    assert r.summary["decision"]["mode"] == "none" and not r.passed
    assert [(c.name, c.passed, c.value) for c in r.checks] == [("safe_surface", False, "none")]
    assert "height_error_m" not in r.metrics


def test_a_jump_that_cannot_be_planned_is_a_failed_check(
    ara: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    def refuse(*args: Any, **kwargs: Any) -> None:
        raise InfeasibleError("no IK solution for foot 1 (test)")

    monkeypatch.setattr(switch_plan, "plan_inchworm_jump", refuse)
    r, scene = _plan(ara, "perpendicular", JumpParams())
    _assert_decision_form(r, ara, scene)
    assert r.summary["decision"]["mode"] == "inchworm" and r.summary["jump"] is None
    assert [(c.name, c.passed) for c in r.checks] == [
        ("safe_surface", True),
        ("jump_planned", False),
    ]
    assert r.checks[1].message == "no IK solution for foot 1 (test)"
    assert list(r.arrays) == DECISION_ARRAYS and "jump_duration_s" not in r.metrics


def test_without_jump_params_only_the_decision(ara: Any) -> None:
    r, _ = _plan(ara, "perpendicular", None)
    assert r.summary["decision"]["mode"] == "inchworm" and r.summary["jump"] is None
    assert [c.name for c in r.checks] == ["safe_surface"] and r.passed


@pytest.mark.slow
def test_the_jump_checks_match_its_arrays(ara: Any) -> None:
    """Fig. 5.4: every jump check's value is what the returned arrays give."""
    margin = 0.01
    r, scene = _plan(ara, "perpendicular", JumpParams(clearance_margin_m=margin, seed=0))
    _assert_decision_form(r, ara, scene)
    s, a, m = r.summary, r.arrays, r.metrics
    checks = {c.name: c for c in r.checks}
    assert list(checks) == [
        "safe_surface",
        "jump_planned",
        "joint_limits",
        "joint_speeds",
        "clearance",
        "self_clearance",
        "foothold_inside_surface",
    ]
    assert r.passed, [c.message for c in r.checks if not c.passed]
    Q, t = a["joint_trajectory"], a["times"]
    assert Q.dtype == np.float64 and Q.shape == (len(t), 6) and a["anchor"].dtype == np.int32
    lo, hi = ara.joint_limits[:, 0], ara.joint_limits[:, 1]
    excess = max(0.0, float(np.max(lo - Q)), float(np.max(Q - hi)))
    assert checks["joint_limits"].value == pytest.approx(excess, abs=1e-12)
    ratio = max(
        float(np.max(abs(Q[k + 1] - Q[k]) / (t[k + 1] - t[k]) / ara.max_speed))
        for k in range(len(t) - 1)
    )
    assert checks["joint_speeds"].value == pytest.approx(ratio, rel=1e-9)
    assert checks["joint_speeds"].value == pytest.approx(m["jump_max_speed_ratio"], rel=1e-9)
    assert checks["clearance"].value == float(a["clearance"].min()) == m["jump_min_clearance_m"]
    assert checks["clearance"].limit == margin
    assert checks["self_clearance"].value == m["jump_min_self_clearance_m"] >= 0.0
    jump = s["jump"]
    assert [p["name"] for p in jump["phases"]] == ["A", "B", "C", "D", "E", "F"]
    assert jump["phases"][0]["start"] == 0 and jump["phases"][-1]["stop"] == len(t)
    assert m["jump_duration_s"] == pytest.approx(t[-1]) == jump["phases"][-1]["t_end_s"]
    assert all(t[0] <= c["t_s"] <= t[-1] for c in jump["magnet_commands"])
    assert jump["joint_names"] == list(ara.joint_names)
    assert m["foot2_on_seen_surface"] == float(jump["foot2_on_seen_surface"])
