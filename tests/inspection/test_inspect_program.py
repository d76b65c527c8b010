"""The ``ara.inspect`` robot program: jump sites, shared jump
plans, the assembled program, the feet-attachment simulation."""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import pytest

import planners.inspection.jumps as jumps_mod
from planners.inspection.jumps import JumpSetParams, plan_site_jumps
from planners.inspection.layout import JumpSite, layout_program
from planners.inspection.plan import plan_inspection
from planners.inspection.program import simulate_attachment
from planners.inspection.program_plan import plan_route_program, world_origin
from planners.structure.pipeline import model_structure
from planners.switching.jump import JumpPhase, JumpPlan
from robots import load_robot
from robots.protocol.commands import WheelSpeeds, command_from_dict
from server.kinds import ara_inspect
from server.kinds.ara_inspect import (
    AraInspectParams,
    assemble_program,
    inspection_params,
    sample_points,
    structure_params,
)
from server.kinds.programs import replay_wheels

ARA: Any = load_robot("ara")
QM = np.asarray(ARA.q_mobile, dtype=np.float64)
TRACK = float(ARA.params["foot"]["wheel_track_m"])


@pytest.fixture(scope="module")
def default_plan():
    p = AraInspectParams()
    pts = np.asarray(sample_points(p.sample, p.sample_seed))
    model = model_structure(pts, params=structure_params(p))
    plan = plan_inspection(model, params=inspection_params(p))
    return pts, model, plan


def fake_jump(foothold: np.ndarray, spacing: float = 0.5) -> JumpPlan:
    """A timed trajectory mobile → P_conv → a landing pose (phases B, C,
    anchor foot 2) → mobile (phase E, anchor foot 1), the planner's phase
    layout and magnet commands; feet targets at the foothold and one foot
    spacing ahead of it."""
    q_conv = np.asarray(ARA.q_conv, dtype=np.float64)
    q_land = q_conv * 0.5
    dt = 0.02
    segs = [(QM, q_conv, 0), (q_conv, q_land, 0), (q_land, QM, 1)]
    qs: list[Any] = [QM[None]]
    ts: list[Any] = [np.zeros(1)]
    anchor: list[Any] = [np.zeros(1, int)]
    bounds: list[Any] = []
    t0, n = 0.0, 1
    for a, b, anc in segs:
        steps = int(np.ceil(np.max(np.abs(b - a)) / (0.8 * dt))) or 1
        s = np.linspace(0, 1, steps + 1)[1:]
        qs.append(a + s[:, None] * (b - a))
        ts.append(t0 + dt * np.arange(1, steps + 1))
        anchor.append(np.full(steps, anc))
        bounds.append((n, n + steps, t0, t0 + dt * steps))
        t0 += dt * steps
        n += steps
    bounds[0] = (0, bounds[0][1], 0.0, bounds[0][3])
    mags = {"foot1": "untouched", "foot2": "touched"}
    swap = {"foot1": "touched", "foot2": "untouched"}
    phases = [
        JumpPhase("A", "", "foot2", mags, 0, 0, 0.0, 0.0),
        JumpPhase("B", "", "foot2", mags, *bounds[0]),
        JumpPhase("C", "", "foot2", mags, *bounds[1]),
        JumpPhase("D", "", "foot1", swap, bounds[2][0], bounds[2][0], bounds[2][2], bounds[2][2]),
        JumpPhase("E", "", "foot1", swap, *bounds[2]),
        JumpPhase("F", "", "none", {}, n, n, t0, t0),
    ]
    f2 = np.asarray(foothold, float) @ np.array(
        [[1, 0, 0, spacing], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]]
    )
    T = np.concatenate(ts)
    return JumpPlan(
        times=T,
        joint_trajectory=np.vstack(qs),
        anchor=np.concatenate(anchor),
        clearance=np.full(len(T), 0.05),
        self_clearance=np.full(len(T), 0.05),
        phases=phases,
        magnet_commands=[],
        foot1_target=np.asarray(foothold, float),
        foot1_requested=np.asarray(foothold, float),
        foot2_target=f2,
        foot2_target_inside=True,
        waypoints=[],
        attempts_used=1,
        planning_time_s=0.0,
    )


