"""Joint trajectory of the sand-blasting planner (seed 004, §3.4.1.3,
Eq. 3.12–3.13, §3.4.2): way-points through the sequenced spots, branch
choice by dynamic programming, certified-free moves, via-point and
RRT-Connect transitions.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from planners.blasting import arm as _arm
from planners.blasting import motion as _motion
from planners.blasting.collision import Obstacles
from planners.blasting.constants import (
    CLEAR_HORIZON_M,
    CLEAR_REL_TOL,
    FOCI,
    JUMP_RAD,
    RETRACT_M,
    RRT_BUDGET_ITER,
    RRT_MAX_ITER,
    SAFETY_M,
    STEP_RAD,
)
from planners.blasting.spots import _family_mask
from planners.errors import InfeasibleError


@dataclass
class _Traj:
    q: np.ndarray
    segment: np.ndarray
    spot: np.ndarray
    unreached: np.ndarray
    stats: dict[str, int]  # joint-planner counters (calls, failures, nodes, ...)


class _Clearance:
    """Ellipsoid clearance of the arm (§3.4.2) less the safety margin, as the
    planner's validity functions: ``val`` (bounded by the horizon, with the
    relative tolerance; > 0 is free) and ``sign`` (sign-exact, cheaper)."""

    def __init__(self, robot: Any, obst: Obstacles, nozzle_m: float, kp: tuple[float, ...]) -> None:
        self.robot, self.obst, self.nozzle_m, self.kp = robot, obst, nozzle_m, kp

    def val(self, qq: np.ndarray) -> np.ndarray:
        qq = np.atleast_2d(qq)
        if self.obst.empty:
            return np.full(len(qq), np.inf)
        c = _arm.waypoint_clearance(
            self.robot, qq, self.obst, self.nozzle_m, self.kp, FOCI,
            horizon=CLEAR_HORIZON_M, rel_tol=CLEAR_REL_TOL,
        )  # fmt: skip
        return c - SAFETY_M  # > 0: free with the safety margin

    def sign(self, qq: np.ndarray) -> np.ndarray:
        c = _arm.waypoint_clearance(
            self.robot, qq, self.obst, self.nozzle_m, self.kp, FOCI, sign_only=True, margin=SAFETY_M
        )
        return c - SAFETY_M


def _cartesian_waypoints(
    order: np.ndarray, flange: np.ndarray, axes: np.ndarray, fam: np.ndarray, step_m: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Straight flange moves between consecutive spots every ``step_m``
    (§3.4.1.3), the nozzle axis interpolated and renormalised: way-point
    positions P, axes A, spot id (−1 between spots) and the arm family each
    way-point belongs to (−1: any; the family of its spots when both agree)."""
    P, A, spot = [flange[order[0]]], [axes[order[0]]], [order[0]]
    wfam = [fam[order[0]]]
    for a_i, b_i in itertools.pairwise(order):
        L = float(np.linalg.norm(flange[b_i] - flange[a_i]))
        n = max(1, int(np.ceil(L / step_m)))
        t = np.arange(1, n + 1)[:, None] / n
        P.append(flange[a_i] + t * (flange[b_i] - flange[a_i]))
        ax = axes[a_i] + t * (axes[b_i] - axes[a_i])
        A.append(ax / np.linalg.norm(ax, axis=1, keepdims=True))
        spot.append(np.r_[np.full(n - 1, -1), b_i])
        between = fam[a_i] if fam[a_i] == fam[b_i] else -1
        wfam.append(np.r_[np.full(n - 1, between), fam[b_i]])
    return (
        np.vstack([np.atleast_2d(p) for p in P]),
        np.vstack([np.atleast_2d(a) for a in A]),
        np.concatenate([np.atleast_1d(s) for s in spot]).astype(int),
        np.concatenate([np.atleast_1d(f) for f in wfam]).astype(int),
    )


