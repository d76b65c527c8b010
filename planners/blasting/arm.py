"""Arm motion for blasting (seed §3.4.1, §4.2.4): spot poses, IK selection,
approximate IK when no exact solution exists, way-points and speed limits.

* The nozzle is a fixed transform along the flange z axis (length 100 mm);
  the blast axis is the flange z axis and points into the surface, so the
  flange stands ``stream + nozzle`` off the spot along the surface normal.
  The blast is axisymmetric, so the roll about the axis is free: J6 keeps
  its start value and never moves (the seed's Fig. 4.15 shows large J6 swings
  at turns because its poses fixed the roll).
* Every spot gets all closed-form solutions; the branch per spot is chosen by
  dynamic programming over the visiting order for the least joint change
  (§3.4.1.1 — the seed picks the least change greedily; DP is the optimum of
  the same criterion), skipping solutions in collision.
* No exact solution (out of reach, joint limits, collision): the nozzle is
  first tilted up to 45° off the normal (§3.2.1 allows 45–90° to the
  surface), then :func:`approximate_ik` minimises Eq. 3.11
  (αp·Perr + αo·Oerr, Eq. 3.9–3.10) with bounded least squares from several
  starts — a stronger optimiser than the seed's GA (:func:`ga_ik`, kept for
  comparison) — and the residual is reported.
* Way-points: m = 100 joint-space way-points from the start pose to the first
  spot; straight Cartesian moves between spots at ``step`` spacing, each
  way-point taking the solution nearest the previous one.  Segment times are
  stretched so that no joint exceeds the speed limit (Eq. 3.12–3.13).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.optimize import least_squares, minimize

from planners.blasting.collision import Obstacles, Spheroids, clearance
from planners.errors import UnreachableError

if TYPE_CHECKING:
    from robots.denso_vm6083 import DensoVM6083

ALPHA_P = 1.0  # Eq. 3.11 weight per metre of position error (chosen)
ALPHA_O = 0.05  # Eq. 3.11 weight per unit of |a − n| (chosen: 1° ≈ 0.9 mm)
DP_CHUNK = 4096  # steps whose branch-transition scores are computed in one batch


# -- geometry of the tool and the force-field ellipsoids --------------------------
def link_spheroids(
    robot: DensoVM6083,
    q: np.ndarray,
    nozzle_m: float,
    kp: tuple[float, ...],
    foci: tuple[tuple[int, int], ...],
) -> Spheroids:
    """Spheroids (T,E) covering the links for joint vectors q (T,6): foci are
    D-H frame origins (index −1 = nozzle tip); major axis L·Kp (§3.4.2)."""
    F = robot.frames(np.atleast_2d(q))  # (T,7,4,4)
    org = F[:, :, :3, 3]
    tip = org[:, -1] + nozzle_m * F[:, -1, :3, 2]
    pts = np.concatenate([org, tip[:, None]], axis=1)  # index 7 = tip
    f1 = np.stack([pts[:, i if i >= 0 else 7] for i, _ in foci], axis=1)
    f2 = np.stack([pts[:, j if j >= 0 else 7] for _, j in foci], axis=1)
    L = np.linalg.norm(f2 - f1, axis=-1)
    cf = L * np.asarray(kp, dtype=float)
    return Spheroids(f1, f2, cf)


def tilted_axes(axis: np.ndarray, tilts_deg: np.ndarray, n_azimuth: int = 8) -> np.ndarray:
    """Unit axes tilted from ``axis`` by each tilt toward ``n_azimuth``
    directions: (len(tilts)·n_azimuth, 3)."""
    axis = axis / np.linalg.norm(axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    t = np.deg2rad(np.asarray(tilts_deg, dtype=float))[:, None]
    ph = np.linspace(0, 2 * np.pi, n_azimuth, endpoint=False)[None, :]
    d = np.cos(ph)[..., None] * e1 + np.sin(ph)[..., None] * e2
    out = np.cos(t)[..., None] * axis + np.sin(t)[..., None] * d
    return out.reshape(-1, 3)


# -- IK selection -------------------------------------------------------------------
def _change(qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
    """Least-change score: largest joint move (sets the time under a uniform
    speed limit) plus a small Euclidean tie-breaker."""
    d = np.abs(qa - qb)
    return d.max(axis=-1) + 1e-3 * np.linalg.norm(d, axis=-1)


def choose_branches(Q: np.ndarray, ok: np.ndarray, q_start: np.ndarray) -> np.ndarray:
    """Viterbi over spots in visiting order: the branch index per spot that
    minimises Σ least-change(q_i, q_{i+1}) from ``q_start`` (§3.4.1.1's
    criterion, optimised over the whole path).  Every spot needs at least
    one valid branch (the planner substitutes tilted or approximate
    solutions first)."""
    N, K, _ = Q.shape
    if N == 0:
        return np.zeros(0, dtype=int)
    if not ok.any(axis=1).all():
        raise UnreachableError("every spot needs at least one valid IK branch")
    cost = np.where(ok[0], _change(Q[0], q_start), np.inf)
    back = np.zeros((N, K), dtype=int)
    for s in range(1, N, DP_CHUNK):
        # the (K,K) transition scores of a chunk of steps in one batch (the
        # same elementwise arithmetic as one step at a time); the recursion
        # itself stays sequential
        e = min(s + DP_CHUNK, N)
        C = _change(Q[s - 1 : e - 1][:, :, None, :], Q[s:e][:, None, :, :])  # (e−s,K,K)
        # an invalid branch's column is inf: its cost is inf as before (its
        # back-pointer is never followed: the chosen branches have finite cost)
        C[~ok[s:e][:, None, :].repeat(K, axis=1)] = np.inf
        for i in range(s, e):
            tot = cost[:, None] + C[i - s]
            back[i] = tot.argmin(axis=0)
            cost = tot.min(axis=0)
    out = np.empty(N, dtype=int)
    out[-1] = int(np.argmin(cost))
    for i in range(N - 1, 0, -1):
        out[i - 1] = back[i, out[i]]
    return out


# -- approximate IK (Eq. 3.9–3.11) -------------------------------------------------------
@dataclass
class ApproxIK:
    q: np.ndarray
    pos_err_m: float
    axis_err_deg: float
    objective: float


def _axis_residual(
    robot: DensoVM6083, q5: np.ndarray, q6: float, p: np.ndarray, a: np.ndarray
) -> np.ndarray:
    q = np.append(q5, q6)
    T = robot.fk(q)  # one configuration: pinocchio on the URDF
    return np.concatenate([ALPHA_P * (T[:3, 3] - p), ALPHA_O * (T[:3, 2] - a)])


def _axis_jacobian(robot: DensoVM6083, q5: np.ndarray, q6: float) -> np.ndarray:
    """d[αp·p; αo·z]/dq1..5 from the geometric Jacobian (dz/dqi = ωi × z)."""
    q = np.append(q5, q6)
    J = robot.jacobian(q)[:, :5]
    z = robot.fk(q)[:3, 2]
    return np.vstack([ALPHA_P * J[:3], ALPHA_O * np.cross(J[3:].T, z).T])


def approximate_ik(
    robot: DensoVM6083, p: np.ndarray, a: np.ndarray, q_ref: np.ndarray, *, seed: int = 0
) -> ApproxIK:
    """Joint vector minimising Eq. 3.11 (αp·|P_t − P_e| + αo·|a − n_t|) inside
    the limits for flange position ``p`` and blast axis ``a``: the seed's GA
    (:func:`ga_ik`) gives one start, ``q_ref`` and the closed-form solutions
    of the target pulled back into reach give others, and each is refined by
    bounded least squares on the residual vector (analytic Jacobian; exact
    solutions end here) and then SLSQP on Eq. 3.11 itself.  The result is
    never worse than the GA's."""
    lo, hi = robot.joint_limits[:5, 0], robot.joint_limits[:5, 1]
    q6 = float(q_ref[5])
    ga = ga_ik(robot, p, a, q_ref, population=60, seed=seed)
    starts = [ga.q[:5], np.clip(q_ref[:5], lo, hi)]
    base_p = robot.base[:3, 3]
    for s in (1.0, 0.97, 0.93, 0.85):
        Q, ok = robot.ik_axis((base_p + s * (p - base_p))[None], a[None], q_ref)
        starts += [Q[0, k, :5] for k in np.nonzero(ok[0])[0]]
        if ok.any():
            break

    def res(x: np.ndarray) -> np.ndarray:
        return _axis_residual(robot, x, q6, p, a)

    def jac(x: np.ndarray) -> np.ndarray:
        return _axis_jacobian(robot, x, q6)

    def eq311(x: np.ndarray) -> float:
        r = res(x)
        return float(np.linalg.norm(r[:3]) + np.linalg.norm(r[3:]))

    def f_and_grad(x: np.ndarray) -> tuple[float, np.ndarray]:
        r, J = res(x), jac(x)
        g = np.zeros(5)
        f = 0.0
        for sl in (slice(0, 3), slice(3, 6)):
            n = float(np.linalg.norm(r[sl]))
            f += n
            if n > 1e-15:
                g += (r[sl] / n) @ J[sl]
        return f, g

    best_x, best_f = ga.q[:5], ga.objective
    for s0 in starts[:4]:
        x0 = np.clip(s0, lo + 1e-9, hi - 1e-9)
        r = least_squares(
            res, x0, jac=jac, bounds=(lo, hi), xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=60
        )
        x, f = r.x, eq311(r.x)
        if f > 1e-9:
            r2 = minimize(
                f_and_grad, x, jac=True, method="SLSQP", bounds=list(zip(lo, hi, strict=True))
            )
            if r2.fun < f:
                x, f = r2.x, float(r2.fun)
        if f < best_f:
            best_x, best_f = x, f
        if best_f < 1e-9:
            break
    q = np.append(best_x, q6)
    T = robot.frames(q)[-1]
    pe = float(np.linalg.norm(T[:3, 3] - p))
    ae = float(np.degrees(np.arccos(np.clip(T[:3, 2] @ a, -1.0, 1.0))))
    return ApproxIK(q, pe, ae, ALPHA_P * pe + ALPHA_O * float(np.linalg.norm(T[:3, 2] - a)))


