"""Per-edge robot path: RRT-Connect in (x, y, yaw) with PIBC validity (seed §2.3, §4.3, Fig. 5.6).

The seed plans "the motion path for one edge each time" with an RRT whose
free configurations are those whose projected footprint points all lie inside
a steel boundary (Alg. 6).  Both planners here take the validity checkers of
:mod:`planners.motion`: a batch state-validity callable ``valid(Q)`` over
(N, 3) poses and a motion validator ``motion_valid(a, b) -> bool``.

* :class:`EdgePlanner` (``motion_model="holonomic"``, the seed's planner):
  straight motions in (x, y, yaw), so it is OMPL's RRT-Connect and path
  simplifier through :func:`planners.motion.plan_motion`, the yaw an SO2
  dimension.
* :class:`DiffDrivePlanner` (the default): turns in place and straight drives
  only — rotate–translate–rotate steering, which OMPL's geometric planners
  do not have (its Reeds–Shepp space needs a positive turning radius), so its
  RRT-Connect (:func:`rrt_connect`, samples from :func:`corridor_sampler`)
  and random shortcutting stay here; its motion validator checks one
  primitive (:func:`primitive_validator`).

Deterministic for a given ``seed``.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from planners.errors import InvalidInputError
from planners.motion import MotionValid, Valid, plan_motion
from planners.motion import wrap_angle as wrap
from planners.navigation.pibc import chunk_slices

__all__ = [
    "DiffDrivePlanner",
    "EdgePath",
    "EdgePlanner",
    "corridor_sampler",
    "primitive_poses",
    "primitive_validator",
    "rrt_connect",
    "rt_waypoints",
    "rtr_cost",
    "rtr_waypoints",
    "settle_pose",
    "wrap",
]

#: Most turn poses :meth:`DiffDrivePlanner.turn_point` checks in one validity
#: call (each is then projected to every footprint point: 4096 × the body's
#: ~100 points stays well inside ``pibc.CHUNK_ELEMENTS``-sized temporaries).
TURN_CHUNK_POSES = 4096
#: Candidate turning points whose turn passes and whose whole way
#: :meth:`DiffDrivePlanner.turn_point` then checks before giving up.
TURN_WAYS_TRIED = 64
#: Positions along the segment :func:`settle_pose` checks per validity call.
SETTLE_CHUNK_POSITIONS = 128


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
    """An RRT tree of poses: node array grown by doubling, parent indices."""

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


Extend = Callable[[_Tree, np.ndarray], tuple[str, int]]  # (tree, target) → (status, node)


def rrt_connect(
    start: np.ndarray,
    goal: np.ndarray,
    sampler: Callable[[], np.ndarray],
    valid: Valid,
    extend: Extend,
    max_iterations: int,
) -> tuple[np.ndarray | None, int]:
    """RRT-Connect (Kuffner & LaValle 2000) with the steering ``extend``
    (grow a tree from its nearest node towards a target: ``"reached"``,
    ``"advanced"`` or ``"trapped"``, and the node reached); connecting is
    repeated extension.  Targets are the samples of ``sampler`` that pass
    ``valid``, checked 256 at a time: on a narrow bar most raw samples are
    off the steel, and extending towards them mostly fails.  Returns the
    poses start → goal or ``None``, and the iterations used."""
    ta, tb = _Tree(start, 256), _Tree(goal, 256)
    a_is_start = True
    buffer: list[np.ndarray] = []
    for it in range(1, max_iterations + 1):
        if not buffer:
            batch = np.array([sampler() for _ in range(256)])
            ok = valid(batch)
            buffer = list(batch[ok][::-1]) if ok.any() else list(batch[:32][::-1])
        q = buffer.pop()
        status, ja = extend(ta, q)
        if status != "trapped":
            status_b, jb = "advanced", -1
            while status_b == "advanced":
                status_b, jb = extend(tb, ta.q[ja])
            if status_b == "reached":
                pa, pb = ta.path_to_root(ja)[::-1], tb.path_to_root(jb)
                path = np.vstack([pa, pb[1:]])
                if not a_is_start:
                    path = path[::-1]
                return path, it
        ta, tb = tb, ta
        a_is_start = not a_is_start
    return None, max_iterations


class EdgePlanner:
    """The seed's holonomic planner (§2.3 RRT in (x, y, yaw)) through OMPL.

    :func:`planners.motion.plan_motion` with the yaw as an OMPL SO2
    dimension (``periodic``): RRT-Connect, range ``step_m``, at most
    ``max_iterations`` iterations, the metric ``‖Δxy‖ + r·|Δyaw|`` (``r`` =
    ``yaw_radius_m``, the footprint's half length, so a turn costs what its
    ends sweep), then OMPL's simplifier (``shortcut_rounds`` vertex
    reductions, then collapsing close vertices).  A search that spends its
    budget is restarted with the next seed up to ``restarts`` times (OMPL
    samples the whole box uniformly where the hand-written planner drew
    from the edge's corridor; a fresh tree recovers the narrow passages a
    first one missed).  ``valid`` is the batch
    state validity (Alg. 6 on the footprint), ``motion_valid(a, b)`` the
    straight (x, y, yaw) motion — by default :meth:`motion_ok`: poses every
    ``resolution_m`` in the metric √(dx² + dy² + (r·dyaw)²), yaw the short
    way round, all in one validity call.  Same seed → same path.
    """

    def __init__(
        self,
        valid: Valid,
        *,
        yaw_radius_m: float,
        step_m: float = 0.08,
        resolution_m: float = 0.01,
        max_iterations: int = 1500,
        shortcut_rounds: int = 60,
        motion_valid: MotionValid | None = None,
        restarts: int = 2,
    ):
        self.valid = valid
        self.restarts = int(restarts)
        self.r = float(max(yaw_radius_m, 1e-3))
        self.step = float(step_m)
        self.res = float(resolution_m)
        self.max_iter = int(max_iterations)
        self.shortcut_rounds = int(shortcut_rounds)
        self.motion_valid: MotionValid = motion_valid or self.motion_ok

    def dist(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """√(dx² + dy² + (r·dyaw)²), yaw the short way (the densifying metric)."""
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

    def plan(
        self,
        start: np.ndarray,
        goal: np.ndarray,
        *,
        lower: np.ndarray,
        upper: np.ndarray,
        seed: int,
    ) -> tuple[np.ndarray | None, int]:
        """Poses from ``start`` to ``goal`` (both valid), simplified, or
        ``None``; iterations used.  ``lower``/``upper`` (2,) bound the
        positions sampled (widened to hold both ends); the direct motion is
        tried first."""
        lo = np.minimum(np.asarray(lower, dtype=float), np.minimum(start[:2], goal[:2]))
        hi = np.maximum(np.asarray(upper, dtype=float), np.maximum(start[:2], goal[:2]))
        used = 0
        for attempt in range(self.restarts + 1):
            res = plan_motion(
                start, goal[None], self.valid, lower=np.r_[lo, -np.pi], upper=np.r_[hi, np.pi],
                seed=seed + attempt, motion_valid=self.motion_valid, range_=self.step,
                # the iteration budget governs, not the clock
                max_time_s=600.0, max_iterations=self.max_iter,
                simplify_steps=self.shortcut_rounds,
                weights=np.array([1.0, 1.0, self.r]), periodic=(2,),
            )  # fmt: skip
            used += res.iterations
            if res.path is not None:
                return res.path, used
        return None, used

    def densify(self, path: np.ndarray) -> np.ndarray:
        """The poses along ``path`` every ``resolution_m`` (the metric of :meth:`dist`)."""
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
    valid: Valid,
    *,
    step_m: float = 0.01,
    yaw_offsets_deg: tuple[float, ...] = (0.0, 180.0, 15.0, -15.0, 165.0, -165.0, 30.0, -30.0),
) -> np.ndarray | None:
    """The valid pose nearest to ``point`` along the segment point→toward, trying
    yaws around ``yaw_hint`` in the order given at the nearest position that has
    any valid one.

    Positions are checked nearest first, ``SETTLE_CHUNK_POSITIONS`` of them
    (every yaw at each) per validity call, stopping at the first batch with
    a valid pose: a long edge's far positions are only looked at when the
    near ones all fail, and no call holds more than a bounded batch.

    At a bar's free end the robot cannot stand on the end vertex itself (its
    footprint would overhang); it goes as far as the steel allows.
    """
    d = toward - point
    length = float(np.hypot(*d))
    n = max(1, int(np.ceil(length / step_m)))
    t = np.linspace(0.0, 1.0, n + 1)
    xy = point + t[:, None] * d
    yaws = wrap(yaw_hint + np.deg2rad(np.asarray(yaw_offsets_deg)))
    for sl in chunk_slices(len(xy), 1, SETTLE_CHUNK_POSITIONS):
        cand = np.concatenate(
            [np.column_stack([xy[sl], np.full(len(xy[sl]), y)]) for y in yaws]
        )  # ordered by yaw, then distance
        ok = valid(cand).reshape(len(yaws), len(xy[sl]))
        if ok.any():
            first = np.where(ok.any(axis=0))[0][0]  # nearest position with any valid yaw
            k = int(np.argmax(ok[:, first]))  # first yaw in preference order
            return np.array([xy[sl][first, 0], xy[sl][first, 1], yaws[k]])
    return None


# ------------------------------------------------------------------ differential drive
def rtr_cost(a: np.ndarray, b: np.ndarray, r: float, allow_reverse: bool = True) -> np.ndarray:
    """Cost of the cheapest rotate–translate–rotate motion a → b (broadcast over
    leading axes): distance driven + ``r`` × angle turned in place.

    The translation heading is the direction a → b (forward) or, with
    ``allow_reverse``, its opposite (driving backwards); both rotations take
    the short way round.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    d = b[..., :2] - a[..., :2]
    dist = np.hypot(d[..., 0], d[..., 1])
    theta = np.arctan2(d[..., 1], d[..., 0])
    fwd = np.abs(wrap(theta - a[..., 2])) + np.abs(wrap(b[..., 2] - theta))
    turn = fwd
    if allow_reverse:
        back = np.abs(wrap(theta + np.pi - a[..., 2])) + np.abs(wrap(b[..., 2] - theta - np.pi))
        turn = np.minimum(fwd, back)
    pure = np.abs(wrap(b[..., 2] - a[..., 2]))
    return np.where(dist > 1e-9, dist + r * turn, r * pure)


