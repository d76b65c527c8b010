"""The dense simulation gate of ``planners/cmbot/simulate.py`` as it was
before the coarse-then-fine gate (every resampled sample evaluated for every check, the
per-interval ``np.linspace`` resampling, one FK pass over the whole motion).

Kept as the reference the coarse-then-fine gate is tested against
(``tests/cmbot/test_cmbot_gate.py``) and benchmarked against
(``tests/benchmarks/bench_cmbot.py``).  Not used by the planners.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
from scipy.interpolate import CubicSpline, PchipInterpolator

from planners.cmbot.arm import ArmKinematics
from planners.cmbot.distance import boxes_arrays, sphere_box_exact
from planners.cmbot.gait import GaitTrajectory, flip_moments
from planners.cmbot.guardrail import Guardrail
from planners.cmbot.scene import arm_base_pose, climber_box_arrays
from planners.cmbot.simulate import GateReport, _limit_checks, _record


def _resample_dense(
    times: np.ndarray,
    values: np.ndarray,
    substeps: int,
    smooth: bool = False,
    breaks: tuple[float, ...] = (),
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cubic resampling: fine times, values, derivatives.  Monotone (PCHIP, no
    overshoot at the holds of a gait) or, with ``smooth``, C² cubic splines
    fitted separately between ``breaks`` (times where the commanded velocity
    jumps, so a spline must not ring across them)."""
    t = np.asarray(times, dtype=float)
    keep = np.concatenate([[True], np.diff(t) > 1e-12])
    t, v = t[keep], np.asarray(values, dtype=float)[keep]
    if len(t) < 2:
        return t, v, np.zeros_like(v)
    cuts = [0, *[int(np.searchsorted(t, b)) for b in breaks if t[0] < b < t[-1]], len(t) - 1]
    T_out, V_out, D_out = [], [], []
    for i, (a, b) in enumerate(itertools.pairwise(cuts)):
        ts, vs = t[a : b + 1], v[a : b + 1]
        fine = np.concatenate(
            [np.linspace(x, y, substeps, endpoint=False) for x, y in itertools.pairwise(ts)]
        )
        if i == len(cuts) - 2:
            fine = np.concatenate([fine, ts[-1:]])
        f: CubicSpline | PchipInterpolator
        if smooth and len(ts) >= 4:
            f = CubicSpline(ts, vs, axis=0)
        else:
            f = PchipInterpolator(ts, vs, axis=0)
        T_out.append(fine)
        V_out.append(f(fine))
        D_out.append(f.derivative()(fine))
    return np.concatenate(T_out), np.concatenate(V_out), np.concatenate(D_out)


