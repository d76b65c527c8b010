"""Gait planner, climbing trajectories and the climbing simulation gate."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import robots
from planners.cmbot import GaitParams, plan_climb, seed_guardrail
from planners.cmbot.gait import build_trajectory, chain_limits, plan_footholds
from planners.cmbot.guardrail import Guardrail, make_guardrail
from planners.cmbot.simulate import simulate_climb
from planners.errors import InfeasibleError, InvalidInputError, UnreachableError

# Tens of seconds (planning on the seed scenes): `make test` runs it, not `make test-fast`.
pytestmark = pytest.mark.slow

MODEL = robots.load_robot("cmbot")
L = MODEL.params["climber"]["foot_length_m"]


@pytest.fixture(scope="module")
def seed_plan():
    """The default walk: across the 10 cm gap on the seed scene, simulated."""
    return plan_climb(MODEL)


def test_footholds_valid_steps_bounded_and_gap_crossed(seed_plan):
    g = seed_plan.guardrail
    lim = seed_plan.limits
    stances = np.array(seed_plan.footholds)
    assert np.all(g.valid_foothold(stances.ravel(), L))
    d = stances[:, 1] - stances[:, 0]
    assert np.all(d >= lim.d_min - 1e-9) and np.all(d <= lim.d_max + 1e-9)
    steps = np.array([abs(ph.step_m) for ph in seed_plan.phases])
    assert np.all(steps <= lim.max_step + 1e-9) and np.all(steps > 0)
    gap = g.gaps[0]
    assert gap[1] - gap[0] == pytest.approx(0.10)
    assert stances[0, 1] < gap[0] and stances[-1, 0] > gap[1]  # both feet crossed it
    assert stances[-1, 0] == pytest.approx(seed_plan.goal_rear_x)


def test_seed_walk_passes_the_gate_and_counterweight_lowers_flip(seed_plan):
    assert seed_plan.gate is not None and seed_plan.gate.passed, seed_plan.gate.summary()
    m = seed_plan.metrics
    assert m["max_flip_torque_Nm"] < m["max_flip_torque_without_counterweight_Nm"]
    assert m["max_flip_torque_Nm"] <= m["magnet_holding_moment_Nm"]


def test_command_sequence_per_phase(seed_plan):
    for ph in seed_plan.phases:
        t = {(c.device, c.action): c.t_s for c in ph.commands}
        s, h = ph.swing, "rear" if ph.swing == "front" else "front"
        assert t[(f"magnet_{h}", "on")] <= t[("arm", "swing")] <= t[(f"plate_{s}", "release")]
        assert t[(f"plate_{s}", "release")] < t[(f"magnet_{s}", "off")] < t[(f"foot_{s}", "lift")]
        assert t[(f"foot_{s}", "lift")] < t[(f"foot_{s}", "touch_down")] <= t[(f"magnet_{s}", "on")]
        assert t[(f"magnet_{s}", "on")] < t[(f"plate_{s}", "seize")] <= ph.t_end
        assert t[(f"foot_{s}", "touch_down")] - t[(f"foot_{s}", "lift")] == pytest.approx(
            10.0
        )  # seed Tb


def test_joint_trajectory_reproduces_planned_soles(seed_plan):
    """FK of the planned joints (rear sole as base) lands on the planned front sole."""
    tr = seed_plan.trajectory
    T = MODEL.climber.fk(tr.q[:, :5])
    assert np.allclose(T[:, :3, 3] + tr.rear, tr.front, atol=1e-9)
    assert np.allclose(T[:, 2, 2], 1.0, atol=1e-12)  # soles stay parallel (φy = 0)


def test_backwards_walk_and_refusals():
    g = seed_guardrail()
    lim = chain_limits(MODEL, GaitParams())
    moves = plan_footholds(g, 3.5, 2.6, lim, 0.005)
    assert moves and all(b < a for _, a, b in moves)
    with pytest.raises(UnreachableError, match="post"):
        plan_footholds(g, 4.6, 5.9, lim, 0.005)
    with pytest.raises(UnreachableError, match="off the guardrail"):
        plan_footholds(g, 4.6, 40.0, lim, 0.005)
    wide = Guardrail(np.array([[0.0, 3.0], [3.4, 6.0]]), np.array([]))
    with pytest.raises(InfeasibleError, match="gap"):
        plan_footholds(wide, 1.0, 4.5, lim, 0.005)
    with pytest.raises(InvalidInputError):
        plan_climb(MODEL, goal_rear_x=float("nan"))


def test_long_random_guardrail_walk_is_planned():
    g = make_guardrail(20.0, seed=11)
    lim = chain_limits(MODEL, GaitParams())
    start = next(
        x
        for x in np.arange(0.5, 2.0, 0.01)
        if g.valid_foothold(np.array([x, x + lim.d_work]), L).all()
    )
    goal = next(
        x
        for x in np.arange(15.0, 17.0, 0.01)
        if g.valid_foothold(np.array([x, x + lim.d_work]), L).all()
    )
    moves = plan_footholds(g, start, goal, lim, 0.005)
    # Replayed here, move by move: a forward walk that ends on the goal stance
    # and never stands anywhere the chain or the guardrail forbids.
    rear, front = _replay(g, lim, start, moves)
    assert rear == pytest.approx(goal) and front == pytest.approx(goal + lim.d_work)
    # Each foot steps over each gap on the way exactly once (forward only).
    for g0, g1 in g.gaps[(g.gaps[:, 0] > start) & (g.gaps[:, 1] < goal)]:
        for kind in ("extension", "contraction"):
            over = [m for m in moves if m[0] == kind and m[1] < g0 and m[2] > g1]
            assert len(over) == 1, (kind, g0, g1, over)
    # Each foot travels goal − start in steps of at most S: at least
    # 2·⌈(goal − start)/S⌉ phases; the gaps and posts may cost a few more.
    assert len(moves) >= 2 * int(np.ceil((goal - start) / lim.max_step - 1e-9))


def _replay(g: Guardrail, lim, start: float, moves) -> tuple[float, float]:
    """Walk ``moves`` from the contracted stance at ``start`` (forward walk):
    an extension moves the front sole, a contraction the rear one, each from
    where that sole stands, forward by at most the step cap, onto a valid
    foothold, keeping the soles d_min…d_max apart.  Returns the final stance."""
    rear, front = start, start + lim.d_work
    for kind, a, b in moves:
        assert kind in ("extension", "contraction"), kind
        foot = front if kind == "extension" else rear
        assert a == pytest.approx(foot, abs=1e-9), (kind, a, foot)
        assert 0 < b - a <= lim.max_step + 1e-9, (kind, a, b)
        assert g.valid_foothold(np.array([b]), L).all(), (kind, b)
        front, rear = (b, rear) if kind == "extension" else (front, b)
        assert lim.d_min - 1e-9 <= front - rear <= lim.d_max + 1e-9, (rear, front)
    return rear, front


def test_clear_guardrail_walk_is_the_plain_inchworm():
    """Without gaps or posts the fewest phases are known in closed form: each
    sole must travel D in steps of at most S, ⌈D/S⌉ steps each, alternating."""
    clear = Guardrail(np.array([[0.0, 20.0]]), np.array([]))
    lim = chain_limits(MODEL, GaitParams())
    for start, goal in ((1.0, 1.3), (1.0, 5.03), (1.0, 15.0)):
        moves = plan_footholds(clear, start, goal, lim, 0.005)
        steps = int(np.ceil((goal - start) / lim.max_step - 1e-9))
        assert len(moves) == 2 * steps, (start, goal, len(moves))
        assert [m[0] for m in moves] == ["extension", "contraction"] * steps
        rear, front = _replay(clear, lim, start, moves)
        assert rear == pytest.approx(goal) and front == pytest.approx(goal + lim.d_work)


def test_gate_reports_where_and_when():
    """A weak magnet and a foothold moved onto a gap are both caught, with time and place."""
    g = seed_guardrail()
    p = GaitParams()
    moves = plan_footholds(g, 4.6, 4.84, chain_limits(MODEL, p), p.grid_m)
    _, tr = build_trajectory(MODEL, moves, 4.6, p)
    weak = dataclasses.replace(MODEL, params={**MODEL.params, "magnet": {"holding_force_N": 200.0}})
    rep = simulate_climb(weak, g, tr)
    flip = next(c for c in rep.checks if c.name == "flip_torque")
    assert not flip.passed and "about the" in flip.message and "t =" in flip.message
    bad = dataclasses.replace(
        tr, rear=tr.rear + np.array([0.98, 0.0, 0.0]), front=tr.front + np.array([0.98, 0.0, 0.0])
    )
    rep2 = simulate_climb(MODEL, g, bad)
    fp = next(c for c in rep2.checks if c.name == "foot_placement")
    assert not fp.passed
    assert any("gap" in v.where or "post" in v.where for v in rep2.violations)