def rtr_waypoints(
    a: np.ndarray, b: np.ndarray, *, allow_reverse: bool = True
) -> list[list[np.ndarray]]:
    """Candidate rotate–translate–rotate way-point lists a → b, cheapest first.

    Each list starts at ``a`` and ends at ``b``; consecutive way-points
    differ either in yaw only (a turn in place) or in position only along
    the shared yaw (a straight drive, forwards or backwards) — the two
    motions of a differential drive whose wheels turn at opposite or equal
    speeds.
    """
    d = b[:2] - a[:2]
    dist = float(np.hypot(*d))
    if dist <= 1e-9:
        return [[a, np.array([a[0], a[1], b[2]])]]
    theta = float(np.arctan2(d[1], d[0]))
    headings = [theta, float(wrap(theta + np.pi))] if allow_reverse else [theta]
    out: list[tuple[float, list[np.ndarray]]] = []
    for h in headings:
        cost = abs(float(wrap(h - a[2]))) + abs(float(wrap(b[2] - h)))
        pts = [a]
        if abs(float(wrap(h - a[2]))) > 1e-12:
            pts.append(np.array([a[0], a[1], h]))
        pts.append(np.array([b[0], b[1], h]))
        if abs(float(wrap(b[2] - h))) > 1e-12:
            pts.append(np.array([b[0], b[1], b[2]]))
        out.append((cost, pts))
    out.sort(key=lambda x: x[0])
    return [p for _, p in out]