# -- reach bound and batched approximate IK ----------------------------------
def wrist_reach_m(robot: DensoVM6083) -> float:
    """Largest distance of the wrist centre from the shoulder: a2 + √(a3² + d4²).

    Proof (D-H of :meth:`robots.denso_vm6083.DensoVM6083._position_branches`):
    with the wrist centre at radius ρ from the J1 axis and height h above
    the shoulder plane (z = d1), θ1 is φ or φ + π (no lateral offset), and
    the wrist centre in frame 1 is (x, y) = (±ρ − a1, −h).  The elbow
    triangle (a2, L3 = √(a3² + d4²)) closes iff (a2 − L3)² ≤ x² + y² ≤
    (a2 + L3)².  Since ρ, a1 ≥ 0, min(x² + y²) = (ρ − a1)² + h², the squared
    distance from the wrist centre to the shoulder circle (radius a1 about
    the J1 axis at height d1).  So a wrist centre farther than a2 + L3 from
    that circle has no closed-form solution on any branch."""
    return float(robot.a[1] + np.hypot(robot.a[2], robot.d[3]))


def shoulder_distance(robot: DensoVM6083, pts: np.ndarray) -> np.ndarray:
    """Distance (M,) of world points ``pts`` (M,3) from the shoulder circle
    (radius a1 about the J1 axis at height d1, in the robot's base frame)."""
    Binv = np.linalg.inv(robot.base)
    pb = np.atleast_2d(pts) @ Binv[:3, :3].T + Binv[:3, 3]
    rho = np.hypot(pb[:, 0], pb[:, 1])
    return np.hypot(rho - robot.a[0], pb[:, 2] - robot.d[0])


