"""Per-edge robot path: RRT-Connect in (x, y, yaw) with PIBC validity (seed §2.3, §4.3, Fig. 5.6).

The seed plans "the motion path for one edge each time" with an RRT whose
free configurations are those whose projected footprint points all lie inside
a steel boundary (Alg. 6).  Here: RRT-Connect (two trees, greedy connect) on
(x, y, yaw) with the metric ``sqrt(dx² + dy² + (r·dyaw)²)`` (r = the
footprint's half length, so a turn costs what its corners sweep), motions
checked at a fixed resolution with one vectorised PIBC call per motion,
followed by random shortcut smoothing.  Samples are drawn half along the
edge's corridor (bars are narrow: uniform samples would almost all be off the
steel) and half uniformly around it.  Deterministic for a given ``seed``.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

ValidFn = Callable[[np.ndarray], np.ndarray]


def wrap(a: np.ndarray | float) -> np.ndarray:
    """Angle(s) wrapped into [-π, π)."""
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


@dataclass
class EdgePath:
    """Robot poses (x, y, yaw in plane coordinates) along one route edge."""

    u: int
    v: int
    poses: np.ndarray  # (K, 3)
    ok: bool
    message: str = ""
    iterations: int = 0
    extra: dict[str, float] = field(default_factory=dict)

    def as_dict(self) -> dict[str, object]:
        return {
            "u": self.u,
            "v": self.v,
            "poses": self.poses.tolist(),
            "ok": self.ok,
            "message": self.message,
            "iterations": self.iterations,
        }


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


class EdgePlanner:
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
        ta, tb = _Tree(start, 256), _Tree(goal, 256)
        a_is_start = True
        buffer: list[np.ndarray] = []
        for it in range(1, self.max_iter + 1):
            # Grow towards free samples only: on a narrow bar most raw samples
            # are off the steel, and extending towards them mostly fails.  The
            # samples are checked 256 at a time (one vectorised PIBC call).
            if not buffer:
                batch = np.array([sampler() for _ in range(256)])
                ok = self.valid(batch)
                buffer = list(batch[ok][::-1]) if ok.any() else list(batch[:32][::-1])
            q = buffer.pop()
            status, ja = self._extend(ta, q)
            if status != "trapped":
                status_b, jb = self._connect(tb, ta.q[ja])
                if status_b == "reached":
                    pa, pb = ta.path_to_root(ja)[::-1], tb.path_to_root(jb)
                    path = np.vstack([pa, pb[1:]])
                    if not a_is_start:
                        path = path[::-1]
                    return path, it
            ta, tb = tb, ta
            a_is_start = not a_is_start
        return None, self.max_iter

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


def corridor_sampler(
    a: np.ndarray,
    b: np.ndarray,
    rng: np.random.Generator,
    *,
    lateral_sigma_m: float,
    margin_m: float,
) -> Callable[[], np.ndarray]:
    """40 % of the samples near the segment a→b with yaw near its direction
    (either way), 30 % around its end points with any yaw (a turn happens at a
    vertex: a crossing), 30 % uniform in its bounding box (± margin)."""
    d = b - a
    yaw = float(np.arctan2(d[1], d[0])) if np.hypot(*d) > 1e-9 else 0.0
    normal = np.array([-np.sin(yaw), np.cos(yaw)])
    lo = np.minimum(a, b) - margin_m
    hi = np.maximum(a, b) + margin_m

    def sample() -> np.ndarray:
        u = rng.random()
        if u < 0.4:
            t = rng.uniform(-0.2, 1.2)
            p = a + t * d + rng.normal(0.0, lateral_sigma_m) * normal
            y = yaw + (np.pi if rng.random() < 0.5 else 0.0) + rng.normal(0.0, 0.35)
        elif u < 0.7:
            p = (a if rng.random() < 0.5 else b) + rng.normal(0.0, 0.5 * margin_m, 2)
            y = rng.uniform(-np.pi, np.pi)
        else:
            p = rng.uniform(lo, hi)
            y = rng.uniform(-np.pi, np.pi)
        return np.array([p[0], p[1], float(wrap(y))])

    return sample


def settle_pose(
    point: np.ndarray,
    toward: np.ndarray,
    yaw_hint: float,
    valid: ValidFn,
    *,
    step_m: float = 0.01,
    yaw_offsets_deg: tuple[float, ...] = (0.0, 180.0, 15.0, -15.0, 165.0, -165.0, 30.0, -30.0),
) -> np.ndarray | None:
    """The valid pose nearest to ``point`` along the segment point→toward, trying
    yaws around ``yaw_hint`` (vectorised: all candidates in one PIBC call).

    At a bar's free end the robot cannot stand on the end vertex itself (its
    footprint would overhang); it goes as far as the steel allows.
    """
    d = toward - point
    length = float(np.hypot(*d))
    n = max(1, int(np.ceil(length / step_m)))
    t = np.linspace(0.0, 1.0, n + 1)
    xy = point + t[:, None] * d
    yaws = wrap(yaw_hint + np.deg2rad(np.asarray(yaw_offsets_deg)))
    cand = np.concatenate(
        [np.column_stack([xy, np.full(len(xy), y)]) for y in yaws]
    )  # ordered by yaw, then distance
    ok = valid(cand).reshape(len(yaws), len(xy))
    if not ok.any():
        return None
    first = np.where(ok.any(axis=0))[0][0]  # nearest position with any valid yaw
    k = int(np.argmax(ok[:, first]))  # first yaw in preference order
    return np.array([xy[first, 0], xy[first, 1], yaws[k]])
