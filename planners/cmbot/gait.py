"""Inchworm gait planner along the guardrail (seed §3.1, Fig. 9; Eq. 8–11).

A step has an extension phase (rear foot holds, the front foot swings
forward) and a contraction phase (front foot holds, the rear foot follows).
Footholds are searched on a grid along the top bar: every sole lies wholly on
one bar segment and off every post joint, the two soles stay between the
closest and farthest distances the chain reaches with φy = 0, and no swing is
longer than the step limit S.  Weighted A* over stances (phases, plus a
penalty on stances wider than the plain gait; heuristic: remaining distance
of each foot / S) finds the walk or proves there is none.

Each phase is then timed — counterweight swing of the folded arm with both
feet held, limiting-plate release, magnet off, the Eq. 11 compound-cycloid
swing, magnet on, plate seize — and turned into joint trajectories by the
closed-form IK (Eq. 8) and the counterweight angle (Eq. 10).
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.ndimage import gaussian_filter1d

from planners.cmbot.arm import ArmKinematics
from planners.cmbot.balance import (
    arm_mass_points,
    climber_mass_points,
    flip_moment,
    folded_arm,
    merge,
)
from planners.cmbot.climbing_kinematics import climber_ik_batch
from planners.cmbot.foot_trajectory import compound_cycloid, smooth_blend
from planners.cmbot.guardrail import Guardrail
from planners.cmbot.scene import arm_base_pose
from planners.errors import InfeasibleError, InvalidInputError, UnreachableError

#: Weight on the A* heuristic (> 1: weighted A*, at most this factor above the
#: fewest phases, far fewer states expanded on long walks).
H_WEIGHT = 1.5

#: Largest angular acceleration [rad/s²] the counterweight swing may demand of J6 (chosen).
ARM_SWING_ACC = 4.0


@dataclass(frozen=True)
class GaitParams:
    """Gait settings; ``None`` takes the robot's params.toml value (the seed's
    S = 240 mm, H = 50 mm, D = 0, Tb = 10 s)."""

    max_step_m: float | None = None
    lift_m: float | None = None
    side_m: float | None = None
    phase_time_s: float | None = None
    switch_time_s: float | None = None
    dt_s: float = 0.02
    grid_m: float = 0.005
    counterweight: bool = True


@dataclass(frozen=True)
class Command:
    """One timed command of the magnet / limiting plate / arm sequence."""

    t_s: float
    device: str  # magnet_front|magnet_rear|plate_front|plate_rear|range_front|range_rear|arm|foot_front|foot_rear
    action: str  # on|off|seize|release|check|swing|lift|touch_down


@dataclass(frozen=True)
class Phase:
    """One half-step: ``kind`` extension (front swings) or contraction (rear swings)."""

    index: int
    kind: str
    swing: str
    x_from: float
    x_to: float
    t_start: float
    t_lift: float
    t_touch: float
    t_end: float
    commands: list[Command] = field(default_factory=list)

    @property
    def step_m(self) -> float:
        return self.x_to - self.x_from


@dataclass(frozen=True)
class ChainLimits:
    """Geometric limits of the climbing chain: sole distance range and step cap."""

    d_min: float
    d_max: float
    d_work: float
    max_step: float
    foot_length: float

    @property
    def d_nominal(self) -> float:
        """Widest stance of the plain inchworm gait: contracted + one step."""
        return min(self.d_work + self.max_step, self.d_max)


def chain_limits(model: Any, params: GaitParams) -> ChainLimits:
    """Closest/farthest sole distances with φy = 0 within the knee-bend and joint limits."""
    c = model.params["climber"]
    l2 = c["l2"]
    bend = np.radians(c["min_knee_bend_deg"])
    d_max = 2.0 * l2 * np.cos(bend / 2.0)
    d_min = c["min_foot_distance_m"]
    # Both ends and the swing apex must be inside the joint limits.
    xs = np.linspace(d_min, d_max, 200)
    _, ok = climber_ik_batch(
        np.column_stack([xs, 0 * xs, 0 * xs]), 0.0, c["l1"], l2, model.climber.joint_limits
    )
    if not ok.any():
        raise UnreachableError("the climbing chain cannot stand with both soles on the bar")
    d_min, d_max = float(xs[ok][0]), float(xs[ok][-1])
    step = params.max_step_m if params.max_step_m is not None else c["step_m"]
    step = min(step, d_max - d_min)
    return ChainLimits(d_min, d_max, c["work_foot_distance_m"], step, c["foot_length_m"])


def plan_footholds(
    guardrail: Guardrail, start_rear_x: float, goal_rear_x: float, lim: ChainLimits, grid: float
) -> list[tuple[str, float, float]]:
    """Sequence of ``(kind, x_from, x_to)`` swings taking the contracted stance
    (rear at ``start_rear_x``, front d_work ahead) to the same stance at
    ``goal_rear_x``.  Walks backwards (rear foot leading) when the goal is behind.
    """
    L = lim.foot_length
    d0 = lim.d_work
    for name, x in (
        ("start rear", start_rear_x),
        ("start front", start_rear_x + d0),
        ("goal rear", goal_rear_x),
        ("goal front", goal_rear_x + d0),
    ):
        why = guardrail.why_invalid(x, L)
        if why:
            raise UnreachableError(f"{name} foothold invalid: {why}")
    if abs(goal_rear_x - start_rear_x) < 1e-9:
        return []
    sign = 1.0 if goal_rear_x > start_rear_x else -1.0
    # In walking coordinates u = sign·x the leading foot is "front".
    lead0 = sign * (start_rear_x + (d0 if sign > 0 else 0.0))
    trail0 = sign * (start_rear_x + (0.0 if sign > 0 else d0))
    lead_goal = sign * (goal_rear_x + (d0 if sign > 0 else 0.0))
    trail_goal = sign * (goal_rear_x + (0.0 if sign > 0 else d0))
    lo = np.floor((min(trail0, lead_goal) - lim.d_max) / grid) * grid
    hi = max(trail0, lead_goal) + lim.d_max
    n = int(np.ceil((hi - lo) / grid)) + 1
    us = np.round(lo + grid * np.arange(n), 9)
    valid = guardrail.valid_foothold(sign * us, L)
    snap = 1e-9

    # Runs of consecutive valid grid positions: their ends are the footholds
    # that matter (right before a gap or post); with the farthest reachable one
    # and the goal they keep the search small without losing feasibility in
    # practice.
    edges = np.diff(np.concatenate([[0], valid.astype(int), [0]]))
    run_lo = np.flatnonzero(edges == 1)
    run_hi = np.flatnonzero(edges == -1) - 1

    def cands(a: float, b: float, target: float) -> list[float]:
        """Candidate footholds in (a, b], farthest first, ``target`` first when inside."""
        i0 = max(int(np.floor((a + snap - lo) / grid)) + 1, 0)
        i1 = min(int(np.floor((b + snap - lo) / grid)), n - 1)
        out: set[int] = set()
        if i1 >= i0:
            k = np.searchsorted(run_lo, i1, side="right") - 1  # last run starting ≤ i1
            while k >= 0 and run_hi[k] >= i0:
                hi_i = min(run_hi[k], i1)
                lo_i = max(run_lo[k], i0)
                out.update({hi_i, lo_i, (hi_i + lo_i) // 2})
                k -= 1
        c = sorted((float(us[i]) for i in out if us[i] > a + snap), reverse=True)
        if a + snap < target <= b + snap:
            c = [target, *[u for u in c if abs(u - target) > snap]]
        return c

    def h(trail: float, lead: float) -> int:
        # each phase moves one foot by at most S: admissible lower bound on the phases left
        return int(np.ceil(max(lead_goal - lead, 0.0) / lim.max_step - 1e-9)) + int(
            np.ceil(max(trail_goal - trail, 0.0) / lim.max_step - 1e-9)
        )

    # A* over stances (trail, lead): a phase moves either foot forward (two
    # contractions in a row are allowed, e.g. to close up on the goal).
    start = (trail0, lead0)
    key0 = (round(trail0 / grid), round(lead0 / grid))
    best_g: dict[tuple[int, int], float] = {key0: 0.0}
    parent: dict[
        tuple[int, int], tuple[tuple[int, int], tuple[str, float, float], tuple[float, float]]
    ] = {}
    heap: list[tuple[float, float, float, float, float]] = [
        (h(*start), -(trail0 + lead0), 0.0, trail0, lead0)
    ]
    blocked_at = lead0
    while heap:
        _f, _tie, g_cost, trail, lead = heapq.heappop(heap)
        key = (round(trail / grid), round(lead / grid))
        if g_cost > best_g.get(key, np.inf):
            continue
        blocked_at = max(blocked_at, lead)
        if abs(trail - trail_goal) < snap and abs(lead - lead_goal) < snap:
            path: list[tuple[str, float, float]] = []
            k = key
            while k in parent:
                k, move, _ = parent[k]
                path.append(move)
            return _unmirror(path[::-1], sign)
        succ = []
        b = min(lead + lim.max_step, trail + lim.d_max, lead_goal)
        for u in cands(lead, b, lead_goal):
            succ.append((trail, u, ("extension", lead, u)))
        b = min(trail + lim.max_step, lead - lim.d_min, trail_goal)
        for u in cands(trail, b, trail_goal):
            if lead - u <= lim.d_max + snap:
                succ.append((u, lead, ("contraction", trail, u)))
        for tr_, ld_, move in succ:
            k2 = (round(tr_ / grid), round(ld_ / grid))
            # A stance wider than the seed's gait (d_work + S) costs extra, so it
            # is used only where the footholds demand it (gaps next to posts):
            # the flip moment grows with the stance width.
            g2 = g_cost + 1 + 4.0 * max(0.0, (ld_ - tr_) - lim.d_nominal)
            if g2 < best_g.get(k2, np.inf) - 1e-12:
                best_g[k2] = g2
                parent[k2] = (key, move, (tr_, ld_))
                heapq.heappush(heap, (g2 + H_WEIGHT * h(tr_, ld_), -(tr_ + ld_), g2, tr_, ld_))
    x_block = sign * blocked_at
    near_gap = [g for g in guardrail.gaps if abs((g[0] + g[1]) / 2 - x_block) < lim.d_max + 0.5]
    hint = ""
    if near_gap:
        g = near_gap[0]
        hint = (
            f"; the gap [{g[0]:.3f}, {g[1]:.3f}] m needs a step of ≥ {g[1] - g[0] + L:.3f} m "
            f"(gap + sole length) with footholds free of posts on both sides"
        )
    raise InfeasibleError(
        f"no foothold sequence reaches the goal rear-foot x = {goal_rear_x:.3f} m: the walk is blocked "
        f"beyond x ≈ {x_block:.3f} m with steps ≤ {lim.max_step:.3f} m and soles "
        f"{lim.d_min:.3f}–{lim.d_max:.3f} m apart{hint}"
    )


def _unmirror(path: list[tuple[str, float, float]], sign: float) -> list[tuple[str, float, float]]:
    # Backwards (sign < 0): the leading (rear) foot "extends" backwards, the front follows.
    return [(k, round(sign * a, 9), round(sign * b, 9)) for k, a, b in path]


@dataclass
class GaitTrajectory:
    """Sampled climbing motion: world poses of both soles, joints J1…J12,
    which foot holds, flip moments with and without the counterweight."""

    times: np.ndarray
    q: np.ndarray  # (T,12) J1…J12
    rear: np.ndarray  # (T,3) rear sole centre in the world
    front: np.ndarray  # (T,3)
    support: np.ndarray  # (T,) 0 both feet, 1 rear only, 2 front only
    flip_Nm: np.ndarray  # (T,3) moment about the holding sole (Eq. 9), counterweight as planned
    flip_no_cw_Nm: np.ndarray  # (T,3) same with the arm held vertical
    phase_index: np.ndarray  # (T,)


def phase_timeline(
    moves: list[tuple[str, float, float]],
    start_rear_x: float,
    d_work: float,
    Tb: float,
    switch: float,
    arm_swing: list[float],
) -> list[Phase]:
    """Phase timing and the magnet / plate / arm command sequence of every move."""
    phases = []
    t = 0.0
    for i, (kind, a, b) in enumerate(moves):
        # Which physical foot swings: extension moves the leading foot.
        forward = b > a
        swing = (
            ("front" if forward else "rear")
            if kind == "extension"
            else ("rear" if forward else "front")
        )
        hold = "rear" if swing == "front" else "front"
        t_arm = arm_swing[i]
        cmds = [
            Command(t, f"magnet_{hold}", "on"),
            Command(t, f"plate_{hold}", "seize"),
            Command(t, "arm", "swing"),
            Command(t + t_arm, f"plate_{swing}", "release"),
            Command(t + t_arm + switch, f"magnet_{swing}", "off"),
            Command(t + t_arm + 2 * switch, f"foot_{swing}", "lift"),
            Command(t + t_arm + 2 * switch + Tb, f"foot_{swing}", "touch_down"),
            Command(t + t_arm + 2 * switch + Tb, f"range_{swing}", "check"),
            Command(t + t_arm + 2 * switch + Tb, f"magnet_{swing}", "on"),
            Command(t + t_arm + 3 * switch + Tb, f"plate_{swing}", "seize"),
        ]
        t_lift = t + t_arm + 2 * switch
        t_touch = t_lift + Tb
        t_end = t_touch + 2 * switch
        phases.append(Phase(i, kind, swing, a, b, t, t_lift, t_touch, t_end, cmds))
        t = t_end
    return phases


def _ik_path(model: Any, rear: np.ndarray, front: np.ndarray) -> np.ndarray:
    c = model.params["climber"]
    q, ok = climber_ik_batch(front - rear, 0.0, c["l1"], c["l2"], model.climber.joint_limits)
    if not ok.all():
        k = int(np.argmin(ok))
        raise UnreachableError(
            f"sole distance {np.linalg.norm(front[k] - rear[k]):.4f} m is outside the climbing chain's reach"
        )
    return q


def _poses(rear: np.ndarray) -> np.ndarray:
    T = np.broadcast_to(np.eye(4), (len(rear), 4, 4)).copy()
    T[:, :3, 3] = rear
    return T


def _soft_clip(x: np.ndarray, m: float) -> np.ndarray:
    """Smooth saturation to ±m (keeps the counterweight rate finite at the limit)."""
    return m * np.tanh(np.asarray(x) / m)


def counterweight_plan(
    model: Any,
    arm: ArmKinematics,
    q_climb: np.ndarray,
    rear: np.ndarray,
    pivot: np.ndarray,
    dt: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Eq. 9–10 over one swing: θ6 with the arm vertical and with the
    counterweight, and the flip moment with the arm vertical (T,3)."""
    a = model.params["arm"]
    q_fold = np.radians(a["fold_deg"])
    fa = folded_arm(arm, q_fold)
    T_wr = _poses(rear)
    T_wk = arm_base_pose(model, q_climb, T_wr)
    R = T_wk[:, :3, :3]
    th_v = fa.vertical_angle(R)
    th_v = np.unwrap(th_v)
    qa = np.tile(q_fold, (len(rear), 1))
    qa[:, 0] = th_v
    pts = merge(climber_mass_points(model, q_climb, T_wr), arm_mass_points(arm, qa, T_wk))
    M_no = flip_moment(pts, pivot, dt)
    A, B, _, _ = fa._coeffs(R)
    phi = np.arctan2(B, A)
    s = np.sign(np.sin(th_v - phi))
    s = np.where(s == 0, 1.0, s)
    ratio = M_no[:, 1] / (fa.mass * 9.81 * np.maximum(np.hypot(A, B), 1e-9))
    # Eq. 10 exact form δ = arcsin(s·ratio); the ratio is saturated smoothly at
    # sin(max swing) so δ never exceeds the allowed swing and stays C¹ (a hard
    # clip would put an acceleration spike into the arm's own inertia term).
    sat = np.sin(np.radians(a["max_swing_deg"]))
    delta = np.arcsin(_soft_clip(s * ratio, sat))
    # The arm cannot follow M_y's fast dynamic part, and chasing it would add
    # its own inertia to Eq. 9: smooth the swing and scale it so J6 stays
    # within 90 % of its speed and the acceleration cap (partial compensation
    # on fast gaits, full compensation on the seed's slow one).
    if len(delta) > 3:
        delta = gaussian_filter1d(delta, sigma=max(1.0, 0.03 * len(delta)), mode="nearest")
        rate = np.abs(np.gradient(delta, dt))
        acc = np.abs(np.gradient(np.gradient(delta, dt), dt))
        w6 = float(model.max_speed[0])
        alpha = min(1.0, 0.9 * w6 / max(rate.max(), 1e-12), ARM_SWING_ACC / max(acc.max(), 1e-12))
        delta = alpha * delta
    return th_v, th_v + delta, M_no


