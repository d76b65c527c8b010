"""Reference only (tests and benchmarks): the per-spot ``_spot_poses`` of
``planners/blasting/pipeline.py`` before batching (one tilt search and one
``approximate_ik`` optimiser call per spot without a collision-free
closed-form solution), kept verbatim so the batched path is checked against
it and the benchmark can time it in the same run
(``pipeline._spot_poses = spot_poses_per_spot``), with the Eq. 3.15 flags
sampled for every pair (``penalty_matrix_sampled``, before the exact pruning).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import shapely
from scipy.spatial import cKDTree

from planners.blasting import arm as _arm
from planners.blasting.collision import Obstacles, clearance
from planners.blasting.constants import FOCI, MAX_TILT_DEG, SAFETY_M
from planners.blasting.footprint import exact_ellipse
from planners.blasting.pipeline import _Discs, _Frame, _Poses, _Setup
from planners.blasting.spots import _collision_free, _tilted_axis
from planners.blasting.surface import Surface

__all__ = ["penalty_matrix_sampled", "spot_poses_per_spot"]


def spot_poses_per_spot(
    robot: Any,
    surface: Surface,
    st: _Setup,
    fr: _Frame,
    d: _Discs,
    nozzle_length_m: float,
    kp: tuple[float, ...],
    seed: int,
) -> _Poses:
    """Robot poses and collision status per spot (§3.4.1–3.4.2): closed-form
    IK along the blast axis, collision-free branches; a spot with none is
    re-tilted (least extra tilt first, exact footprint re-aimed), rejected
    when reachable but every configuration penetrates, else given the
    Eq. 3.11 approximate-IK optimum when that is clear.  With obstacles the
    Eq. 3.15 penalty flags are computed.  Edits ``d`` in place for re-tilted
    spots (tilt, semi-axes, major direction, aim point)."""
    N = len(d.c2)
    keep = np.ones(N, dtype=bool)
    residual_mm = np.zeros(N)
    residual_deg = np.zeros(N)
    obst, cone, beta, L0 = st.obst, st.cone, fr.beta, fr.L0
    n_in = -fr.side * surface.normal
    axis0 = _tilted_axis(surface, fr.side, beta, fr.tilt_dir)
    axes = np.repeat(axis0[None], N, axis=0)  # blast axis into the surface
    standoff = (d.stream / 1000.0 + nozzle_length_m)[:, None]
    flange = surface.to_world(d.aim2) - axes * standoff
    Qs, oks = robot.ik_axis(flange, axes, st.q_start)
    ok_free = _collision_free(robot, Qs, oks, obst, nozzle_length_m, kp)
    # Surface.__post_init__ always resolves x_axis (None only as an argument)
    assert surface.x_axis is not None
    # spots with no collision-free closed-form solution: tilt, then Eq. 3.11
    for i in np.nonzero(~ok_free.any(axis=1))[0]:
        tilts = np.arange(5.0, MAX_TILT_DEG - np.degrees(beta) + 1e-9, 5.0)
        cand = _arm.tilted_axes(axes[i], tilts) if len(tilts) else np.zeros((0, 3))
        # exact footprint of each candidate axis, aimed so it stays centred
        bc = np.arccos(np.clip(cand @ n_in, -1.0, 1.0))
        e3 = cand - np.cos(bc)[:, None] * n_in
        e2 = np.stack([e3 @ surface.x_axis, e3 @ surface.y_axis], axis=1)
        e2 /= np.maximum(np.linalg.norm(e2, axis=1, keepdims=True), 1e-12)
        ac, bcm, cc = exact_ellipse(L0 * d.scale[i], cone.tan_alpha, bc)
        aims = d.c2[i] - cc[:, None] * e2
        fl = surface.to_world(aims) - cand * standoff[i]
        Qt, okt = robot.ik_axis(fl, cand, st.q_start)
        freet = _collision_free(robot, Qt, okt, obst, nozzle_length_m, kp)
        good = np.nonzero(freet.any(axis=1))[0]
        if len(good):
            j = int(good[0])  # tilts ascend: least extra tilt first
            axes[i], flange[i], d.aim2[i] = cand[j], fl[j], aims[j]
            Qs[i], oks[i], ok_free[i] = Qt[j], okt[j], freet[j]
            d.tilt[i] = float(np.degrees(bc[j]))
            d.semi[i] = (ac[j], bcm[j])
            d.major[i] = e2[j]
            continue
        if oks[i].any() or okt.any():
            # reachable, but every configuration penetrates: rejected
            keep[i] = False
            continue
        # out of reach (or limits) for every axis tried: Eq. 3.11 optimum
        ap = _arm.approximate_ik(robot, flange[i], axes[i], st.q_start, seed=seed)
        Sq = _arm.link_spheroids(robot, ap.q[None], nozzle_length_m, kp, FOCI)
        if obst.empty or clearance(Sq, obst)[0] > SAFETY_M:
            Qs[i] = ap.q
            oks[i] = False
            oks[i, 0] = True
            ok_free[i] = oks[i]
            residual_mm[i] = ap.pos_err_m * 1000.0
            residual_deg[i] = ap.axis_err_deg
        else:
            keep[i] = False
    penalty = None
    if not obst.empty:
        penalty = penalty_matrix_sampled(
            robot, surface, d.c2, keep, st.r, obst, axes[0], standoff, nozzle_length_m, kp,
            st.q_start,
        )  # fmt: skip
    return _Poses(keep, Qs, ok_free, residual_mm, residual_deg, penalty, axes, flange)


def penalty_matrix_sampled(
    robot: Any,
    surface: Surface,
    c2: np.ndarray,
    keep: np.ndarray,
    r: float,
    obst: Obstacles,
    axis: np.ndarray,
    standoff: np.ndarray,
    nozzle_m: float,
    kp: tuple[float, ...],
    q_start: np.ndarray,
) -> np.ndarray | None:
    """Eq. 3.15 flags: a move i→j is flagged when it passes within r of a
    surface point whose normal pose has no collision-free branch (a grid of
    pitch r over the surface)."""
    poly = surface.polygon
    minx, miny, maxx, maxy = poly.bounds
    gx, gy = np.meshgrid(np.arange(minx, maxx + r, r), np.arange(miny, maxy + r, r))
    g = np.stack([gx.ravel(), gy.ravel()], axis=1)
    g = g[shapely.contains_xy(poly, g[:, 0], g[:, 1])]
    if len(g) == 0:
        return None
    fl = surface.to_world(g) - axis * float(standoff[0, 0])
    Q, ok = robot.ik_axis(fl, np.repeat(axis[None], len(g), axis=0), q_start)
    free = _collision_free(robot, Q, ok, obst, nozzle_m, kp).any(axis=1)
    blocked = g[~free]
    if len(blocked) == 0:
        return None
    n = len(c2)
    if n > 1500:
        return None  # dense N² flags would cost more than they help; trajectory check still applies
    tree = cKDTree(blocked)
    pen = np.zeros((n, n))
    samples = np.linspace(0.0, 1.0, 9)
    for i in range(n):
        seg = c2[i][None, None, :] + samples[None, :, None] * (
            c2[None, :, :] - c2[i][None, None, :]
        ).transpose(1, 0, 2)
        d, _ = tree.query(seg.reshape(-1, 2), k=1)
        # k=1 over many points gives an array (the stubs also allow a scalar)
        pen[i] = (np.asarray(d).reshape(n, len(samples)) < r).any(axis=1)
    np.fill_diagonal(pen, 0.0)
    return pen
