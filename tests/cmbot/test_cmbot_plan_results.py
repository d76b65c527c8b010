"""The stored form of the CMBOT plans: ``plan_climb_result`` and
``plan_manipulation_result`` on cheap inputs, their checks held against the
simulation gate replayed on the stored arrays, their metrics against the
arrays themselves."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

import robots
from planners.cmbot import ExperimentParams, GaitParams, Section4Trajectory, seed_guardrail
from planners.cmbot.arm import ArmKinematics
from planners.cmbot.climb_plan import plan_climb_result
from planners.cmbot.gait import GaitTrajectory
from planners.cmbot.manipulate_plan import manipulation_result, plan_manipulation_result
from planners.cmbot.manipulation import BaseProposal, plan_manipulation
from planners.cmbot.report import gate_checks
from planners.cmbot.scene import arm_scene, work_stance
from planners.cmbot.simulate import GateCheck, GateReport, Violation, simulate_arm, simulate_climb
from planners.result import PlanResult

MODEL = robots.load_robot("cmbot")
L = MODEL.params["climber"]["foot_length_m"]
SHORT = {"start_rear_x": 4.6, "goal_rear_x": 4.84}  # one step before the gap (~1 s to plan)
#: the §4 trajectory cut to 2 s (1 s per Eq. 21–26 branch), coarse steps: ~3 s to plan
SHORT_ARM = Section4Trajectory(duration_s=2.0, switch_s=1.0)


def _strict_json(r: PlanResult) -> None:
    json.dumps(r.summary, allow_nan=False)


def _gate_on_stored_climb(r: PlanResult):
    a = r.arrays
    tr = GaitTrajectory(
        times=a["times"],
        q=a["q"],
        rear=a["rear"],
        front=a["front"],
        support=a["support"].astype(int),
        flip_Nm=a["flip_Nm"],
        flip_no_cw_Nm=a["flip_no_cw_Nm"],
        phase_index=np.zeros(len(a["times"]), int),
    )
    return simulate_climb(MODEL, seed_guardrail(), tr)


def _assert_checks_are_the_gate(checks, gate: GateReport) -> None:
    assert [c.name for c in checks] == [c.name for c in gate.checks]
    for c, g in zip(checks, gate.checks, strict=True):
        assert c.passed == g.passed, c.name
        assert c.value == pytest.approx(g.value, rel=1e-9, abs=1e-12), c.name
        assert c.limit == pytest.approx(g.limit), c.name
        assert c.message.startswith(g.message), c.name


@pytest.fixture(scope="module")
def climb() -> PlanResult:
    return plan_climb_result(MODEL, guardrail=seed_guardrail(), params=GaitParams(), **SHORT)


@pytest.fixture(scope="module")
def fast_climb() -> PlanResult:
    p = GaitParams(phase_time_s=0.4, counterweight=False)
    return plan_climb_result(MODEL, guardrail=seed_guardrail(), params=p, **SHORT)


def test_climb_stored_form(climb: PlanResult) -> None:
    _strict_json(climb)
    s, a, m = climb.summary, climb.arrays, climb.metrics
    assert set(s) == {
        "guardrail", "footholds", "phases", "limits", "violations", "gate", "plots", "joint_names"
    }  # fmt: skip
    T = len(a["times"])
    shapes = {k: v.shape for k, v in a.items()}
    assert shapes == {
        "times": (T,), "q": (T, 12), "rear": (T, 3), "front": (T, 3), "support": (T,),
        "flip_Nm": (T, 3), "flip_no_cw_Nm": (T, 3),
    }  # fmt: skip
    assert a["support"].dtype == np.int8 and a["q"].dtype == np.float64
    assert s["joint_names"] == list(MODEL.urdf_joint_names)
    g = seed_guardrail()
    assert s["guardrail"]["segments"] == g.segments.tolist()
    assert s["guardrail"]["gaps"] == g.gaps.tolist()
    # the footholds check, recomputed from the stored stances
    soles = np.array(s["footholds"]).ravel()
    foot = climb.checks[0]
    assert foot.name == "footholds" and foot.value == len(s["footholds"]) >= 2
    assert foot.passed and bool(np.all(g.valid_foothold(soles, L)))
    assert s["footholds"][0] == [4.6, pytest.approx(4.6 + s["limits"]["d_work_m"])]
    assert s["footholds"][-1][0] == pytest.approx(4.84)
    # the metrics, recomputed from the arrays and the phases
    sup = a["support"] > 0
    assert m["max_flip_torque_Nm"] == pytest.approx(np.abs(a["flip_Nm"][sup, 1]).max())
    assert m["max_flip_torque_without_counterweight_Nm"] == pytest.approx(
        np.abs(a["flip_no_cw_Nm"][sup, 1]).max()
    )
    assert m["duration_s"] == a["times"][-1] >= s["phases"][-1]["t_end_s"]
    assert m["phases"] == len(s["phases"])
    assert m["max_step_m"] == pytest.approx(max(abs(ph["step_m"]) for ph in s["phases"]))
    assert m["walk_length_m"] == pytest.approx(0.24)
    assert m["gate_samples"] == s["gate"]["samples"]
    # the flip plot: |M_y| in single support, null (JSON) in double support
    fp = s["plots"][0]
    k = np.searchsorted(a["times"], fp["x"])
    assert np.allclose(a["times"][k], fp["x"]) and k[0] == 0 and k[-1] == T - 1
    cw = fp["series"]["with counterweight"]
    for i, v in zip(k, cw, strict=True):
        assert (v is None) == (not sup[i])
        if v is not None:
            assert v == pytest.approx(abs(a["flip_Nm"][i, 1]))
    assert set(fp["series"]["magnet holding moment"]) == {m["magnet_holding_moment_Nm"]}


def test_climb_checks_are_the_gate_replayed_on_the_stored_arrays(climb: PlanResult) -> None:
    gate = _gate_on_stored_climb(climb)
    assert gate.passed and climb.passed
    _assert_checks_are_the_gate(climb.checks[1:], gate)
    assert climb.summary["gate"]["samples"] == gate.samples
    assert climb.summary["gate"]["summary"] == gate.summary()
    assert climb.summary["violations"] == []


def test_a_fast_climb_without_counterweight_fails_saying_where_and_when(
    fast_climb: PlanResult,
) -> None:
    _strict_json(fast_climb)
    assert not fast_climb.passed
    gate = _gate_on_stored_climb(fast_climb)
    _assert_checks_are_the_gate(fast_climb.checks[1:], gate)
    failed = {c.name for c in fast_climb.checks if not c.passed}
    assert "flip_torque" in failed
    flip = next(c for c in fast_climb.checks if c.name == "flip_torque")
    sup = fast_climb.arrays["support"] > 0
    # the gate samples between the planned steps too, so it sees at least the stored worst
    assert flip.value >= np.abs(fast_climb.arrays["flip_Nm"][sup, 1]).max() - 1e-9
    assert flip.limit == fast_climb.metrics["magnet_holding_moment_Nm"]
    assert all("t =" in c.message for c in fast_climb.checks if not c.passed)
    stored = fast_climb.summary["violations"]
    assert stored and stored == json.loads(json.dumps([vars(v) for v in gate.violations]))


def test_gate_checks_name_the_first_violation_unless_the_message_says_when() -> None:
    gate = GateReport(
        checks=[
            GateCheck("a", False, 2.0, 1.0, "a: worst 2 > 1"),
            GateCheck("b", False, 3.0, 1.0, "b: worst 3 > 1 at t = 0.500 s (here)"),
            GateCheck("c", True, float("nan"), 1.0, "c: nothing to check"),
        ],
        violations=[
            Violation("a", 0.25, 2.0, 1.0, "rear sole"),
            Violation("a", 0.5, 1.5, 1.0, "front sole"),
            Violation("b", 0.5, 3.0, 1.0, "here"),
        ],
    )
    a, b, c = gate_checks(gate, prefix="x_")
    assert a.name == "x_a" and a.message == "a: worst 2 > 1 (first at t = 0.250 s: rear sole)"
    assert b.message == "b: worst 3 > 1 at t = 0.500 s (here)" and not b.passed
    assert c.passed and c.value is None and c.limit == 1.0


@pytest.fixture(scope="module")
def arm() -> tuple[PlanResult, ExperimentParams]:
    """Without the escape term, compared with it; a clearance of 0.5 m that no
    base within ±0.1 m reaches, so the relocation search runs and finds none."""
    p = ExperimentParams(trajectory=SHORT_ARM, dt_s=0.02, min_clearance_m=0.5)
    r = plan_manipulation_result(
        MODEL,
        guardrail=seed_guardrail(),
        rear_foot_x=8.0,
        params=p,
        avoidance=False,
        compare=True,
        relocate=True,
        max_shift_m=0.1,
        shift_step_m=0.1,
    )
    return r, p


def test_manipulation_stored_form(arm: tuple[PlanResult, ExperimentParams]) -> None:
    r, p = arm
    _strict_json(r)
    s, a, m = r.summary, r.arrays, r.metrics
    assert set(s) == {
        "guardrail", "rear_foot_x_m", "T_world_base", "q_climb", "boxes_base_frame",
        "q_start_deg", "proposal", "violations", "comparison_violations", "gate",
        "comparison_gate", "plots", "joint_names",
    }  # fmt: skip
    T = len(a["times"])
    assert {k: v.shape for k, v in a.items()} == {
        "times": (T,), "q": (T, 7), "tool_pos": (T, 3), "desired_pos": (T, 3),
        "clearance": (T,), "pos_error": (T,), "q_compare": (T, 7), "clearance_compare": (T,),
    }  # fmt: skip
    assert a["times"][-1] == pytest.approx(2.0)
    assert s["joint_names"] == [f"J{i}" for i in range(6, 13)]
    assert np.allclose(s["q_climb"], work_stance(MODEL))
    assert np.allclose(np.radians(s["q_start_deg"]), a["q"][0])
    scene = arm_scene(MODEL, seed_guardrail(), 8.0)
    assert np.allclose(s["T_world_base"], scene.T_world_base)
    assert [b["name"] for b in s["boxes_base_frame"]] == [b.name for b in scene.boxes]
    # metrics from the arrays
    v = np.linalg.norm(np.gradient(a["tool_pos"], a["times"], axis=0), axis=1)
    assert m["max_tool_speed_m_s"] == pytest.approx(v.max())
    assert m["duration_s"] == a["times"][-1]
    assert m["failed_checks"] == sum(not c.passed for c in r.checks if c.name != "base_position")
    # the plots: the run without, the comparison with avoidance, the two limits
    cp, tp = s["plots"][0], s["plots"][1]
    k = np.searchsorted(a["times"], cp["x"])
    assert np.allclose(a["times"][k], cp["x"])
    assert np.allclose(cp["series"]["without avoidance"], a["clearance"][k])
    assert np.allclose(cp["series"]["with avoidance"], a["clearance_compare"][k])
    assert set(cp["series"]["required clearance"]) == {0.5}
    assert set(cp["series"]["Eq. 15 d_s"]) == {p.avoidance.d_s}
    assert np.allclose(tp["series"]["without avoidance"], a["pos_error"][k] * 1e3)


def test_manipulation_checks_are_the_gate_replayed_on_the_stored_arrays(
    arm: tuple[PlanResult, ExperimentParams],
) -> None:
    r, p = arm
    scene = arm_scene(MODEL, seed_guardrail(), 8.0)
    gate = simulate_arm(
        ArmKinematics.from_model(MODEL),
        scene.boxes,
        p.trajectory,
        r.arrays["times"],
        r.arrays["q"],
        gravity=scene.gravity,
        payload_kg=p.payload_kg,
        min_clearance_m=p.min_clearance_m,
    )
    _assert_checks_are_the_gate(r.checks[:-1], gate)
    clear = next(c for c in r.checks if c.name == "clearance")
    assert not clear.passed and clear.value == pytest.approx(r.metrics["min_clearance_m"])
    assert r.summary["gate"]["summary"] == gate.summary()
    # no base within ±0.1 m passes: a failed base_position check, the bases tried
    base = r.checks[-1]
    assert base.name == "base_position" and not base.passed and base.value is None
    assert base.message == "no base position within ±0.1 m passes every check"
    tried = r.summary["proposal"]["tried"]
    assert [t["rear_foot_x_m"] for t in tried] == pytest.approx([7.9, 8.1])
    assert all("0.5 m" in t["outcome"] for t in tried)
    assert "proposed_rear_foot_x_m" not in r.metrics


def test_a_found_base_is_a_failed_check_that_says_where_to_replan() -> None:
    p = ExperimentParams(trajectory=SHORT_ARM, dt_s=0.02)
    g = seed_guardrail()
    plan = plan_manipulation(MODEL, guardrail=g, params=p, relocate=False)
    assert plan.proposal is None and plan.gate.passed
    r = manipulation_result(plan, g, work_stance(MODEL), avoidance=True, max_shift_m=0.5)
    assert r.passed and r.summary["proposal"] is None and r.summary["comparison_gate"] is None
    assert "q_compare" not in r.arrays
    found = BaseProposal(8.1, 0.1, None, None, [(8.1, "passes")])
    r2 = manipulation_result(
        dataclasses.replace(plan, proposal=found),
        g,
        work_stance(MODEL),
        avoidance=True,
        max_shift_m=0.5,
    )
    base = r2.checks[-1]
    assert base.name == "base_position" and not base.passed and base.value == 8.1
    assert base.message == (
        "the motion passes every check with the rear sole at 8.100 m (shift +0.100 m): re-plan there"
    )
    assert r2.summary["proposal"] == {
        "rear_foot_x_m": 8.1,
        "shift_m": 0.1,
        "tried": [{"rear_foot_x_m": 8.1, "outcome": "passes"}],
    }