def build_trajectory(
    model: Any,
    moves: list[tuple[str, float, float]],
    start_rear_x: float,
    params: GaitParams,
) -> tuple[list[Phase], GaitTrajectory]:
    """Time, IK and counterweight for a foothold sequence (seed Eq. 8–11)."""
    c = model.params["climber"]
    arm = ArmKinematics.from_model(model)
    H = params.lift_m if params.lift_m is not None else c["lift_m"]
    D = params.side_m if params.side_m is not None else c["side_m"]
    Tb = params.phase_time_s if params.phase_time_s is not None else c["phase_time_s"]
    sw = params.switch_time_s if params.switch_time_s is not None else c["magnet_switch_time_s"]
    if Tb <= 0 or sw < 0 or H < 0 or params.dt_s <= 0:
        raise InvalidInputError("need phase_time_s > 0, switch_time_s ≥ 0, lift_m ≥ 0, dt_s > 0")
    dt = params.dt_s
    d0 = c["work_foot_distance_m"]
    w6 = float(model.max_speed[0])
    q_fold = np.radians(model.params["arm"]["fold_deg"])
    rear_x, front_x = start_rear_x, start_rear_x + d0
    # First pass: swings and counterweight per move (needs the arm angle at lift-off).
    swings = []
    for kind, a, b in moves:
        n = max(int(np.ceil(Tb / dt)), 2)
        ts = np.linspace(0.0, Tb, n + 1)
        pos, _, _ = compound_cycloid(ts, b - a, H, D, Tb)
        swing_front = (kind == "extension") == (b > a)
        if swing_front:
            front = np.column_stack([front_x + pos[:, 0], pos[:, 1], pos[:, 2]])
            rear = np.tile([rear_x, 0.0, 0.0], (len(ts), 1))
            pivot = rear
            front_x = b
        else:
            rear = np.column_stack([rear_x + pos[:, 0], pos[:, 1], pos[:, 2]])
            front = np.tile([front_x, 0.0, 0.0], (len(ts), 1))
            pivot = front
            rear_x = b
        q = _ik_path(model, rear, front)
        th_v, th_cw, _ = counterweight_plan(model, arm, q, rear, pivot, ts[1] - ts[0])
        th = th_cw if params.counterweight else th_v
        swings.append((ts, rear, front, q, th, th_v, pivot, swing_front))
    # Arm swing time before each lift-off: cycloid blend from the previous angle.
    prev = None
    t_arm = []
    for *_, th, th_v, _pivot, _sf in swings:
        start_angle = th_v[0] if prev is None else prev
        t_arm.append(max(2.0 * abs(th[0] - start_angle) / (0.95 * w6), sw))
        prev = th[-1]
    phases = phase_timeline(moves, start_rear_x, d0, Tb, sw, t_arm)
    # Second pass: sample everything on one clock.
    T_list, q_list, r_list, f_list, s_list, p_list = [], [], [], [], [], []
    prev_angle = None
    rear_x, front_x = start_rear_x, start_rear_x + d0
    for ph, (ts, rear, front, q, th, th_v, _pivot, swing_front) in zip(phases, swings, strict=True):
        # Double support: arm swings to its lift-off angle, plate release, magnet off.
        t_hold = np.arange(ph.t_start, ph.t_lift - 1e-9, dt)
        start_angle = th_v[0] if prev_angle is None else prev_angle
        blend = smooth_blend(t_hold - ph.t_start, ph.t_lift - ph.t_start - 2 * sw)
        a6 = start_angle + blend * (th[0] - start_angle)
        qh = np.tile(q[0], (len(t_hold), 1))
        T_list.append(t_hold)
        q_list.append(np.column_stack([qh, a6, np.tile(q_fold[1:], (len(t_hold), 1))]))
        r_list.append(np.tile(rear[0], (len(t_hold), 1)))
        f_list.append(np.tile(front[0], (len(t_hold), 1)))
        s_list.append(np.zeros(len(t_hold), dtype=int))
        p_list.append(np.full(len(t_hold), ph.index))
        # Single support: the swing.
        T_list.append(ph.t_lift + ts[:-1])
        q_list.append(np.column_stack([q[:-1], th[:-1], np.tile(q_fold[1:], (len(ts) - 1, 1))]))
        r_list.append(rear[:-1])
        f_list.append(front[:-1])
        s_list.append(np.full(len(ts) - 1, 1 if swing_front else 2))
        p_list.append(np.full(len(ts) - 1, ph.index))
        # Touch-down, magnet on, plate seize (both feet).
        t_post = np.arange(ph.t_touch, ph.t_end - 1e-9, dt)
        T_list.append(t_post)
        q_list.append(np.tile(np.concatenate([q[-1], [th[-1]], q_fold[1:]]), (len(t_post), 1)))
        r_list.append(np.tile(rear[-1], (len(t_post), 1)))
        f_list.append(np.tile(front[-1], (len(t_post), 1)))
        s_list.append(np.zeros(len(t_post), dtype=int))
        p_list.append(np.full(len(t_post), ph.index))
        prev_angle = th[-1]
    # Final: arm back to vertical, then hold.
    if swings:
        ts, rear, front, q, th, th_v, *_ = swings[-1]
        t0 = phases[-1].t_end
        t_back = max(2.0 * abs(th[-1] - th_v[-1]) / (0.95 * w6), sw)
        tt = np.arange(t0, t0 + t_back + dt / 2, dt)
        a6 = th[-1] + smooth_blend(tt - t0, t_back) * (th_v[-1] - th[-1])
        T_list.append(tt)
        q_list.append(
            np.column_stack([np.tile(q[-1], (len(tt), 1)), a6, np.tile(q_fold[1:], (len(tt), 1))])
        )
        r_list.append(np.tile(rear[-1], (len(tt), 1)))
        f_list.append(np.tile(front[-1], (len(tt), 1)))
        s_list.append(np.zeros(len(tt), dtype=int))
        p_list.append(np.full(len(tt), len(phases) - 1))
    else:
        q0 = _ik_path(
            model, np.array([[start_rear_x, 0, 0]]), np.array([[start_rear_x + d0, 0, 0]])
        )
        T_list.append(np.zeros(1))
        q_list.append(np.column_stack([q0, [0.0], q_fold[None, 1:]]))
        r_list.append(np.array([[start_rear_x, 0, 0]]))
        f_list.append(np.array([[start_rear_x + d0, 0, 0]]))
        s_list.append(np.zeros(1, dtype=int))
        p_list.append(np.zeros(1, dtype=int))
    traj = GaitTrajectory(
        np.concatenate(T_list),
        np.concatenate(q_list),
        np.concatenate(r_list),
        np.concatenate(f_list),
        np.concatenate(s_list),
        np.zeros((0, 3)),
        np.zeros((0, 3)),
        np.concatenate(p_list),
    )
    traj.flip_Nm, traj.flip_no_cw_Nm = flip_moments(model, arm, traj)
    return phases, traj


