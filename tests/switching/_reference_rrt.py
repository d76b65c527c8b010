"""The inch-worm jump's former hand-written RRT-Connect, kept
as the baseline that ``tests/benchmarks/bench_motion.py`` measures OMPL's
against on the same problems in the same run.

Kuffner & LaValle (2000): two trees (start; all goal configurations as roots
of the other) grow alternately; one extends a step towards a random sample
(a goal with probability ``goal_bias``), the other connects greedily towards
the new node; edges are checked by batching the interpolated configurations
at ``resolution`` rad into one call of ``valid``; then random shortcutting.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from planners.motion import interpolate

Valid = Callable[[np.ndarray], np.ndarray]  # (K, d) configs → (K,) bool


def segment_free(a: np.ndarray, b: np.ndarray, valid: Valid, resolution: float) -> bool:
    # Coarse pass first (every 4th sample) to reject colliding segments cheaply.
    cand = interpolate(a, b, resolution)
    if not np.all(valid(cand[3::4])):
        return False
    return bool(np.all(valid(cand)))


class _Tree:
    def __init__(self, roots: np.ndarray) -> None:
        self.nodes = [np.asarray(r, float) for r in roots]
        self.parent = [-1] * len(roots)
        self._arr = np.array(self.nodes)

    def add(self, q: np.ndarray, parent: int) -> int:
        self.nodes.append(q)
        self.parent.append(parent)
        self._arr = np.vstack([self._arr, q[None]])
        return len(self.nodes) - 1

    def nearest(self, q: np.ndarray) -> int:
        return int(np.argmin(np.sum((self._arr - q) ** 2, axis=1)))

    def path_to_root(self, i: int) -> list[np.ndarray]:
        out = []
        while i >= 0:
            out.append(self.nodes[i])
            i = self.parent[i]
        return out


def _steer(
    tree: _Tree, target: np.ndarray, valid: Valid, step: float, resolution: float, greedy: bool
) -> tuple[int | None, bool]:
    """Extend (one step) or connect (greedy, as far as valid) towards target.

    Returns (index of the last node added or None, reached target)."""
    i = tree.nearest(target)
    q = tree.nodes[i]
    delta = target - q
    dist = float(np.linalg.norm(delta))
    if dist < 1e-9:
        return i, True
    goal = target if (greedy or dist <= step) else q + delta * (step / dist)
    cand = interpolate(q, goal, resolution)
    first_bad = _first_invalid(cand, valid)
    if first_bad is None:
        j = tree.add(goal, i)
        return j, bool(np.allclose(goal, target))
    if first_bad == 0:
        return None, False
    j = tree.add(cand[first_bad - 1], i)  # furthest valid configuration
    return j, False


def _first_invalid(cand: np.ndarray, valid: Valid, chunk: int = 16) -> int | None:
    """Index of the first invalid configuration, checking in chunks so a long
    greedy connection that collides early costs little."""
    for s in range(0, len(cand), chunk):
        ok = valid(cand[s : s + chunk])
        if not ok.all():
            return s + int(np.argmin(ok))
    return None


def rrt_connect(
    start: np.ndarray,
    goals: np.ndarray,
    valid: Valid,
    *,
    lower: np.ndarray,
    upper: np.ndarray,
    rng: np.random.Generator,
    step: float = 0.25,
    resolution: float = 0.03,
    goal_bias: float = 0.1,
    max_iterations: int = 1500,
) -> np.ndarray | None:
    """A path (P, d) from ``start`` to one of ``goals`` (G, d), or ``None``."""
    start = np.asarray(start, float)
    goals = np.atleast_2d(np.asarray(goals, float))
    for g in goals:  # direct shot first: frequent for short jumps
        if segment_free(start, g, valid, resolution):
            return np.vstack([start, g])
    ta, tb = _Tree(start[None]), _Tree(goals)
    a_is_start = True
    for _ in range(int(max_iterations)):
        if rng.random() < goal_bias:
            pool = tb.nodes[: len(goals)] if a_is_start else [start]
            target = pool[int(rng.integers(len(pool)))]
        else:
            target = rng.uniform(lower, upper)
        new, _ = _steer(ta, target, valid, step, resolution, greedy=False)
        if new is not None:
            j, reached = _steer(tb, ta.nodes[new], valid, step, resolution, greedy=True)
            if reached and j is not None:
                # tb's node j equals ta's node `new`: join the two root paths.
                if a_is_start:
                    path = ta.path_to_root(new)[::-1] + tb.path_to_root(j)[1:]
                else:
                    path = tb.path_to_root(j)[::-1] + ta.path_to_root(new)[1:]
                return np.array(path)
        ta, tb = tb, ta
        a_is_start = not a_is_start
    return None


def shortcut(
    path: np.ndarray,
    valid: Valid,
    *,
    rng: np.random.Generator,
    iterations: int = 80,
    resolution: float = 0.03,
) -> np.ndarray:
    """Random shortcutting: replace the sub-path between two random waypoints
    by a straight joint-space segment when that segment is valid."""
    pts = [np.asarray(p, float) for p in path]
    for _ in range(int(iterations)):
        if len(pts) <= 2:
            break
        i, j = sorted(rng.choice(len(pts), size=2, replace=False))
        if j - i < 2:
            continue
        if segment_free(pts[i], pts[j], valid, resolution):
            pts = pts[: i + 1] + pts[j:]
    return np.array(pts)


def plan_path_legacy(
    start: np.ndarray,
    goals: np.ndarray,
    valid: Valid,
    *,
    lower: np.ndarray,
    upper: np.ndarray,
    rng: np.random.Generator,
    step: float = 0.25,
    resolution: float = 0.03,
    goal_bias: float = 0.1,
    max_iterations: int = 1500,
    shortcut_iterations: int = 80,
) -> np.ndarray | None:
    """One RRT-Connect attempt, then shortcutting (the jump's former ``plan_path``)."""
    path = rrt_connect(
        start, goals, valid, lower=lower, upper=upper, rng=rng, step=step,
        resolution=resolution, goal_bias=goal_bias, max_iterations=max_iterations,
    )  # fmt: skip
    if path is None:
        return None
    return shortcut(path, valid, rng=rng, iterations=shortcut_iterations, resolution=resolution)