@pytest.fixture
def fake_planner(monkeypatch):
    """Replace the OMPL jump planner by :func:`fake_jump`, counting calls."""
    calls: list[np.ndarray] = []

    def plan(robot: Any, foothold: np.ndarray, **kw: Any) -> JumpPlan:
        calls.append(np.asarray(foothold, float))
        return fake_jump(foothold)

    monkeypatch.setattr(jumps_mod, "plan_inchworm_jump", plan)
    monkeypatch.setattr(
        jumps_mod,
        "jump_clearance",
        lambda robot, plan, obstacles, **kw: (plan.clearance, plan.self_clearance),
    )
    return calls


def _assemble(parts) -> list[dict]:
    summary = {"program": parts.summary, "world_origin_m": parts.summary["world_origin_m"]}
    cmds = assemble_program(
        summary,
        parts.arrays.__getitem__,
        track_m=TRACK,
        speed_m_s=0.05,
        turn_rate_rad_s=0.5,
    )
    return [c.to_dict() for c in cmds]


# ------------------------------------------------------------------ the kind


class _Ctx:
    def __init__(self) -> None:
        self.stages: list[str] = []

    def progress(self, fraction: float, stage: str) -> None:
        self.stages.append(stage)

    def load_cloud(self, cloud_id: str) -> np.ndarray:
        raise AssertionError("no stored cloud in this test")


class _View:
    def __init__(self, out) -> None:
        self.result, self._arrays = out.result, out.arrays

    def array(self, name: str) -> np.ndarray:
        return self._arrays[name]


#: One panel at the default sample's (Warren seed 2) south-west end: two
#: diagonals, the end post and the two chords' ends, five jump sites — the
#: real layout, landing test and jump planner on a few sites (4–5 s, where
#: the whole truss's 30 sites took 56 s).
PANEL_BOX = ((480100.0, 5355157.0, 97.0), (480103.0, 5355160.5, 101.5))


def test_default_plan_compiles():
    """The default plan (scan_warren, seed 2; one panel of it) with ``plan_jumps``
    plans its jumps with the real planner and compiles: every command parses,
    the program starts with a base pose relative to the survey-frame origin,
    the progress names the jumps, a jump that was not planned is a failing
    check naming its transition (not an exception), and a transition beyond
    the arm is named by ``transitions_feasible`` with its wrist distance."""
    ctx = _Ctx()
    out = ara_inspect.run(AraInspectParams(plan_jumps=True, crop_box_m=PANEL_BOX), ctx)
    # The progress names every jump given to the planner (none, when no
    # placement of the panel's sites passes the landing test).
    calls = int(out.metrics["jump_planner_calls"])
    assert sum(s.startswith("jump ") and s.endswith(f"/{calls}") for s in ctx.stages) == calls
    assert out.metrics["jump_sites"] >= 2
    checks = {c.name: c for c in out.checks}
    for name in ("members_found", "gaps_explained"):
        assert checks[name].passed, checks[name].message
    assert out.metrics["member_count"] >= 3 and out.metrics["jumps"] >= 2
    # The route's checks: passed, or naming what fails (the arm's reach, S_hc).
    cov, feas = checks["members_covered"], checks["transitions_feasible"]
    assert cov.passed or "not inspected" in cov.message or "not on the main route" in cov.message
    if not feas.passed:
        assert "vertex " in feas.message and "member " in feas.message
        bad = [t for t in out.result["transitions"] if not t["feasible"]]
        assert len(bad) == int(feas.value)
        for t in bad:
            av = t["availability"]
            if av["plane"] and av["area"]:
                assert av["wrist_distance_m"] > av["arm_length_m"]
                assert f"{av['wrist_distance_m']:.3f} m apart > the 0.50 m arm" in t["reason"]
    for name in ("jumps_planned", "jump_clearance", "landings_on_steel", "feet_attached"):
        assert name in checks
    if not checks["jumps_planned"].passed:
        assert "transition " in checks["jumps_planned"].message
    assert checks["feet_attached"].passed, checks["feet_attached"].message
    program = ara_inspect.compile_program(_View(out))
    assert program
    for c in program:
        command_from_dict(c)
    assert program[0]["op"] == "base_pose"
    assert max(abs(v) for v in program[0]["position_m"]) < 1000.0
    origin = out.result["world_origin_m"]
    pts = sample_points("scan_warren", 2)
    lo, hi = np.asarray(PANEL_BOX)
    inside = pts[np.all((pts >= lo) & (pts <= hi), axis=1)]
    assert origin == np.floor(inside.min(axis=0)).tolist()
    assert out.metrics["program_duration_s"] > 0
    assert out.metrics["program_distance_m"] > 0