#: slack (m) beyond the reach before a target counts as out of reach: covers the
#: closed-form IK's |D| ≤ 1 + 1e-12 tolerance (≈ 1e-12·a2·L3/(a2 + L3) m)
REACH_TOL_M = 1e-9


def beyond_reach(
    robot: DensoVM6083, p: np.ndarray, a: np.ndarray, slack_m: np.ndarray | float = 0.0
) -> np.ndarray:
    """True (M,) where no closed-form solution can exist for the flange at
    ``p`` (M,3) with blast axis ``a`` (M,3): the wrist centre p − d6·a lies
    more than :func:`wrist_reach_m` from the shoulder circle.  With
    ``slack_m`` > 0 (per row or scalar) the answer holds for every flange
    point within ``slack_m`` of ``p`` and every axis (the wrist centre moves
    at most slack + 2·d6 — use it with ``a`` = 0 for "any axis": then it must
    cover d6 itself, see :func:`beyond_reach_any_axis`)."""
    a = np.atleast_2d(np.asarray(a, dtype=float))
    n = np.linalg.norm(a, axis=1, keepdims=True)
    a = np.where(n > 0, a / np.where(n > 0, n, 1.0), 0.0)
    pc = np.atleast_2d(p) - robot.d[5] * a
    return shoulder_distance(robot, pc) > wrist_reach_m(robot) + slack_m + REACH_TOL_M