def min_clearance_dense(
    centers: np.ndarray,
    radii: np.ndarray,
    boxes: tuple[np.ndarray, np.ndarray, np.ndarray],
    *,
    mask: np.ndarray | None = None,
    cap: float = 1.0,
    chunk: int = 500,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per time step: the smallest sphere–box distance (capped at ``cap``), and
    which sphere and box give it.  ``boxes`` centres/rotations may carry the
    time axis.  Boxes whose bounding-sphere lower bound exceeds ``cap`` over a
    whole chunk are skipped (they cannot be the minimum below the cap)."""
    bc, bh, bR = boxes
    T = len(centers)
    circum = np.linalg.norm(bh, axis=-1)
    out = np.full(T, cap)
    sph = np.zeros(T, dtype=int)
    box = np.zeros(T, dtype=int)
    batched = bc.ndim == 3
    for a in range(0, T, chunk):
        b = min(a + chunk, T)
        C = centers[a:b]
        bcc = bc[a:b] if batched else bc[None]
        lb = (
            np.linalg.norm(C[:, :, None, :] - bcc[:, None, :, :], axis=-1)
            - radii[None, :, None]
            - circum
        )
        if mask is not None:
            lb = np.where(mask[None], lb, np.inf)
        near = np.flatnonzero(lb.min(axis=(0, 1)) <= cap)
        if not len(near):
            continue
        sub = (
            bcc[:, near] if batched else bc[near],
            bh[near],
            bR[a:b][:, near] if batched else bR[near],
        )
        d, _ = sphere_box_exact(C, radii, sub, directions=False)
        if mask is not None:
            d = np.where(mask[None][:, :, near], d, np.inf)
        flat = d.reshape(b - a, -1)
        kk = flat.argmin(axis=1)
        out[a:b] = np.minimum(flat[np.arange(b - a), kk], cap)
        sph[a:b] = kk // len(near)
        box[a:b] = near[kk % len(near)]
    return out, sph, box


def simulate_climb_dense(
    model: Any,
    guardrail: Guardrail,
    traj: GaitTrajectory,
    *,
    substeps: int = 2,
    arm_clearance_m: float = 0.05,
) -> GateReport:
    """Replay a climbing trajectory finely and check it (seed §4 simulation system).

    Checks: joint limits and speeds (J1…J12), holding soles on valid
    footholds and on the bar, swing sole never below the bar top, flip
    moment about the holding sole ≤ the magnet's holding moment (single
    support), folded-arm spheres clear of the guardrail and of the climbing
    mechanism.
    """
    c = model.params["climber"]
    rep = GateReport()
    t, q, qd = _resample_dense(traj.times, traj.q, substeps)
    _, rear, _ = _resample_dense(traj.times, traj.rear, substeps)
    _, front, _ = _resample_dense(traj.times, traj.front, substeps)
    idx = np.clip(np.searchsorted(traj.times, t, side="right") - 1, 0, len(traj.times) - 1)
    sup = traj.support[idx]
    rep.dt_s = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    rep.samples = len(t)
    names = list(model.urdf_joint_names)
    limits = np.vstack([model.climber.joint_limits, model.joint_limits])
    vmax = np.concatenate([model.climber.max_speed, model.max_speed])
    _limit_checks(rep, names, t, q, qd, limits, vmax)
    # Footholds: a holding sole sits on the bar top (z = 0) on a valid foothold.
    L = c["foot_length_m"]
    hold_rear = sup != 2
    hold_front = sup != 1
    bad = np.zeros(len(t))
    where = ["" for _ in t]
    for holds, pos, name in ((hold_rear, rear, "rear"), (hold_front, front, "front")):
        ok = guardrail.valid_foothold(pos[:, 0], L) & (np.abs(pos[:, 2]) < 1e-6)
        viol = holds & ~ok
        for k in np.flatnonzero(viol):
            bad[k] = 1.0
            where[k] = (
                f"{name} sole at x = {pos[k, 0]:.3f} m: {guardrail.why_invalid(pos[k, 0], L) or 'off the bar top'}"
            )
    _record(
        rep,
        "foot_placement",
        bad,
        0.0,
        t,
        lambda k: where[k],
        "holding soles off a valid foothold (count)",
        "",
    )
    swing_z = np.where(sup == 1, front[:, 2], np.where(sup == 2, rear[:, 2], 0.0))
    _record(
        rep,
        "swing_above_bar",
        swing_z,
        -1e-9,
        t,
        lambda k: f"swing sole z = {swing_z[k] * 1e3:.2f} mm",
        "swing sole height above the bar top",
        "m",
        upper=False,
    )
    # Flip moment (Eq. 9) at the fine steps, single support only.
    arm = ArmKinematics.from_model(model)
    M, _ = flip_moments(model, arm, traj, t, q, rear, front, sup)
    hold = c["foot_length_m"] / 2 * model.params["magnet"]["holding_force_N"]
    My = np.where(sup > 0, np.abs(M[:, 1]), 0.0)
    _record(
        rep,
        "flip_torque",
        My,
        hold,
        t,
        lambda k: f"about the {'rear' if sup[k] == 1 else 'front'} sole",
        "|flip moment| about the holding sole",
        "N·m",
    )
    # Clearance of the folded arm: guardrail (≥ arm_clearance_m) and own climbing links (≥ 0).
    T_wr = np.broadcast_to(np.eye(4), (len(t), 4, 4)).copy()
    T_wr[:, :3, 3] = rear
    T_wk = arm_base_pose(model, q[:, :5], T_wr)
    centers = (
        np.einsum("tij,tsj->tsi", T_wk[:, :3, :3], arm.sphere_centers(arm.frames(q[:, 5:])))
        + T_wk[:, None, :3, 3]
    )
    lo = float(min(rear[:, 0].min(), front[:, 0].min())) - 3.0
    hi = float(max(rear[:, 0].max(), front[:, 0].max())) + 3.0
    env = guardrail.boxes(lo, hi)
    dmin, si, bi = min_clearance_dense(centers, arm.spheres.radius, boxes_arrays(env), cap=1.0)
    _record(
        rep,
        "arm_env_clearance",
        dmin,
        arm_clearance_m,
        t,
        lambda k: f"arm sphere {si[k]} ↔ {env[bi[k]].name}",
        "folded-arm clearance to the guardrail",
        "m",
        upper=False,
    )
    body = arm.spheres.body >= 1
    bc, bh, bR, bnames = climber_box_arrays(model, q[:, :5], T_wr)
    self_d, _, kk = min_clearance_dense(
        centers[:, body], arm.spheres.radius[body], (bc, bh, bR), cap=1.0
    )
    _record(
        rep,
        "self_clearance",
        self_d,
        0.0,
        t,
        lambda k: f"arm ↔ {bnames[kk[k]]}",
        "folded arm to the climbing mechanism",
        "m",
        upper=False,
    )
    return rep