def rt_waypoints(
    a: np.ndarray, xy: np.ndarray, *, allow_reverse: bool = True
) -> list[list[np.ndarray]]:
    """Candidate rotate–translate way-point lists from ``a`` to the position
    ``xy`` (any final yaw), the smaller turn first."""
    d = xy - a[:2]
    theta = float(np.arctan2(d[1], d[0]))
    headings = [theta, float(wrap(theta + np.pi))] if allow_reverse else [theta]
    headings.sort(key=lambda h: abs(float(wrap(h - a[2]))))
    out = []
    for h in headings:
        pts = [a]
        if abs(float(wrap(h - a[2]))) > 1e-12:
            pts.append(np.array([a[0], a[1], h]))
        pts.append(np.array([xy[0], xy[1], h]))
        out.append(pts)
    return out


def primitive_poses(
    a: np.ndarray, b: np.ndarray, *, resolution_m: float, turn_resolution_rad: float
) -> np.ndarray:
    """Poses sampled along one differential-drive primitive a → b, ``a``
    excluded, ``b`` included: a turn in place (short way round, steps of at
    most ``turn_resolution_rad``) or a straight drive (steps of at most
    ``resolution_m``).  Raises ``ValueError`` for a pose pair that is neither
    (a sideways slide)."""
    d = b[:2] - a[:2]
    dist = float(np.hypot(*d))
    dyaw = float(wrap(b[2] - a[2]))
    if dist <= 1e-9:
        n = max(1, int(np.ceil(abs(dyaw) / turn_resolution_rad)))
        t = np.linspace(0.0, 1.0, n + 1)[1:]
        return np.column_stack([np.full(n, a[0]), np.full(n, a[1]), wrap(a[2] + t * dyaw)])
    if abs(dyaw) > 1e-9 or abs(d[0] * np.sin(a[2]) - d[1] * np.cos(a[2])) > 1e-7:
        raise InvalidInputError(
            f"pose ({a[0]:.4f}, {a[1]:.4f}, {np.degrees(a[2]):.1f}°) → "
            f"({b[0]:.4f}, {b[1]:.4f}, {np.degrees(b[2]):.1f}°) is neither a turn in place "
            "nor a straight drive along the heading"
        )
    n = max(1, int(np.ceil(dist / resolution_m)))
    t = np.linspace(0.0, 1.0, n + 1)[1:, None]
    xy = a[:2] + t * d
    return np.column_stack([xy, np.full(n, a[2])])