def test_world_origin():
    assert world_origin(np.array([[1.0, 2.0, 3.0], [-5.0, 0.0, 9999.0]])).tolist() == [0, 0, 0]
    far = np.array([[480100.7, 5355140.2, 97.5], [480120.0, 5355160.0, 101.0]])
    assert world_origin(far).tolist() == [480100.0, 5355140.0, 97.0]


# ------------------------------------------------------------------ attachment simulation


def _magnet(ch: int, on: bool) -> dict:
    return {"op": "magnet", "magnet": ch, "touched": on}


Q_OFF = (QM + np.array([0.0, 0.5, 0.0, 0.0, 0.5, 0.0])).tolist()
ALPHABET = {
    "m0+": _magnet(0, True),
    "m0-": _magnet(0, False),
    "m1+": _magnet(1, True),
    "m1-": _magnet(1, False),
    "off": {"op": "joints", "q_rad": Q_OFF, "duration_s": 1.0},
    "mob": {"op": "joints", "q_rad": QM.tolist(), "duration_s": 1.0},
    "drive": {"op": "wheels", "speeds_m_s": [0.05, 0.05], "duration_s": 1.0},
    "capture": {"op": "capture"},
}


def _reference(word: tuple[str, ...]) -> bool:
    """Independent statement of the rules: track (arm off mobile?, magnets);
    the robot is safe when at every step some foot grips the steel."""
    off, mag = False, [False, False]
    for w in word:
        if w in ("m0-", "m1-"):
            me = 0 if w == "m0-" else 1
            if mag[me] and off and not mag[1 - me]:
                return False
            mag[me] = False
        elif w in ("m0+", "m1+"):
            mag[0 if w == "m0+" else 1] = True
        elif w in ("off", "mob"):
            moving_off = off or w == "off"
            if moving_off and sum(mag) != 1:
                return False
            off = w == "off"
        elif w == "drive" and (off or any(mag)):
            return False
        if off and not any(mag):
            return False
    return True


def test_attachment_brute_force():
    """Every program of up to 4 commands over a small alphabet: the
    simulation agrees with an independent statement of the rules."""
    n_bad = 0
    for n in range(1, 5):
        for word in itertools.product(ALPHABET, repeat=n):
            res = simulate_attachment([ALPHABET[w] for w in word], q_mobile=QM)
            assert res.ok == _reference(word), word
            n_bad += not res.ok
    assert n_bad > 100


@pytest.mark.parametrize(
    ("word", "why"),
    [
        (("off",), "no foot touched"),
        (("m1+", "off", "m1-"), "releases foot2"),
        (("m1+", "off", "m0+", "m1-", "m0-"), "releases foot1"),
        (("m1+", "m0+", "off"), "both feet touched"),
        (("m1+", "drive"), "magnet touched"),
        (("m1+", "off", "m1-", "drive"), "releases foot2"),
    ],
)
def test_attachment_bad_programs(word, why):
    res = simulate_attachment([ALPHABET[w] for w in word], q_mobile=QM)
    assert not res.ok and why in res.message


def test_attachment_good_jump():
    word = ("drive", "m1+", "off", "m0+", "m1-", "mob", "m0-", "drive")
    assert simulate_attachment([ALPHABET[w] for w in word], q_mobile=QM).ok


# ------------------------------------------------------------------ sharing


def _moved(site: JumpSite, M: np.ndarray) -> JumpSite:
    return JumpSite(
        site.transition,
        site.vertex,
        site.landing_vertex,
        site.from_member,
        site.to_member,
        M @ site.standing,
        M @ site.landing,
        site.joint,
        site.landing_line,
        site.standing_line,
    )


def test_identical_geometries_planned_once(default_plan, fake_planner):
    """Sites with the same standing → landing transform share one plan; on
    the default plan there are fewer planner calls than sites."""
    pts, model, plan = default_plan
    lay = layout_program(model, plan)
    n_sites = len(lay.sites)
    out = plan_site_jumps(object(), lay, model, pts, JumpSetParams())
    assert out.planner_calls == len(fake_planner) == len(out.plans) < n_sites
    # the same geometry moved rigidly along the member: one call for all
    site = lay.sites[1]
    M = np.eye(4)
    M[:3, 3] = site.standing[:3, 0] * 0.003
    lay.sites = [site, _moved(site, M), _moved(site, M @ M)]
    fake_planner.clear()
    out = plan_site_jumps(object(), lay, model, pts, JumpSetParams())
    assert out.planner_calls == len(fake_planner) == 1
    assert [p.unique for p in out.placed] == [0, 0, 0]
    # the landing alone moved off its plane by 2 cm: another geometry
    other = _moved(site, np.eye(4))
    other.landing = other.landing.copy()
    other.landing[:3, 3] += site.landing[:3, 2] * 0.02
    lay.sites = [site, other]
    fake_planner.clear()
    out = plan_site_jumps(object(), lay, model, pts, JumpSetParams())
    assert out.planner_calls == 2