def beyond_reach_any_axis(robot: DensoVM6083, w: np.ndarray, radius_m: np.ndarray) -> np.ndarray:
    """True (M,) where no flange point within ``radius_m`` (M,) of ``w``
    (M,3) has a closed-form solution with any axis: the wrist centre is
    then within radius + d6 of ``w``, and the distance to the shoulder
    circle is 1-Lipschitz."""
    slack = np.asarray(radius_m, dtype=float) + robot.d[5]
    return shoulder_distance(robot, w) > wrist_reach_m(robot) + slack + REACH_TOL_M


def _frames_jac(
    robot: DensoVM6083, q: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Flange position (K,3), z axis (K,3) and their derivatives d/dq1..5
    (K,3,5) each (geometric Jacobian: joint i turns about z of frame i − 1).

    The D-H chain of :meth:`robots.model.DHRobotModel.frames`, written
    component-wise on (K,) arrays (a batched 4×4 matmul per link costs
    ~10× more for small matrices); the tests compare it with ``frames``.
    Computed by :func:`_frames_jac_t` (column layout) and transposed."""
    pe, ze, Jp, Jz = _frames_jac_t(robot, np.asarray(q, dtype=float).T)
    return pe.T, ze.T, Jp.transpose(2, 0, 1), Jz.transpose(2, 0, 1)


def _frames_jac_t(
    robot: DensoVM6083, qt: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_frames_jac` on joint vectors stored column-wise, ``qt`` (6,K):
    flange position (3,K), z axis (3,K), d/dq1..5 (3,5,K) each.

    Structure-of-arrays layout: every operation runs on whole (3,K) or
    (5,K) rows (contiguous in K), about a third of the array operations of
    the per-component chain and no transposed copies; terms with a zero D-H
    length are skipped (adding an exact zero changes nothing)."""
    K = qt.shape[1]
    R = np.broadcast_to(robot.base[:3, :3, None], (3, 3, K)).copy()  # R[row, col, k]
    o = np.broadcast_to(robot.base[:3, 3, None], (3, K)).copy()
    zs = np.empty((5, 3, K))
    os_ = np.empty((5, 3, K))
    for i in range(6):
        if i < 5:
            zs[i] = R[:, 2]
            os_[i] = o
        th = qt[i] + robot.offset[i]
        ct, st = np.cos(th), np.sin(th)
        ca, sa = float(np.cos(robot.alpha[i])), float(np.sin(robot.alpha[i]))
        ai, di = float(robot.a[i]), float(robot.d[i])
        x, y, z = R[:, 0], R[:, 1], R[:, 2]
        if ai:
            o = o + x * (ai * ct) + y * (ai * st)
        if di:
            o = o + z * di
        # columns of Rz(θ)Rx(α): (ct, st, 0), (−st·ca, ct·ca, sa), (st·sa, −ct·sa, ca)
        c0 = x * ct + y * st
        c1 = -x * (st * ca) + y * (ct * ca) + z * sa
        c2 = x * (st * sa) - y * (ct * sa) + z * ca
        R = np.stack([c0, c1, c2], axis=1)
    pe, ze = o, R[:, 2]
    d = pe[None] - os_  # (5,3,K)
    zx, zy, zz = zs[:, 0], zs[:, 1], zs[:, 2]
    Jp = np.stack(
        [zy * d[:, 2] - zz * d[:, 1], zz * d[:, 0] - zx * d[:, 2], zx * d[:, 1] - zy * d[:, 0]]
    )
    Jz = np.stack([zy * ze[2] - zz * ze[1], zz * ze[0] - zx * ze[2], zx * ze[1] - zy * ze[0]])
    return pe, ze, Jp, Jz


def _eq311(pe: np.ndarray, ze: np.ndarray, p: np.ndarray, a: np.ndarray) -> np.ndarray:
    return ALPHA_P * np.linalg.norm(pe - p, axis=-1) + ALPHA_O * np.linalg.norm(ze - a, axis=-1)


def _lm_batch(
    robot: DensoVM6083,
    x: np.ndarray,
    q6: np.ndarray,
    p: np.ndarray,
    a: np.ndarray,
    iters: int,
    *,
    irls: bool,
) -> np.ndarray:
    """Batched bounded Levenberg–Marquardt on rows x (K,5): least squares of
    the residual [αp(P − p); αo(z − a)] (``irls=False``) or Eq. 3.11 itself
    (``irls=True``: each block weighted by 1/its norm, a step kept only
    when Eq. 3.11 decreases).  Steps are clipped into the joint limits; a
    row stops once its damping saturates or a kept step gains < 1e-12
    (relative), so converged rows cost nothing.

    Works column-wise (rows of the problem along the last axis, see
    :func:`_frames_jac_t`): JᵀJ and Jᵀr are one small einsum each over
    contiguous rows instead of a (K,3,5) contraction per block."""
    lo, hi = robot.joint_limits[:5, 0, None], robot.joint_limits[:5, 1, None]
    xt = np.ascontiguousarray(np.asarray(x, dtype=float).T)  # (5,K)
    K = xt.shape[1]
    pt, at = np.ascontiguousarray(p.T), np.ascontiguousarray(a.T)
    lam = np.full(K, 1e-3)

    def evaluate(rows: np.ndarray, xx: np.ndarray) -> tuple[np.ndarray, ...]:
        pe, ze, Jp, Jz = _frames_jac_t(robot, np.concatenate([xx, q6[None, rows]], axis=0))
        rp, ro = ALPHA_P * (pe - pt[:, rows]), ALPHA_O * (ze - at[:, rows])
        if irls:
            f = np.sqrt((rp * rp).sum(axis=0)) + np.sqrt((ro * ro).sum(axis=0))
        else:
            f = (rp * rp).sum(axis=0) + (ro * ro).sum(axis=0)
        return f, rp, ro, ALPHA_P * Jp, ALPHA_O * Jz

    act = np.arange(K)
    f, rp, ro, Jp, Jz = evaluate(act, xt)
    diag = np.arange(5)
    for _ in range(iters):
        if not len(act):
            break
        Hp = np.einsum("rik,rjk->ijk", Jp, Jp)
        Hz = np.einsum("rik,rjk->ijk", Jz, Jz)
        gp = np.einsum("rik,rk->ik", Jp, rp)
        gz = np.einsum("rik,rk->ik", Jz, ro)
        if irls:
            wp = 1.0 / np.maximum(np.sqrt((rp * rp).sum(axis=0)), 1e-12)
            wo = 1.0 / np.maximum(np.sqrt((ro * ro).sum(axis=0)), 1e-12)
            H, g = wp * Hp + wo * Hz, wp * gp + wo * gz
        else:
            H, g = Hp + Hz, gp + gz
        la = lam[act]
        H[diag, diag] += la * (H[diag, diag] + 1e-9)
        step = -np.linalg.solve(H.transpose(2, 0, 1), g.T[..., None])[..., 0].T
        xa = xt[:, act]
        xn = np.clip(xa + step, lo, hi)
        fn, rpn, ron, Jpn, Jzn = evaluate(act, xn)
        better = fn < f
        gain = np.where(better, (f - fn) / np.maximum(np.abs(f), 1e-300), 0.0)
        xt[:, act[better]] = xn[:, better]
        f = np.where(better, fn, f)
        rp[:, better], ro[:, better] = rpn[:, better], ron[:, better]
        Jp[..., better], Jz[..., better] = Jpn[..., better], Jzn[..., better]
        lam[act] = np.clip(np.where(better, la * 0.3, la * 10.0), 1e-9, 1e9)
        go = (lam[act] < 1e9) & ~(better & (gain < 1e-12))
        act, f, rp, ro, Jp, Jz = act[go], f[go], rp[:, go], ro[:, go], Jp[..., go], Jz[..., go]
    return np.ascontiguousarray(xt.T)


def _nearer_wrist_twin(robot: DensoVM6083, q: np.ndarray, q_ref: np.ndarray) -> np.ndarray:
    """Each row or its wrist twin (q4 ± π, −q5: the same flange position and
    z axis, so the same Eq. 3.11 value), whichever is inside the limits and
    the least change from ``q_ref`` — neighbouring spots then agree on the
    wrist instead of each taking whichever twin its optimiser ended in."""
    lo, hi = robot.joint_limits[:, 0], robot.joint_limits[:, 1]
    best = q.copy()
    for shift in (np.pi, -np.pi):
        tw = q.copy()
        tw[:, 3] += shift
        tw[:, 4] = -tw[:, 4]
        inside = np.all((tw >= lo) & (tw <= hi), axis=1)
        better = inside & (_change(tw, q_ref) < _change(best, q_ref))
        best[better] = tw[better]
    return best


def approximate_ik_batch(
    robot: DensoVM6083,
    p: np.ndarray,
    a: np.ndarray,
    q_ref: np.ndarray,
    *,
    n_starts: int = 6,
    warm_iters: int = 5,
    iters: int = 60,
    n_random: int = 64,
    seed: int = 0,
    chunk: int = 256,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Eq. 3.11 optimum for many targets at once (flange ``p`` (M,3), blast
    axis ``a`` (M,3)): the batched counterpart of :func:`approximate_ik`.

    Starts per target, all from the closed-form IK: the target pulled back
    along the ray from the shoulder circle until the wrist centre is just
    inside :func:`wrist_reach_m` (the closest reachable point along that
    ray; ×0.999, 0.97, 0.9 of the reach), the target pulled toward the base
    as :func:`approximate_ik` does (×1, 0.97, 0.93, 0.85), every valid
    branch of each, ``q_ref`` and ``n_random`` joint vectors drawn uniformly
    inside the limits (the role of :func:`ga_ik`'s population; deterministic
    for ``seed``); the ``n_starts`` with the least Eq. 3.11
    value are refined together by bounded Levenberg–Marquardt on the
    residual vector (``warm_iters`` steps: only a warm start), then on
    Eq. 3.11 itself (reweighted, ≤ ``iters`` steps; rows stop when they
    converge), and the best per target is kept.  The 5 + 60 split
    (40 + 40 before) costs ~40 % less on the 4 m
    square's 2,857 far spots: its Eq. 3.11 values equal the 40 + 40 ones
    within 1e-6 on 96 % of them, are lower on 90 and higher on 17 (by at
    most 1.3e-3, ~1.3 mm on spots metres out of reach), lower in sum.
    The 6 best starts (8 before) lose a further ~27 %: 2 of those spots end
    higher, by ≤ 6e-6 (both ~1 m out of reach), none lower.  Returns q (M,6) (q6 = q_ref[5]), position error (M,) m,
    axis error (M,) degrees and the Eq. 3.11 objective (M,).

    Targets are solved ``chunk`` at a time (each start's frames are (M·≈120,
    7, 4, 4): 264 MB for the 4 m square's 2,438 spots in one pass); every
    target's starts and refinement are its own, so the answer does not
    depend on the chunking."""
    p = np.atleast_2d(np.asarray(p, dtype=float))
    a = np.atleast_2d(np.asarray(a, dtype=float))
    if len(p) > chunk:
        parts = [
            approximate_ik_batch(
                robot, p[i : i + chunk], a[i : i + chunk], q_ref, n_starts=n_starts,
                warm_iters=warm_iters, iters=iters, n_random=n_random, seed=seed, chunk=chunk,
            )
            for i in range(0, len(p), chunk)
        ]  # fmt: skip
        q_, pe_, ae_, obj_ = zip(*parts, strict=True)
        return np.concatenate(q_), np.concatenate(pe_), np.concatenate(ae_), np.concatenate(obj_)
    a = a / np.linalg.norm(a, axis=1, keepdims=True)
    M = len(p)
    q_ref = np.asarray(q_ref, dtype=float)
    if M == 0:
        z = np.zeros(0)
        return np.zeros((0, 6)), z, z, z
    lo, hi = robot.joint_limits[:5, 0], robot.joint_limits[:5, 1]
    targets = []
    # the closest reachable wrist centre along the ray from the shoulder circle
    Binv = np.linalg.inv(robot.base)
    pc = p - robot.d[5] * a
    pb = pc @ Binv[:3, :3].T + Binv[:3, 3]
    rho = np.maximum(np.hypot(pb[:, 0], pb[:, 1]), 1e-12)
    sh = np.stack(
        [robot.a[0] * pb[:, 0] / rho, robot.a[0] * pb[:, 1] / rho, np.full(M, robot.d[0])], axis=1
    )
    v = pb - sh
    dist = np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)
    R = wrist_reach_m(robot)
    for s in (0.999, 0.97, 0.9):
        pcb = sh + v * np.minimum(1.0, s * R / dist)
        pcw = pcb @ robot.base[:3, :3].T + robot.base[:3, 3]
        targets.append(pcw + robot.d[5] * a)
    base_p = robot.base[:3, 3]
    for s in (1.0, 0.97, 0.93, 0.85):
        targets.append(base_p + s * (p - base_p))
    T = np.concatenate(targets)  # (nt·M,3)
    Q, ok = robot.ik_axis(T, np.tile(a, (len(targets), 1)), q_ref)
    rand = np.random.default_rng(seed).uniform(lo, hi, size=(n_random, 5))
    S = np.concatenate(
        [Q.reshape(len(targets), M, 8, 6).transpose(1, 0, 2, 3).reshape(M, -1, 6)[..., :5],
         np.broadcast_to(rand, (M, n_random, 5)),
         np.broadcast_to(np.clip(q_ref[:5], lo, hi), (M, 1, 5))],
        axis=1,
    )  # fmt: skip
    valid = np.concatenate(
        [ok.reshape(len(targets), M, 8).transpose(1, 0, 2).reshape(M, -1),
         np.ones((M, n_random + 1), bool)],
        axis=1,
    )  # fmt: skip
    q6 = np.full(M, q_ref[5])
    # flange frames of the starts: the closed-form ones per target, the
    # random ones and q_ref once for all targets (they are shared)
    n_ik = S.shape[1] - n_random - 1
    F = robot.frames(
        np.concatenate([S[:, :n_ik].reshape(-1, 5), np.full((M * n_ik, 1), q_ref[5])], axis=1)
    )[:, -1]
    Fs = robot.frames(np.concatenate([S[0, n_ik:], np.full((n_random + 1, 1), q_ref[5])], axis=1))[
        :, -1
    ]
    pos = np.concatenate(
        [F[:, :3, 3].reshape(M, n_ik, 3), np.broadcast_to(Fs[:, :3, 3], (M, n_random + 1, 3))],
        axis=1,
    )
    zax = np.concatenate(
        [F[:, :3, 2].reshape(M, n_ik, 3), np.broadcast_to(Fs[:, :3, 2], (M, n_random + 1, 3))],
        axis=1,
    )
    f0 = _eq311(pos, zax, p[:, None], a[:, None])
    f0 = np.where(valid, f0, np.inf)
    k = min(n_starts, S.shape[1])
    pick = np.argsort(f0, axis=1, kind="stable")[:, :k]
    pick = np.where(np.isfinite(np.take_along_axis(f0, pick, axis=1)), pick, S.shape[1] - 1)
    X = np.take_along_axis(S, pick[..., None], axis=1).reshape(-1, 5)
    X = np.clip(X, lo + 1e-9, hi - 1e-9)
    P_, A_, q6_ = np.repeat(p, k, axis=0), np.repeat(a, k, axis=0), np.repeat(q6, k)
    X = _lm_batch(robot, X, q6_, P_, A_, warm_iters, irls=False)
    X = _lm_batch(robot, X, q6_, P_, A_, iters, irls=True)
    Fq = robot.frames(np.concatenate([X, q6_[:, None]], axis=1))[:, -1]
    f = _eq311(Fq[:, :3, 3], Fq[:, :3, 2], P_, A_).reshape(M, k)
    best = np.argmin(f, axis=1)
    xb = X.reshape(M, k, 5)[np.arange(M), best]
    q = _nearer_wrist_twin(robot, np.concatenate([xb, q6[:, None]], axis=1), q_ref)
    Tq = robot.frames(q)[:, -1]
    pe = np.linalg.norm(Tq[:, :3, 3] - p, axis=1)
    ae = np.degrees(np.arccos(np.clip((Tq[:, :3, 2] * a).sum(axis=1), -1.0, 1.0)))
    obj = ALPHA_P * pe + ALPHA_O * np.linalg.norm(Tq[:, :3, 2] - a, axis=1)
    return q, pe, ae, obj


def ga_ik(
    robot: DensoVM6083,
    p: np.ndarray,
    a: np.ndarray,
    q_ref: np.ndarray,
    *,
    population: int = 100,
    max_generations: int = 300,
    patience: int = 10,
    crossover: float = 0.9,
    mutation: float = 0.1,
    seed: int = 0,
) -> ApproxIK:
    """The seed's GA-amended IK (§3.4.1.2) for comparison: real-coded joints
    q1..q5 inside the limits, fitness Eq. 3.11, rank roulette, blend
    crossover 0.9, Gaussian mutation 0.1, ≤ 300 generations, stop after 10
    without improvement (one elite kept)."""
    rng = np.random.default_rng(seed)
    lo, hi = robot.joint_limits[:5, 0], robot.joint_limits[:5, 1]
    P = population

    def fitness(X: np.ndarray) -> np.ndarray:
        q = np.concatenate([X, np.full((len(X), 1), q_ref[5])], axis=1)
        T = robot.frames(q)[:, -1]
        return ALPHA_P * np.linalg.norm(T[:, :3, 3] - p, axis=1) + ALPHA_O * np.linalg.norm(
            T[:, :3, 2] - a, axis=1
        )

    X = rng.uniform(lo, hi, size=(P, 5))
    f = fitness(X)
    best_i = int(np.argmin(f))
    best, best_f = X[best_i].copy(), float(f[best_i])
    w = np.arange(P, 0, -1, dtype=float)
    w /= w.sum()
    stale = 0
    for _ in range(max_generations):
        ranked = np.argsort(f)
        par = X[ranked[rng.choice(P, size=P, p=w)]]
        child = par.copy()
        cross = rng.random(P // 2) < crossover
        lam = rng.random((P // 2, 1))
        A, B = par[0::2][: P // 2], par[1::2][: P // 2]
        child[0::2][: P // 2] = np.where(cross[:, None], lam * A + (1 - lam) * B, A)
        child[1::2][: P // 2] = np.where(cross[:, None], (1 - lam) * A + lam * B, B)
        mut = rng.random((P, 5)) < mutation
        child = np.where(mut, child + rng.normal(scale=0.05 * (hi - lo), size=(P, 5)), child)
        child = np.clip(child, lo, hi)
        child[0] = best
        X, f = child, fitness(child)
        i = int(np.argmin(f))
        if f[i] < best_f - 1e-12:
            best, best_f, stale = X[i].copy(), float(f[i]), 0
        else:
            stale += 1
            if stale >= patience:
                break
    q = np.append(best, q_ref[5])
    T = robot.frames(q)[-1]
    pe = float(np.linalg.norm(T[:3, 3] - p))
    ae = float(np.degrees(np.arccos(np.clip(T[:3, 2] @ a, -1.0, 1.0))))
    return ApproxIK(q, pe, ae, best_f)


# -- trajectory -------------------------------------------------------------------------
def follow_line(
    robot: DensoVM6083, P: np.ndarray, A: np.ndarray, q_prev: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Joint vectors along way-point poses (flange P (M,3), axes A (M,3)),
    each the valid closed-form solution nearest the previous one; returns q
    (M,6) and ok (M,) (False where no solution exists: q repeats)."""
    M = len(P)
    if M == 0:
        return np.zeros((0, 6)), np.zeros(0, dtype=bool)
    Q, ok = robot.ik_axis(P, A, q_prev)
    out = np.empty((M, 6))
    good = np.zeros(M, dtype=bool)
    q = q_prev
    for k in range(M):
        if ok[k].any():
            # re-express the wrap-around joints near the running q
            cand = Q[k]
            sc = np.where(ok[k], _change(cand, q), np.inf)
            j = int(np.argmin(sc))
            qn = cand[j].copy()
            for jj in (3,):
                d = (qn[jj] - q[jj] + np.pi) % (2 * np.pi) - np.pi
                alt = q[jj] + d
                if robot.joint_limits[jj, 0] <= alt <= robot.joint_limits[jj, 1]:
                    qn[jj] = alt
            q = qn
            good[k] = True
        out[k] = q
    return out, good


def joint_path(q0: np.ndarray, q1: np.ndarray, n: int) -> np.ndarray:
    """n way-points linear in joint space from q0 (excluded) to q1 (included)."""
    t = np.arange(1, n + 1)[:, None] / n
    return q0 + t * (q1 - q0)


def time_stamps(q: np.ndarray, dt_nominal: np.ndarray, v_max: float) -> np.ndarray:
    """Eq. 3.12–3.13: each segment takes its nominal time unless some joint
    would exceed ``v_max`` (rad/s); then the time is stretched to
    |Δθ|/v_max.  Returns time stamps (T,) from 0."""
    if len(q) < 2:
        return np.zeros(len(q))
    dq = np.abs(np.diff(q, axis=0)).max(axis=1)
    dt = np.maximum(np.asarray(dt_nominal, dtype=float), dq / v_max)
    return np.concatenate([[0.0], np.cumsum(dt)])


def waypoint_clearance(
    robot: DensoVM6083,
    q: np.ndarray,
    obstacles: Obstacles,
    nozzle_m: float,
    kp: tuple[float, ...],
    foci: tuple[tuple[int, int], ...],
    chunk: int = 4096,
    *,
    horizon: float = np.inf,
    sign_only: bool = False,
    margin: float = 0.0,
    rel_tol: float = 0.0,
) -> np.ndarray:
    """Signed clearance (m) of the force-field ellipsoids per way-point (see
    :func:`planners.blasting.collision.clearance` for ``horizon``,
    ``sign_only`` and ``rel_tol``)."""
    if obstacles.empty:
        return np.full(len(q), np.inf)
    out = np.empty(len(q))
    for s in range(0, len(q), chunk):
        S = link_spheroids(robot, q[s : s + chunk], nozzle_m, kp, foci)
        out[s : s + chunk] = clearance(
            S, obstacles, horizon=horizon, sign_only=sign_only, margin=margin, rel_tol=rel_tol
        )
    return out