def primitive_validator(
    valid: Valid, *, resolution_m: float, turn_resolution_rad: float
) -> MotionValid:
    """The motion validator of one differential-drive primitive a → b: every
    pose of :func:`primitive_poses` (``a`` excluded) passes ``valid``; every
    4th pose first, so a blocked primitive is rejected cheaply."""

    def check(a: np.ndarray, b: np.ndarray) -> bool:
        poses = primitive_poses(
            a, b, resolution_m=resolution_m, turn_resolution_rad=turn_resolution_rad
        )
        if len(poses) > 4 and not np.all(valid(poses[3::4])):
            return False
        return bool(np.all(valid(poses)))

    return check


class DiffDrivePlanner:
    """RRT-Connect for a differential drive (seed §2.3 RRT, Alg. 6 validity).

    The robot can only turn in place or drive straight along its heading,
    forwards or backwards (wheel speeds opposite or equal); so every tree
    edge is one such primitive, and steering from a pose towards a target is
    rotate → translate (→ rotate onto the target's yaw when it is reached):
    a zero-radius Reeds–Shepp steering.  The differential drive is
    small-time locally controllable, so wherever the holonomic planner of
    :class:`EdgePlanner` finds room to manoeuvre this one can too (by
    multi-point turns), and its paths need no conversion to be driven.

    Nearest neighbours use the rotate–translate–rotate cost
    (:func:`rtr_cost`, turning weighted by ``yaw_radius_m`` so a turn costs
    what the footprint's far end sweeps); then random shortcuts by
    rotate–translate–rotate motions.  Deterministic for a given generator.

    Validity has the shape of :mod:`planners.motion`: ``valid`` decides (N, 3)
    poses in one batch (samples, the candidate turns of :meth:`turn_point`);
    ``motion_valid(a, b)`` one primitive a → b — by default
    :func:`primitive_validator`: poses every ``resolution_m`` along a
    straight and every ``turn_resolution_rad`` in a turn, coarse pass first.
    OMPL has no equivalent of this steering, so the search is kept here
    (:func:`rrt_connect`).
    """

    def __init__(
        self,
        valid: Valid,
        *,
        yaw_radius_m: float,
        step_m: float = 0.08,
        resolution_m: float = 0.01,
        turn_resolution_rad: float = 0.05,
        max_iterations: int = 1500,
        shortcut_rounds: int = 60,
        allow_reverse: bool = True,
        motion_valid: MotionValid | None = None,
    ):
        self.valid = valid
        self.r = float(max(yaw_radius_m, 1e-3))
        self.step = float(step_m)
        self.res = float(resolution_m)
        self.turn_res = float(turn_resolution_rad)
        self.max_iter = int(max_iterations)
        self.shortcut_rounds = int(shortcut_rounds)
        self.allow_reverse = bool(allow_reverse)
        self.motion_valid: MotionValid = motion_valid or primitive_validator(
            valid, resolution_m=self.res, turn_resolution_rad=self.turn_res
        )
        self._batch_ways = motion_valid is None

    # -- motions
    def dist(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return rtr_cost(a, b, self.r, self.allow_reverse)

    def _samples(self, way: list[np.ndarray]) -> np.ndarray:
        return np.vstack(
            [
                primitive_poses(p, q, resolution_m=self.res, turn_resolution_rad=self.turn_res)
                for p, q in itertools.pairwise(way)
            ]
        )

    def way_ok(self, way: list[np.ndarray]) -> bool:
        """Every primitive along ``way`` passes the motion validator.  With the
        default validator (:func:`primitive_validator`) the poses of all its
        primitives go to ``valid`` in one call instead — the same answer,
        one PIBC call where a direct rotate–translate–rotate way would make
        up to six."""
        if self._batch_ways:
            return len(way) < 2 or bool(np.all(self.valid(self._samples(way))))
        return all(self.motion_valid(p, q) for p, q in itertools.pairwise(way))

    def connect_poses(self, a: np.ndarray, b: np.ndarray) -> list[np.ndarray] | None:
        """The cheapest valid rotate–translate–rotate way-points a → b, or None."""
        for way in rtr_waypoints(a, b, allow_reverse=self.allow_reverse):
            if self.way_ok(way):
                return way
        return None

    def path_cost(self, path: np.ndarray) -> float:
        if len(path) < 2:
            return 0.0
        d = np.diff(path, axis=0)
        return float(np.sum(np.hypot(d[:, 0], d[:, 1]) + self.r * np.abs(wrap(d[:, 2]))))

    # -- trees
    def _extend(self, tree: _Tree, target: np.ndarray) -> tuple[str, int]:
        i = int(np.argmin(self.dist(tree.q[: tree.n], target)))
        near = tree.q[i]
        d = target[:2] - near[:2]
        dist = float(np.hypot(*d))
        if dist <= self.step:
            way = self.connect_poses(near, target)
            if way is None:
                return "trapped", i
            reached = True
        else:
            new_xy = near[:2] + d * (self.step / dist)
            way = None
            for cand in rt_waypoints(near, new_xy, allow_reverse=self.allow_reverse):
                if self.way_ok(cand):
                    way = cand
                    break
            if way is None:
                return "trapped", i
            reached = False
        j = i
        for q in way[1:]:
            j = tree.add(q, j)
        return ("reached" if reached else "advanced"), j

    def turn_point(
        self,
        start: np.ndarray,
        goal: np.ndarray,
        centre: np.ndarray,
        *,
        radius_m: float,
        spacing_m: float = 0.005,
    ) -> list[np.ndarray] | None:
        """Drive to a turning point near ``centre``, turn in place there, drive
        on: the cheapest valid such path start → p → goal over a grid of
        points p within ``radius_m`` of ``centre`` (the vertex where the route
        changes bars), or ``None``.

        The turn is where a narrow crossing decides feasibility: the whole
        footprint must stay on steel while it rotates, so the best point is
        rarely the vertex itself (in an L corner it lies towards the inside
        of the corner).  Candidates are taken cheapest first: their turns are
        checked in batches of at most ``TURN_CHUNK_POSES`` poses, and the full
        paths of the first ``TURN_WAYS_TRIED`` whose turn passes, in that
        order; the first valid path is returned, so memory stays bounded and
        the search stops as soon as it has its answer.
        """
        n = int(np.ceil(radius_m / spacing_m))
        g = np.arange(-n, n + 1) * spacing_m
        gx, gy = np.meshgrid(g, g, indexing="ij")
        keep = gx**2 + gy**2 <= radius_m**2
        pts = np.asarray(centre, dtype=float) + np.column_stack([gx[keep], gy[keep]])
        # Heading in (start → p) and out (p → goal), forwards or backwards,
        # and the turn between them the short way round.
        d_in = pts - start[:2]
        d_out = goal[:2] - pts
        th_in = np.arctan2(d_in[:, 1], d_in[:, 0])
        th_out = np.arctan2(d_out[:, 1], d_out[:, 0])
        flips = [0.0, np.pi] if self.allow_reverse else [0.0]
        cands = []  # (cost, p index, heading in, heading out)
        for fi in flips:
            for fo in flips:
                h_in = wrap(th_in + fi)
                h_out = wrap(th_out + fo)
                cost = (
                    np.hypot(*d_in.T)
                    + np.hypot(*d_out.T)
                    + self.r
                    * (
                        np.abs(wrap(h_in - start[2]))
                        + np.abs(wrap(h_out - h_in))
                        + np.abs(wrap(goal[2] - h_out))
                    )
                )
                cands.append(np.column_stack([cost, np.arange(len(pts)), h_in, h_out]))
        c = np.vstack(cands)
        c = c[np.argsort(c[:, 0], kind="stable")]
        # Pre-check the turn at p alone (the hard part), cheapest candidates
        # first, a bounded batch of turns per state-validity call; the motion
        # validator decides the whole way of the first ``TURN_WAYS_TRIED``
        # whose turn passes.  (One call over every candidate held all their
        # turn poses × footprint points at once: gigabytes for a body-sized
        # radius, and mostly wasted, as a cheap candidate usually passes.)
        per_turn = int(np.ceil(np.pi / self.turn_res)) + 1  # poses of the longest turn
        tried = 0
        for sl in chunk_slices(len(c), per_turn, TURN_CHUNK_POSES):
            turns = [
                primitive_poses(
                    np.array([*pts[int(i)], hi]),
                    np.array([*pts[int(i)], ho]),
                    resolution_m=self.res,
                    turn_resolution_rad=self.turn_res,
                )
                for _, i, hi, ho in c[sl]
            ]
            counts = np.array([len(t) for t in turns])
            ok = self.valid(np.vstack(turns))
            bad_per = np.add.reduceat(~ok, np.concatenate([[0], np.cumsum(counts)[:-1]]))
            for _, i, hi, ho in c[sl][bad_per == 0]:
                if tried == TURN_WAYS_TRIED:
                    return None
                tried += 1
                p = pts[int(i)]
                way = [start]
                if abs(float(wrap(hi - start[2]))) > 1e-12:
                    way.append(np.array([start[0], start[1], hi]))
                way.append(np.array([p[0], p[1], hi]))
                if abs(float(wrap(ho - hi))) > 1e-12:
                    way.append(np.array([p[0], p[1], ho]))
                way.append(np.array([goal[0], goal[1], ho]))
                if abs(float(wrap(goal[2] - ho))) > 1e-12:
                    way.append(goal.copy())
                if self.way_ok(way):
                    return way
        return None

    def plan(
        self,
        start: np.ndarray,
        goal: np.ndarray,
        sampler: Callable[[], np.ndarray],
        *,
        turn_centre: np.ndarray | None = None,
        turn_radius_m: float = 0.0,
    ) -> tuple[np.ndarray | None, int]:
        """Way-points from ``start`` to ``goal`` (both valid) whose consecutive
        pairs are differential-drive primitives, or ``None``; iterations used.

        Tries, in order: the direct rotate–translate–rotate motion; one turn
        in place at the best point within ``turn_radius_m`` of
        ``turn_centre`` (:meth:`turn_point`); RRT-Connect."""
        direct = self.connect_poses(start, goal)
        if direct is not None:
            return np.array(direct), 0
        if turn_centre is not None and turn_radius_m > 0:
            way = self.turn_point(start, goal, turn_centre, radius_m=turn_radius_m)
            if way is not None:
                return np.array(way), 0
        return rrt_connect(start, goal, sampler, self.valid, self._extend, self.max_iter)

    def shortcut(self, path: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Random shortcuts: replace way-points i..j by a valid, cheaper
        rotate–translate–rotate motion."""
        path = path.copy()
        for _ in range(self.shortcut_rounds):
            if len(path) <= 2:
                break
            i, j = sorted(rng.choice(len(path), size=2, replace=False))
            if j - i < 2:
                continue
            way = self.connect_poses(path[i], path[j])
            if way is None:
                continue
            if self.path_cost(np.array(way)) < self.path_cost(path[i : j + 1]) - 1e-9:
                path = np.vstack([path[:i], np.array(way), path[j + 1 :]])
        return path

    def densify(self, path: np.ndarray) -> np.ndarray:
        """Every sampled pose of the primitives along ``path`` (the poses the
        wheels will drive through, at the planner's resolutions)."""
        if len(path) < 2:
            return path.copy()
        return np.vstack([path[:1], self._samples(list(path))])
