"""The hand-written holonomic RRT-Connect that ``planners.navigation.rrt.EdgePlanner``
used before it moved to OMPL (``planners.motion.plan_motion`` with an SO2 yaw),
frozen as the benchmark and test baseline (as ``tests/switching/_reference_rrt.py``
is for the jump).  Copied from commit 111f02a, ``planners/navigation/rrt.py``:
``_Tree``, ``_rrt_connect`` and ``EdgePlanner`` (renamed ``EdgePlannerLegacy``),
unchanged; it samples with ``planners.navigation.rrt.corridor_sampler``.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np

from planners.navigation.rrt import wrap

ValidFn = Callable[[np.ndarray], np.ndarray]


class _Tree:
    def __init__(self, root: np.ndarray, cap: int):
        self.q = np.zeros((cap, 3))
        self.parent = np.full(cap, -1, dtype=np.int64)
        self.q[0] = root
        self.n = 1

    def add(self, q: np.ndarray, parent: int) -> int:
        if self.n == len(self.q):
            self.q = np.vstack([self.q, np.zeros_like(self.q)])
            self.parent = np.concatenate([self.parent, np.full(len(self.parent), -1)])
        self.q[self.n] = q
        self.parent[self.n] = parent
        self.n += 1
        return self.n - 1

    def path_to_root(self, i: int) -> np.ndarray:
        out = []
        while i >= 0:
            out.append(self.q[i])
            i = int(self.parent[i])
        return np.array(out)


def _rrt_connect(
    planner: EdgePlannerLegacy,
    start: np.ndarray,
    goal: np.ndarray,
    sampler: Callable[[], np.ndarray],
) -> tuple[np.ndarray | None, int]:
    """RRT-Connect (Kuffner & LaValle 2000) with ``planner``'s ``valid``,
    ``_extend``, ``_connect`` and ``max_iter``: poses start → goal or
    ``None``, and the iterations used."""
    ta, tb = _Tree(start, 256), _Tree(goal, 256)
    a_is_start = True
    buffer: list[np.ndarray] = []
    for it in range(1, planner.max_iter + 1):
        # Grow towards free samples only: on a narrow bar most raw samples
        # are off the steel, and extending towards them mostly fails.  The
        # samples are checked 256 at a time (one vectorised PIBC call).
        if not buffer:
            batch = np.array([sampler() for _ in range(256)])
            ok = planner.valid(batch)
            buffer = list(batch[ok][::-1]) if ok.any() else list(batch[:32][::-1])
        q = buffer.pop()
        status, ja = planner._extend(ta, q)
        if status != "trapped":
            status_b, jb = planner._connect(tb, ta.q[ja])
            if status_b == "reached":
                pa, pb = ta.path_to_root(ja)[::-1], tb.path_to_root(jb)
                path = np.vstack([pa, pb[1:]])
                if not a_is_start:
                    path = path[::-1]
                return path, it
        ta, tb = tb, ta
        a_is_start = not a_is_start
    return None, planner.max_iter


class EdgePlannerLegacy:
    """RRT-Connect + shortcut smoothing for one pose pair."""

    def __init__(
        self,
        valid: ValidFn,
        *,
        yaw_radius_m: float,
        step_m: float = 0.08,
        resolution_m: float = 0.01,
        max_iterations: int = 1500,
        shortcut_rounds: int = 60,
    ):
        self.valid = valid
        self.r = float(max(yaw_radius_m, 1e-3))
        self.step = float(step_m)
        self.res = float(resolution_m)
        self.max_iter = int(max_iterations)
        self.shortcut_rounds = int(shortcut_rounds)

    def dist(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        d = b - a
        return np.sqrt(d[..., 0] ** 2 + d[..., 1] ** 2 + (self.r * wrap(d[..., 2])) ** 2)

    def interpolate(
        self, a: np.ndarray, b: np.ndarray, *, include_start: bool = True
    ) -> np.ndarray:
        n = max(1, int(np.ceil(float(self.dist(a, b)) / self.res)))
        t = np.linspace(0.0, 1.0, n + 1)[:, None]
        if not include_start:
            t = t[1:]
        d = b - a
        d = np.array([d[0], d[1], float(wrap(d[2]))])
        q = a + t * d
        q[:, 2] = wrap(q[:, 2])
        return q

    def motion_ok(self, a: np.ndarray, b: np.ndarray) -> bool:
        return bool(np.all(self.valid(self.interpolate(a, b, include_start=False))))

    def _steer(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        d = float(self.dist(a, b))
        if d <= self.step:
            return b.copy()
        f = self.step / d
        delta = b - a
        out = a + f * np.array([delta[0], delta[1], float(wrap(delta[2]))])
        out[2] = float(wrap(out[2]))
        return out

    def _extend(self, tree: _Tree, target: np.ndarray) -> tuple[str, int]:
        dists = self.dist(tree.q[: tree.n], target)
        i = int(np.argmin(dists))
        new = self._steer(tree.q[i], target)
        if not self.motion_ok(tree.q[i], new):
            return "trapped", i
        j = tree.add(new, i)
        return ("reached" if float(self.dist(new, target)) < 1e-9 else "advanced"), j

    def _connect(self, tree: _Tree, target: np.ndarray) -> tuple[str, int]:
        status, j = "advanced", -1
        while status == "advanced":
            status, j = self._extend(tree, target)
        return status, j

    def plan(
        self, start: np.ndarray, goal: np.ndarray, sampler: Callable[[], np.ndarray]
    ) -> tuple[np.ndarray | None, int]:
        """Poses from ``start`` to ``goal`` (both must be valid) or ``None``; iterations used."""
        if self.motion_ok(start, goal):
            return np.array([start, goal]), 0
        return _rrt_connect(self, start, goal, sampler)

    def shortcut(self, path: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Random shortcutting: replace a sub-path by a straight motion when valid."""
        path = path.copy()
        for _ in range(self.shortcut_rounds):
            if len(path) <= 2:
                break
            i, j = sorted(rng.choice(len(path), size=2, replace=False))
            if j - i < 2:
                continue
            if self.motion_ok(path[i], path[j]):
                path = np.vstack([path[: i + 1], path[j:]])
        return path

    def densify(self, path: np.ndarray) -> np.ndarray:
        out = [path[:1]]
        for a, b in itertools.pairwise(path):
            out.append(self.interpolate(a, b, include_start=False))
        return np.vstack(out)