def flip_moments(
    model: Any,
    arm: ArmKinematics,
    traj: GaitTrajectory,
    times: np.ndarray | None = None,
    q: np.ndarray | None = None,
    rear: np.ndarray | None = None,
    front: np.ndarray | None = None,
    support: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 9 about the holding sole along a (possibly resampled) trajectory,
    with the planned arm angle and with the arm held vertical."""
    t = traj.times if times is None else times
    q = traj.q if q is None else q
    rear = traj.rear if rear is None else rear
    front = traj.front if front is None else front
    sup = traj.support if support is None else support
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    T_wr = _poses(rear)
    T_wk = arm_base_pose(model, q[:, :5], T_wr)
    cl = climber_mass_points(model, q[:, :5], T_wr)
    pivot = np.where((sup == 2)[:, None], front, rear)
    M = flip_moment(merge(cl, arm_mass_points(arm, q[:, 5:], T_wk)), pivot, dt)
    fa = folded_arm(arm, np.radians(model.params["arm"]["fold_deg"]))
    qv = q[:, 5:].copy()
    qv[:, 0] = np.unwrap(fa.vertical_angle(T_wk[:, :3, :3]))
    M0 = flip_moment(merge(cl, arm_mass_points(arm, qv, T_wk)), pivot, dt)
    return M, M0
