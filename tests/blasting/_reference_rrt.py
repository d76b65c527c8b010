"""The blasting planner's former hand-written RRT-Connect,
kept as the baseline that ``tests/benchmarks/bench_motion.py --blasting``
measures OMPL's against, same problems, same run.

Bidirectional RRT in J1–J5 (J6 never moves), nearest neighbours in the
weighted L1 metric Σ w|Δq|, extensions of at most ``step_m`` in it, goal
bias towards the other tree's root, every edge certified by
:func:`planners.blasting.motion.edge_free`.
"""

from __future__ import annotations

import numpy as np

from planners.blasting.motion import ClearFn, RRTResult, edge_free


def rrt_connect_legacy(
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
    goal_bias: float = 0.1,
) -> RRTResult:
    """RRT-Connect between joint vectors ``qa`` and ``qb``; joints not in
    ``active`` (default J1–J5) keep qa's value.  Extensions are at most
    ``step_m`` in the weighted metric (≈ the largest motion of any
    ellipsoid point); every edge is certified by :func:`edge_free`."""
    qa = np.asarray(qa, dtype=float)
    qb = np.asarray(qb, dtype=float)
    act = np.arange(5) if active is None else np.asarray(active)
    lo, hi = limits[act, 0], limits[act, 1]
    wa = w[act]

    def full(x: np.ndarray) -> np.ndarray:
        q = np.repeat(qa[None], len(x), axis=0)
        q[:, act] = x
        return q

    def cfn(x: np.ndarray) -> np.ndarray:
        return clear_fn(full(np.atleast_2d(x)))

    xa, xb = qa[act], qb[act]
    ca0, cb0 = cfn(xa)[0], cfn(xb)[0]
    if ca0 <= 0 or cb0 <= 0:
        return RRTResult(None, 0, 0)
    if edge_free(full(xa[None]), full(xb[None]), clear_fn, w, ca=[ca0], cb=[cb0])[0]:
        return RRTResult(np.stack([qa, qb]), 2, 0)
    trees = [
        {"x": [xa], "c": [ca0], "parent": [-1]},
        {"x": [xb], "c": [cb0], "parent": [-1]},
    ]

    def nearest(t: dict, x: np.ndarray) -> int:
        X = np.asarray(t["x"])
        return int(np.argmin(np.abs(X - x) @ wa))

    def steer(x0: np.ndarray, x1: np.ndarray) -> np.ndarray:
        d = float(np.abs(x1 - x0) @ wa)
        return x1 if d <= step_m else x0 + (x1 - x0) * (step_m / d)

    def extend(t: dict, x: np.ndarray) -> tuple[str, int]:
        k = nearest(t, x)
        xn = steer(np.asarray(t["x"][k]), x)
        cn = cfn(xn)[0]
        if cn <= 0:
            return "trapped", k
        if not edge_free(full(np.asarray(t["x"][k])[None]), full(xn[None]), clear_fn, w,
                         ca=[t["c"][k]], cb=[cn])[0]:  # fmt: skip
            return "trapped", k
        t["x"].append(xn)
        t["c"].append(cn)
        t["parent"].append(k)
        reached = np.allclose(xn, x, atol=1e-12)
        return ("reached" if reached else "advanced"), len(t["x"]) - 1

    def trace(t: dict, k: int) -> list[np.ndarray]:
        out = []
        while k >= 0:
            out.append(np.asarray(t["x"][k]))
            k = t["parent"][k]
        return out

    it = 0
    for it in range(1, max_iter + 1):
        a, b = (0, 1) if it % 2 else (1, 0)
        goal = trees[b]["x"][0]
        x_rand = goal if rng.random() < goal_bias else rng.uniform(lo, hi)
        status, ka = extend(trees[a], x_rand)
        if status == "trapped":
            continue
        x_new = np.asarray(trees[a]["x"][ka])
        while True:  # connect: greedy extension of the other tree
            status_b, kb = extend(trees[b], x_new)
            if status_b != "advanced":
                break
        if status_b == "reached":
            pa = trace(trees[a], ka)[::-1]
            pb = trace(trees[b], kb)[1:]
            joined = pa + pb
            if a == 1:
                joined = joined[::-1]
            n = len(trees[0]["x"]) + len(trees[1]["x"])
            return RRTResult(full(np.asarray(joined)), n, it)
    return RRTResult(None, len(trees[0]["x"]) + len(trees[1]["x"]), it)