# ------------------------------------------------------------------ the program


@pytest.fixture
def fake_parts(default_plan, fake_planner):
    pts, model, plan = default_plan
    return plan_route_program(model, plan, pts, object(), joint_names=list(ARA.joint_names))


def test_program_with_jumps(fake_parts):
    """With every jump planned (stub), all stretches are placed, the
    program attaches a foot throughout and every command parses."""
    parts = fake_parts
    assert len(parts.summary["stretches"]) == parts.summary["stretches_total"]
    checks = {c.name: c for c in parts.checks}
    assert checks["jumps_planned"].passed, checks["jumps_planned"].message
    program = _assemble(parts)
    for c in program:
        command_from_dict(c)
    res = simulate_attachment(program, q_mobile=QM)
    assert res.ok, res.message
    assert sum(c["op"] == "base_pose" for c in program) == len(parts.summary["stretches"])
    # a program without "landed foot holds" lets go of both feet
    i = next(k for k, c in enumerate(program) if c == _magnet(0, True))
    assert not simulate_attachment(program[:i] + program[i + 1 :], q_mobile=QM).ok


def _stretch_blocks(program: list[dict]) -> list[list[dict]]:
    """The commands after each base_pose up to the next magnet / base_pose."""
    out: list[list[dict]] = []
    for c in program:
        if c["op"] == "base_pose":
            out.append([])
        elif out and c["op"] in ("wheels", "stop", "capture"):
            if not out[-1] or out[-1][-1] is not None:
                out[-1].append(c)
        elif out:
            out[-1].append(None)  # type: ignore[arg-type]
    return [[c for c in b if c is not None] for b in out]


def test_replayed_wheels_end_where_the_plan_says(fake_parts):
    parts = fake_parts
    program = _assemble(parts)
    blocks = _stretch_blocks(program)
    for st, block in zip(parts.summary["stretches"], blocks, strict=True):
        cmds = [command_from_dict(c) for c in block]
        end = replay_wheels(np.zeros(3), cmds, track_m=TRACK)[-1]
        want = np.asarray(st["waypoints"][-1], float)
        assert np.allclose(end[:2], want[:2], atol=1e-4), (end, want)
        assert abs((end[2] - want[2] + np.pi) % (2 * np.pi) - np.pi) < 1e-4
        assert all(
            abs(v) <= 0.05 + 1e-9 for c in cmds if isinstance(c, WheelSpeeds) for v in c.speeds_m_s
        )


def test_captures_every_half_metre(fake_parts):
    program = _assemble(fake_parts)
    dist = 0.0
    for c in program:
        if c["op"] == "wheels" and abs(c["speeds_m_s"][0] - c["speeds_m_s"][1]) < 1e-12:
            dist += abs(c["speeds_m_s"][0]) * c["duration_s"]
        if c["op"] == "capture":
            assert dist <= 0.5 + 1e-3
            dist = 0.0


def test_jump_waypoints_match_stored_trajectory(fake_parts):
    parts = fake_parts
    program = _assemble(parts)
    off = parts.arrays["jump_offsets"]
    q = parts.arrays["jump_q"]
    runs: list[list[np.ndarray]] = []
    for c in program:
        if c["op"] == "joints":
            if not runs or runs[-1] is None:
                runs.append([])
            runs[-1].append(np.asarray(c["q_rad"]))
        elif c["op"] in ("wheels", "base_pose") and runs and runs[-1] is not None:
            runs.append(None)
    runs = [r for r in runs if r is not None]
    sites = [s for s in parts.summary["sites"] if s["unique"] is not None]
    assert len(runs) == len(sites)
    for run, site in zip(runs, sites, strict=True):
        k = site["unique"]
        traj = q[off[k] : off[k + 1]]
        assert np.allclose(run[0], traj[0]) and np.allclose(run[-1], traj[-1])
