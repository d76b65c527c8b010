"""Joint-space motion planning for the blasting arm (ours; extends seed §3.4.2).

The seed avoids collisions with a penalty in the sequencing (Eq. 3.15) and
rejects penetrating configurations; it has no planner for a transition whose
straight joint interpolation passes through an obstacle.  Here:

* :func:`displacement_weights` — per joint i a bound ``w_i`` (m/rad) on how
  fast any point of the force-field ellipsoids moves when joint i turns (the
  chain length from joint i's axis to the farthest focus plus that
  ellipsoid's semi-major axis).  Along a straight joint segment every point
  of the arm moves at most ``D = Σ w_i |Δq_i|``, so the ellipsoid clearance
  (§3.4.2; 1-Lipschitz in that motion) changes by at most D.
* :func:`edge_free` — certified check of straight joint segments: a segment
  whose end clearances (minus the margin) sum to more than D is free
  throughout; otherwise it is bisected (batched over all segments) until
  every piece is certified or a configuration within the margin is found.
* :func:`rrt_connect` — OMPL's RRT-Connect (Kuffner & LaValle 2000;
  :func:`planners.motion.plan_motion`) in the joint space (J1–J5; J6 is the
  free roll of the axisymmetric nozzle and never moves): the clearance as
  state validity, :func:`edge_free` injected as the motion validator, OMPL's
  metric scaled by ``w``, OMPL's simplifier; then :func:`shortcut` (random
  pairs, deterministic, certified) and :func:`densify` (≤ ``max_step`` per
  joint) so the trajectory's time stamps can hold the 30°/s limit
  (Eq. 3.12–3.13).  The hand-written RRT-Connect it replaced is kept as the
  benchmark baseline (``tests/blasting/_reference_rrt.py``).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:
    from robots.denso_vm6083 import DensoVM6083
from planners.motion import plan_motion

ClearFn = Callable[[np.ndarray], np.ndarray]  # (T,6) → (T,) clearance minus margin (m)


def displacement_weights(
    robot: DensoVM6083,
    nozzle_m: float,
    kp: tuple[float, ...],
    foci: tuple[tuple[int, int], ...],
) -> np.ndarray:
    """(6,) bounds w_i (m per rad): no point of the ellipsoids moves faster
    than Σ w_i |q̇_i|.  A point x of an ellipsoid rigid with a link after
    joint i lies within its semi-major axis a of the ellipsoid centre, whose
    distance from joint i's axis is at most the farther focus's: the chain
    |a_i| + Σ_{k>i}(|a_k| + |d_k|) (+ the nozzle for the tip) from frame
    origin i−1, which lies on the axis (d_i runs along it)."""
    n = 6
    seg = np.abs(np.asarray(robot.a, dtype=float)) + np.abs(np.asarray(robot.d, dtype=float))

    # bound on the distance from joint i's axis to point j (frame origin j, 7 =
    # nozzle tip): the chain of link offsets from frame origin i−1, whose
    # first d_i runs along the axis itself and adds nothing
    def chain(i: int, j: int) -> float:
        if j < i:
            return 0.0
        last = 6 if j == 7 else j
        tail = nozzle_m if j == 7 else 0.0
        return float(abs(robot.a[i - 1]) + seg[i:last].sum() + tail)

    w = np.zeros(n)
    for (f1, f2), k in zip(foci, kp, strict=True):
        j1 = f1 if f1 >= 0 else 7
        j2 = f2 if f2 >= 0 else 7
        # focal distance (constant: both foci are rigid with one link)
        L = _focal_length(robot, j1, j2, nozzle_m)
        a = 0.5 * L * float(k)
        last = max(j1, j2)  # the ellipsoid moves with joints 1..last (tip: 1..5)
        for i in range(1, n + 1):
            if i > min(last, 5):
                continue
            w[i - 1] = max(w[i - 1], max(chain(i, j1), chain(i, j2)) + a)
    return w


def _focal_length(robot: DensoVM6083, j1: int, j2: int, nozzle_m: float) -> float:
    q = np.zeros(6)
    F = robot.frames(q)
    pts = [F[k, :3, 3] for k in range(7)] + [F[-1, :3, 3] + nozzle_m * F[-1, :3, 2]]
    return float(np.linalg.norm(pts[j2] - pts[j1]))


def weighted_distance(qa: np.ndarray, qb: np.ndarray, w: np.ndarray) -> np.ndarray:
    """D = Σ w_i |Δq_i|: a bound on how far any ellipsoid point moves."""
    return np.abs(np.asarray(qb) - np.asarray(qa)) @ w


def edge_free(
    qa: np.ndarray,
    qb: np.ndarray,
    clear_fn: ClearFn,
    w: np.ndarray,
    *,
    ca: ArrayLike | None = None,
    cb: ArrayLike | None = None,
    max_depth: int = 12,
) -> np.ndarray:
    """Which straight segments qa[k] → qb[k] ((K,6) each) stay free: a piece
    is certified when the clearances (minus margin) at its ends sum to more
    than its weighted length; undecided pieces are halved (batched) up to
    ``max_depth`` times; a piece end with clearance ≤ 0 fails the segment."""
    qa = np.atleast_2d(np.asarray(qa, dtype=float))
    qb = np.atleast_2d(np.asarray(qb, dtype=float))
    ca = clear_fn(qa) if ca is None else np.asarray(ca, dtype=float)
    cb = clear_fn(qb) if cb is None else np.asarray(cb, dtype=float)
    ok = (ca > 0) & (cb > 0)
    # pieces: (segment id, start q, end q, start c, end c)
    sid = np.nonzero(ok)[0]
    A, B, cA, cB = qa[sid], qb[sid], ca[sid], cb[sid]
    for _ in range(max_depth + 1):
        if len(sid) == 0:
            break
        done = cA + cB > weighted_distance(A, B, w)
        sid, A, B, cA, cB = sid[~done], A[~done], B[~done], cA[~done], cB[~done]
        if len(sid) == 0:
            break
        M = 0.5 * (A + B)
        cM = clear_fn(M)
        bad = cM <= 0
        ok[np.unique(sid[bad])] = False
        keep = ok[sid]
        sid, A, B, cA, cB, M, cM = (x[keep] for x in (sid, A, B, cA, cB, M, cM))
        sid = np.r_[sid, sid]
        A, B = np.r_[A, M], np.r_[M, B]
        cA, cB = np.r_[cA, cM], np.r_[cM, cB]
    if len(sid):  # still undecided at the depth limit: not certified
        ok[np.unique(sid)] = False
    return ok


@dataclass
class RRTResult:
    """A certified path (P,6) from ``qa`` to ``qb`` (both included) or None,
    with the tree sizes and iterations used."""

    path: np.ndarray | None
    nodes: int
    iterations: int


def rrt_connect(
    qa: np.ndarray,
    qb: np.ndarray,
    clear_fn: ClearFn,
    limits: np.ndarray,
    w: np.ndarray,
    *,
    rng: np.random.Generator,
    step_m: float = 0.12,
    max_iter: int = 1500,
    active: np.ndarray | None = None,
) -> RRTResult:
    """OMPL's RRT-Connect (Kuffner & LaValle 2000) between joint vectors ``qa``
    and ``qb``; joints not in ``active`` (default J1–J5) keep qa's value.

    State validity is ``clear_fn > 0``; every edge is certified by
    :func:`edge_free`, injected as OMPL's motion validator; OMPL's metric is
    scaled by ``w`` (‖w ⊙ Δq‖₂) and its range is ``step_m`` (≈ the largest
    motion of any ellipsoid point); ``max_iter`` planner iterations at most;
    the seed is drawn from ``rng``, so runs are reproducible."""
    qa = np.asarray(qa, dtype=float)
    qb = np.asarray(qb, dtype=float)
    act = np.arange(5) if active is None else np.asarray(active)
    lo, hi = limits[act, 0], limits[act, 1]

    def full(x: np.ndarray) -> np.ndarray:
        q = np.repeat(qa[None], len(x), axis=0)
        q[:, act] = x
        return q

    def cfn(x: np.ndarray) -> np.ndarray:
        return clear_fn(full(np.atleast_2d(x)))

    xa, xb = qa[act], qb[act]
    if cfn(xa)[0] <= 0 or cfn(xb)[0] <= 0:
        return RRTResult(None, 0, 0)
    res = plan_motion(
        xa, xb[None], lambda x: cfn(x) > 0,
        lower=np.minimum(lo, np.minimum(xa, xb)), upper=np.maximum(hi, np.maximum(xa, xb)),
        seed=int(rng.integers(2**31 - 1)),
        motion_valid=lambda x0, x1: bool(edge_free(full(x0[None]), full(x1[None]), clear_fn, w)[0]),
        range_=step_m, max_time_s=600.0, max_iterations=max_iter,
        weights=np.maximum(w[act], 1e-9),
    )  # fmt: skip
    path = None if res.path is None else full(res.path)
    return RRTResult(path, max(res.vertices, 2 if path is not None else 0), res.iterations)


def shortcut(
    path: np.ndarray,
    clear_fn: ClearFn,
    w: np.ndarray,
    *,
    rng: np.random.Generator,
    tries: int = 60,
) -> np.ndarray:
    """Random-pair shortcutting: replace the path between two of its
    vertices by the straight segment when that is certified free."""
    path = np.asarray(path, dtype=float)
    for _ in range(tries):
        if len(path) <= 2:
            break
        i, j = sorted(rng.choice(len(path), size=2, replace=False))
        if j - i < 2:
            continue
        if edge_free(path[i][None], path[j][None], clear_fn, w)[0]:
            path = np.vstack([path[: i + 1], path[j:]])
    # and greedily from the start: the farthest vertex reachable in one segment
    out = [path[0]]
    i = 0
    while i < len(path) - 1:
        for j in range(len(path) - 1, i, -1):
            if j == i + 1 or edge_free(path[i][None], path[j][None], clear_fn, w)[0]:
                out.append(path[j])
                i = j
                break
    return np.asarray(out)


def densify(path: np.ndarray, max_step: float) -> np.ndarray:
    """Way-points along the polyline, no joint moving more than ``max_step``
    (rad) between neighbours; the first vertex is excluded, the last kept."""
    out = []
    for a, b in itertools.pairwise(path):
        n = max(1, int(np.ceil(np.abs(b - a).max() / max_step)))
        t = np.arange(1, n + 1)[:, None] / n
        out.append(a + t * (b - a))
    return np.vstack(out) if out else np.zeros((0, path.shape[1]))