def _waypoint_branches(
    robot: Any,
    P: np.ndarray,
    A: np.ndarray,
    spot: np.ndarray,
    wfam: np.ndarray,
    Qs: np.ndarray,
    oks: np.ndarray,
    q_start: np.ndarray,
    clear: _Clearance,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """IK branch per way-point by the least-joint-change DP
    (:func:`planners.blasting.arm.choose_branches`, §3.4.1); way-points whose
    chosen configuration penetrates an obstacle lose that branch and the DP
    is re-run (up to 4 times).  Spots keep their own solution set (tilt /
    approximate IK included) and are never dropped.  Returns the usable
    way-points' mask, their configurations and their spot ids."""
    Q, ok = robot.ik_axis(P, A, q_start)
    at = spot >= 0
    Q[at] = Qs[spot[at]]
    ok[at] = oks[spot[at]]
    grouped = wfam >= 0
    if grouped.any():
        ok[grouped] &= _family_mask(wfam[grouped])
    # sign-only clearance per (way-point, branch), kept across the re-runs:
    # a re-run moves few way-points to another branch, and a configuration's
    # value does not depend on what it is evaluated with
    known = np.full(ok.shape, np.nan)
    for _ in range(4):
        usable = ok.any(axis=1)
        usable[at] = True
        Qu, oku, spu = Q[usable], ok[usable], spot[usable]
        br = _arm.choose_branches(Qu, oku, q_start)
        qb = Qu[np.arange(len(Qu)), br]
        if clear.obst.empty:
            bad = np.zeros(len(qb), dtype=bool)
        else:
            rows_u = np.nonzero(usable)[0]
            sv = known[rows_u, br]
            todo = np.isnan(sv)
            sv[todo] = clear.sign(qb[todo])
            known[rows_u[todo], br[todo]] = sv[todo]
            bad = sv <= 0
        bad &= spu < 0  # spots were checked already
        if not bad.any():
            break
        rows = np.nonzero(usable)[0][bad]
        ok[rows, br[bad]] = False
    return usable, qb, spu


def _retracts(
    robot: Any, k: int, Pu: np.ndarray, Au: np.ndarray, qb: np.ndarray, clear: _Clearance
) -> list[np.ndarray]:
    """Poses of way-point ``k`` with the flange backed off along the
    nozzle axis (same arm family, nearest branch), clear of obstacles:
    moving in or out along the axis keeps the wrist out of the surface."""
    if k < 0 or clear.obst.empty:
        return []
    pr = Pu[k][None] - RETRACT_M[:, None] * Au[k][None]
    Qr, okr = robot.ik_axis(pr, np.repeat(Au[k][None], len(pr), axis=0), qb[k])
    out = []
    for j in range(len(pr)):
        if not okr[j].any():
            continue
        d = np.where(okr[j], np.abs(Qr[j] - qb[k]).max(axis=1), np.inf)
        out.append(Qr[j, int(np.argmin(d))])
    if not out:
        return []
    R = np.stack(out)
    return list(R[clear.val(R) > 0])


def _certify_short_steps(
    qb: np.ndarray, c_wp: np.ndarray, clear: _Clearance, w: np.ndarray
) -> np.ndarray:
    """Certify the short blasting moves (joint change ≤ :data:`JUMP_RAD`) in
    one batch with :func:`planners.blasting.motion.edge_free` (clearance
    against a bound on how far the arm moves); entry k: the move k−1 → k."""
    n_wp = len(qb)
    step_ok = np.zeros(n_wp, dtype=bool)
    if n_wp > 1:
        short = np.abs(np.diff(qb, axis=0)).max(axis=1) <= JUMP_RAD
        k = np.nonzero(short)[0]
        if clear.obst.empty:
            step_ok[k + 1] = True
        elif len(k):
            step_ok[k + 1] = _motion.edge_free(
                qb[k], qb[k + 1], clear.val, w, ca=c_wp[k], cb=c_wp[k + 1]
            )
    return step_ok


def _trajectory(
    robot: Any,
    order: np.ndarray,
    flange: np.ndarray,
    axes: np.ndarray,
    Qs: np.ndarray,
    oks: np.ndarray,
    q_start: np.ndarray,
    step_m: float,
    approach_waypoints: int,
    obst: Obstacles,
    nozzle_m: float,
    kp: tuple[float, ...],
    joint_planner: str,
    seed: int,
    family: np.ndarray | None = None,
) -> _Traj:
    """Way-points: start pose, ``approach_waypoints`` joint-space points to the
    first spot, then straight moves between spots every ``step_m``.

    Branches are chosen by DP over all way-points (least joint change); a
    jump larger than 15° between neighbours becomes a joint-space
    reconfiguration.  Way-points whose ellipsoids penetrate an obstacle are
    rejected (their state is removed and the DP re-run, up to 4 times).
    Every move between way-points is then certified free
    (:func:`planners.blasting.motion.edge_free`, the ellipsoid clearance
    against a bound on how far the arm moves).  A move that is not: the
    approach and reconfigurations try, shortest first, a direct move,
    "rotate folded, then extend" and "extend, then rotate" via-points, each
    optionally through poses backed off 0.1/0.2 m along the nozzle axis at
    either end, and (reconfigurations) out to the start pose and back; with
    ``joint_planner="rrt"`` any move still blocked is planned by
    RRT-Connect in the joint space (shortcut, densified to 2° steps, nozzle
    off), and a spot that no certified path reaches from the previous one is
    left out (``unreached``).  With ``joint_planner="none"`` (the default)
    an uncertified move keeps the shortest candidate whose way-points are
    free, else the clearest one even when it penetrates, so the clearance
    check fails.

    Steps: :func:`_cartesian_waypoints` → :func:`_waypoint_branches` →
    :func:`_certify_short_steps` → :func:`_walk`."""
    rng = np.random.default_rng(seed)
    w = _motion.displacement_weights(robot, nozzle_m, kp, FOCI)
    clear = _Clearance(robot, obst, nozzle_m, kp)
    fam = np.full(len(Qs), -1) if family is None else np.asarray(family)
    P, A, spot, wfam = _cartesian_waypoints(order, flange, axes, fam, step_m)
    usable, qb, spot = _waypoint_branches(robot, P, A, spot, wfam, Qs, oks, q_start, clear)
    Pu, Au = P[usable], A[usable]
    c_wp = clear.val(qb)
    step_ok = _certify_short_steps(qb, c_wp, clear, w)
    return _walk(
        robot, qb, spot, c_wp, step_ok, Pu, Au, q_start, approach_waypoints, clear, w, rng,
        joint_planner,
    )  # fmt: skip


def _walk(
    robot: Any,
    qb: np.ndarray,
    spot: np.ndarray,
    c_wp: np.ndarray,
    step_ok: np.ndarray,
    Pu: np.ndarray,
    Au: np.ndarray,
    q_start: np.ndarray,
    approach_waypoints: int,
    clear: _Clearance,
    w: np.ndarray,
    rng: np.random.Generator,
    joint_planner: str,
) -> _Traj:
    """Walk the way-points from the start pose: a certified short move is
    appended as a blasting way-point (segment 2); anything else becomes a
    :func:`_transition` — the approach (segment 1, exactly
    ``approach_waypoints`` points, §4.2.4) or a reconfiguration (segment 3,
    ≤ :data:`STEP_RAD` per step).  Penetrating way-points between spots are
    passed over; a spot no certified path reaches is left out
    (``unreached``) together with the way-points leading from it."""
    limits = robot.joint_limits
    out = [q_start[None]]
    seg = [np.array([0])]
    sp = [np.array([-1])]
    cur, c_cur, cur_k = q_start, clear.val(q_start)[0], -1
    reached_first = False
    unreached: list[int] = []
    stats = {
        "rrt_calls": 0, "rrt_failures": 0, "rrt_nodes": 0, "rrt_iterations": 0,
        "rrt_out_of_budget": 0, "via_moves": 0,
    }  # fmt: skip
    skip_to_spot = False
    for k in range(len(qb)):
        if spot[k] < 0 and (c_wp[k] <= 0 or not reached_first or skip_to_spot):
            # a penetrating way-point between spots, or one on the way from a
            # spot that was left out: move past it
            continue
        skip_to_spot = False
        if reached_first and cur_k == k - 1 and step_ok[k]:
            out.append(qb[k][None])
            seg.append(np.array([2]))
            sp.append(np.array([spot[k]]))
            cur, c_cur, cur_k = qb[k], c_wp[k], k
            continue
        dq = float(np.abs(qb[k] - cur).max())
        if reached_first and dq <= JUMP_RAD and (clear.obst.empty or _motion.edge_free(
                cur[None], qb[k][None], clear.val, w, ca=[c_cur], cb=[c_wp[k]])[0]):  # fmt: skip
            out.append(qb[k][None])
            seg.append(np.array([2]))
            sp.append(np.array([spot[k]]))
            cur, c_cur, cur_k = qb[k], c_wp[k], k
            continue
        m = approach_waypoints if not reached_first else max(int(np.ceil(dq / STEP_RAD)), 2)
        path = _transition(
            cur, qb[k], m, clear.val, clear.sign, w, limits, rng, joint_planner, clear.obst.empty,
            stats, c_cur, c_wp[k], _retracts(robot, cur_k, Pu, Au, qb, clear),
            _retracts(robot, k, Pu, Au, qb, clear), q_start if reached_first else None,
            not reached_first,
        )  # fmt: skip
        if path is None:
            if spot[k] >= 0:
                unreached.append(int(spot[k]))
                skip_to_spot = True
            continue
        out.append(path)
        seg.append(np.full(len(path), 3 if reached_first else 1))
        sp.append(np.r_[np.full(len(path) - 1, -1), spot[k]])
        cur, c_cur, cur_k = qb[k], c_wp[k], k
        if spot[k] >= 0:
            reached_first = True
    if not reached_first:
        raise InfeasibleError(
            "no spot can be reached from the start pose on a collision-free path "
            f"({stats['rrt_calls']} joint-space searches failed)"
        )
    return _Traj(
        np.vstack(out), np.concatenate(seg), np.concatenate(sp),
        np.asarray(sorted(set(unreached)), dtype=int), stats,
    )  # fmt: skip


def _resample(path: np.ndarray, m: int) -> np.ndarray:
    """Exactly ``m`` way-points along the polyline ``path`` (first vertex
    excluded, last included) that contain every corner, so the way-points
    trace the certified polyline itself: each of the K segments gets
    ≥ 1 evenly spaced points, the rest shared by largest remainder in
    proportion to its largest joint move.  With K > m the corners alone
    are returned (K points)."""
    path = np.asarray(path, dtype=float)
    K = len(path) - 1
    if K <= 0:
        return np.repeat(path[-1:], m, axis=0)
    if m <= K:
        return path[1:].copy()
    seglen = np.abs(np.diff(path, axis=0)).max(axis=1)
    share = (m - K) * seglen / seglen.sum() if seglen.sum() > 0 else np.full(K, (m - K) / K)
    n = 1 + np.floor(share).astype(int)
    rest = m - int(n.sum())
    if rest > 0:
        n[np.argsort(-(share - np.floor(share)), kind="stable")[:rest]] += 1
    out = [_arm.joint_path(a, b, int(k)) for a, b, k in zip(path[:-1], path[1:], n, strict=True)]
    return np.vstack(out)


def _via_polylines(
    q0: np.ndarray,
    q1: np.ndarray,
    r0: list[np.ndarray],
    r1: list[np.ndarray],
    home: np.ndarray | None = None,
) -> list[np.ndarray]:
    """Candidate corner sequences q0 → … → q1, shortest first: the direct
    move, "turn folded, then extend" and "extend, then turn", each optionally
    entered and left through a pose backed off along the nozzle axis
    (``r0`` at q0, ``r1`` at q1); and, with ``home``, out through the
    retract poses to the home pose and back in (the way a crew clears a
    blocked arm)."""

    def mids(a: np.ndarray, b: np.ndarray) -> list[list[np.ndarray]]:
        return [[], [np.r_[b[0], a[1:3], b[3:]]], [np.r_[a[0], b[1:3], a[3:5], b[5]]]]

    cands = []
    for a in [None, *r0]:
        for b in [None, *r1]:
            ea = q0 if a is None else a
            eb = q1 if b is None else b
            for mid in mids(ea, eb):
                corners = [q0, *([] if a is None else [a]), *mid, *([] if b is None else [b]), q1]
                cands.append(np.stack(corners))
            if home is not None:
                pa, pb = [] if a is None else [a], [] if b is None else [b]
                cands.append(np.stack([q0, *pa, home, *pb, q1]))
    length = [float(np.abs(np.diff(c, axis=0)).max(axis=1).sum()) for c in cands]
    return [cands[i] for i in np.argsort(length, kind="stable")]


def _transition(
    q0: np.ndarray,
    q1: np.ndarray,
    m: int,
    clear_val: Callable[[np.ndarray], np.ndarray],
    clear_sign: Callable[[np.ndarray], np.ndarray],
    w: np.ndarray,
    limits: np.ndarray,
    rng: np.random.Generator,
    joint_planner: str,
    free_space: bool,
    stats: dict[str, int],
    c0: float,
    c1: float,
    r0: Sequence[np.ndarray] = (),
    r1: Sequence[np.ndarray] = (),
    home: np.ndarray | None = None,
    exact_m: bool = True,
) -> np.ndarray | None:
    """Joint-space move q0 → q1 as way-points (q0 excluded): the shortest
    certified-free candidate of :func:`_via_polylines` (``r0``/``r1``:
    retract poses at the two ends), else (``joint_planner="rrt"``)
    RRT-Connect + shortcut; None when nothing certified is found.  With
    ``joint_planner="none"`` the shortest candidate whose way-points are
    free is returned, else the clearest.  ``exact_m``: exactly ``m``
    way-points (the approach, §4.2.4); otherwise at least ``m`` and no joint
    step above :data:`STEP_RAD` on a candidate's own polyline."""
    direct = _arm.joint_path(q0, q1, m)
    if free_space:
        return direct
    polys = _via_polylines(q0, q1, list(r0), list(r1), home)

    def n_points(p: np.ndarray) -> int:
        if exact_m:
            return m
        steps = np.ceil(np.abs(np.diff(p, axis=0)).max(axis=1) / STEP_RAD)
        return max(m, int(np.maximum(steps, 1).sum()))

    # a sign-only look at the candidates' way-points rules most of them out
    # before the (more expensive) certification: the shortest candidate
    # first (it is usually taken), the others in one batch only when it is
    # not; the first candidate in order that passes both is the same either way
    paths = [direct if len(p) == 2 else _resample(p, n_points(p)) for p in polys]
    worst: list[float] = []

    def look(k: int) -> None:
        if k < len(worst):
            return
        batch = paths[k : k + 1] if k == 0 else paths[k:]
        sign = clear_sign(np.vstack(batch))
        cut = np.cumsum([len(p) for p in batch])[:-1]
        worst.extend(float(c.min()) for c in np.split(sign, cut))  # exact where ≤ 0

    for k, (poly, path) in enumerate(zip(polys, paths, strict=True)):
        look(k)
        if worst[k] <= 0:
            continue
        cs = np.r_[c0, clear_val(poly[1:-1]) if len(poly) > 2 else [], c1]
        if cs.min() > 0 and _motion.edge_free(poly[:-1], poly[1:], clear_val, w,
                                              ca=cs[:-1], cb=cs[1:]).all():  # fmt: skip
            if len(poly) > 2:
                stats["via_moves"] += 1
            return path
    look(len(paths) - 1)  # every candidate looked at (no-op when done)
    hit = [c <= 0 for c in worst]
    if joint_planner == "none":
        # nothing certified between way-points: the shortest candidate whose
        # way-points are free, else the clearest (the clearance check fails)
        if not all(hit):
            return paths[hit.index(False)]
        return paths[int(np.argmax(worst))]
    budget = RRT_BUDGET_ITER - stats["rrt_iterations"]
    if budget <= 0:
        stats["rrt_out_of_budget"] += 1
        return None
    stats["rrt_calls"] += 1
    res = _motion.rrt_connect(
        q0, q1, clear_val, limits, w, rng=rng, max_iter=min(RRT_MAX_ITER, budget)
    )
    stats["rrt_nodes"] += res.nodes
    stats["rrt_iterations"] += res.iterations
    if res.path is None:
        stats["rrt_failures"] += 1
        return None
    path = _motion.shortcut(res.path, clear_val, w, rng=rng)
    # as many way-points as the move needs at ≤ 2° per step, at least m
    # (the approach: exactly m = 100 unless the path has more corners)
    n_dense = len(_motion.densify(path, STEP_RAD))
    return _resample(path, m) if n_dense <= m else _motion.densify(path, STEP_RAD)
