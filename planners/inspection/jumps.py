"""Inch-worm jumps of an inspection route, planned at planning time (seed 000 §3.2, Fig. 3.5 / 5.4).

Every inch-worm transition of the route (:mod:`.transitions`: Eq. 3.1 false,
or a jump across a gap) has a jump site (:mod:`.layout`): foot 2 standing at
the end of the current driving line, foot 1's target on the landing line.
Each is planned with the ``ara.switch`` jump planner,
:func:`planners.switching.jump.plan_inchworm_jump` (phases A–F of §3.2:
magnet 2 touched, foot 1 to P_conv, OMPL RRT-Connect to the target, magnets
swap, foot 2 follows, mobile configuration), with the target as the
foothold in the standing base frame and foot 2's landing fixed one foot
spacing ahead of foot 1 along its x axis (the mobile configuration, so the
robot drives on without re-arranging its feet).

Obstacles (:func:`site_obstacles`): the scan points within ``radius_m`` of
the joint and the structure model's member faces sampled on a grid there,
thinned on a voxel grid that grows until at most ``max_points`` remain.

Sharing: sites whose standing → landing transform agrees within a rounding
(``position_round_m``, ``angle_round_deg`` on the rotation vector) and whose
members have the same section (depth and width rounded to
``section_round_m``) share one planned jump — planned once, for the first
such site, by :func:`plan_geometry` (a pure function of one geometry, so the
unique geometries can be mapped over a pool) — placed at every site by its
standing pose.  Every placement is re-checked against its own obstacles
(:func:`planners.switching.jump.jump_clearance`): the clearance a check
reports is the placed jump's, never the representative's.  A jump that
cannot be planned is recorded with the planner's reason (a failing check,
not an exception).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import shapely
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation
from shapely.geometry import Polygon

from planners.errors import CancelledError, PlannerError
from planners.inspection.faces import FaceGeom
from planners.inspection.layout import JumpSite, ProgramLayout
from planners.structure.model import Member, StructureModel
from planners.switching.jump import (
    JumpParams,
    JumpPlan,
    JumpRobot,
    arm_length,
    jump_clearance,
    landing_configurations,
    plan_inchworm_jump,
    wrist_distance,
)

__all__ = [
    "JumpSetParams",
    "PlacedJump",
    "PlannedJumps",
    "inspection_jump_params",
    "jump_key",
    "plan_geometry",
    "plan_site_jumps",
    "reach_test",
    "site_obstacles",
    "unreachable_reason",
]

Progress = Callable[[float, str], None]


@dataclass(frozen=True)
class JumpSetParams:
    """Tunables of the route's jumps, units in the names.

    ``radius_m``: obstacles within this of the joint (the robot's reach,
    0.7 m, plus the mobile footprint behind the standing foot);
    ``voxel_m``/``max_points``: obstacle thinning; ``face_step_m``: grid of
    the member faces' sample points; ``position_round_m``,
    ``angle_round_deg``, ``section_round_m``: the sharing key;
    ``landing_tolerance_m`` / ``landing_tolerance_deg``: a placed foot is on
    the landing face when its sole is within this of the face's plane and
    its normal within this angle; ``jump``: the jump planner's params (its
    ``seed`` is the first unique geometry's; the k-th gets ``seed + k``)."""

    radius_m: float = 1.0
    voxel_m: float = 0.01
    max_points: int = 20_000
    face_step_m: float = 0.02
    position_round_m: float = 0.02
    angle_round_deg: float = 3.0
    section_round_m: float = 0.02
    landing_tolerance_m: float = 0.01
    landing_tolerance_deg: float = 3.0
    jump: JumpParams = field(default_factory=lambda: inspection_jump_params(0.5))


#: The known standing surface the jump planner adds (``standing_patch_m``)
#: for an inspection jump: only under foot 2's sole (0.18 × 0.12 m).  The
#: ``ara.switch`` default (0.88 × 0.4 m, the floor the camera cannot see)
#: invents steel beside a diagonal's 0.2 m web where the arm must pass
#: below the standing plane; here the standing face itself is among the
#: obstacles (the member faces' samples, :func:`face_samples`).
STANDING_PATCH_M = ((-0.09, 0.09), (-0.06, 0.06))


def inspection_jump_params(foot_spacing_m: float, **overrides: Any) -> JumpParams:
    """The jump planner's params for an inspection jump: foot 2 lands
    ``foot_spacing_m`` ahead of foot 1 along its x axis and nowhere else
    (the mobile configuration: the robot drives on without re-arranging its
    feet), foot 1 exactly on its target (not flipped, not shifted), the
    standing patch only under foot 2 (:data:`STANDING_PATCH_M`), and foot
    2's landing IK seeded with the mobile configuration (the straight arm
    is singular: random seeds miss it)."""
    base = JumpParams(
        second_foot_distances_m=(float(foot_spacing_m),),
        second_foot_angles_deg=(0.0,),
        max_second_foot_candidates=1,
        try_flipped=False,
        inward_shifts_m=(0.0,),
        standing_patch_m=STANDING_PATCH_M,
        mobile_ik_seed=True,
    )
    return replace(base, **overrides)


@dataclass
class PlacedJump:
    """A planned jump at one site: ``site`` (index into the layout's sites),
    ``unique`` (index into :attr:`PlannedJumps.plans`), the standing pose it
    is placed at, the feet's landed poses in the model frame, the clearance
    of the placed jump against this site's obstacles (``None`` when not
    planned), whether both feet land on the landing face (with the measured
    misfit), and ``error`` (why it was not planned)."""

    site: int
    unique: int | None
    standing: np.ndarray
    foot1: np.ndarray | None = None
    foot2: np.ndarray | None = None
    min_clearance_m: float | None = None
    min_self_clearance_m: float | None = None
    on_steel: bool = False
    landing_misfit_m: float | None = None
    error: str | None = None


@dataclass
class PlannedJumps:
    """Every site's jump: ``plans`` (one per unique geometry, ``None`` when
    it could not be planned, with ``errors`` saying why), ``keys`` (their
    sharing keys), ``placed`` (one per site, in route order),
    ``planner_calls`` and ``timings_s``."""

    plans: list[JumpPlan | None]
    errors: list[str | None]
    keys: list[tuple[Any, ...]]
    placed: list[PlacedJump]
    planner_calls: int
    timings_s: dict[str, float]


def jump_key(site: JumpSite, members: dict[int, Member], p: JumpSetParams) -> tuple[Any, ...]:
    """Sharing key of a site: the standing → landing transform (translation
    rounded to ``position_round_m``, rotation vector to ``angle_round_deg``)
    and both members' sections (depth, width rounded to ``section_round_m``)."""
    rel = site.relative
    t = tuple(int(v) for v in np.round(rel[:3, 3] / p.position_round_m))
    rv = Rotation.from_matrix(rel[:3, :3]).as_rotvec(degrees=True)
    r = tuple(int(v) for v in np.round(rv / p.angle_round_deg))

    def section(mid: int | None) -> tuple[int, int]:
        if mid is None:
            return (-1, -1)
        m = members[mid]
        return (round(m.depth_m / p.section_round_m), round(m.width_m / p.section_round_m))

    return (t, r, section(site.from_member), section(site.to_member))


def same_geometry(site: JumpSite, rep: JumpSite, p: JumpSetParams) -> bool:
    """Can ``rep``'s jump serve ``site``?  Placed at ``site``'s standing
    pose, ``rep``'s foot-1 target, seen from ``site``'s own target, must lie
    within ``position_round_m`` in the landing plane, within
    ``landing_tolerance_m`` / 2 across it, its normal within
    ``landing_tolerance_deg`` and its heading within ``angle_round_deg``."""
    d = np.linalg.inv(site.landing) @ site.standing @ rep.relative
    tilt = math.degrees(math.acos(float(np.clip(d[2, 2], -1.0, 1.0))))
    turn = abs(math.degrees(math.atan2(float(d[1, 0]), float(d[0, 0]))))
    return bool(
        max(abs(float(d[0, 3])), abs(float(d[1, 3]))) <= p.position_round_m
        and abs(float(d[2, 3])) <= p.landing_tolerance_m / 2
        and tilt <= p.landing_tolerance_deg
        and turn <= p.angle_round_deg
    )


def face_samples(model: StructureModel, step_m: float) -> np.ndarray:
    """(N, 3) points on every member face of ``model``, a ``step_m`` grid in
    each face's plane clipped to its outline (the faces as obstacles)."""
    out = []
    for f in model.faces:
        g = FaceGeom.of(f)
        if g.polygon.is_empty:
            continue
        x0, y0, x1, y1 = g.polygon.bounds
        gx, gy = np.meshgrid(np.arange(x0, x1 + 1e-9, step_m), np.arange(y0, y1 + 1e-9, step_m))
        xy = np.column_stack([gx.ravel(), gy.ravel()])
        xy = xy[shapely.contains_xy(g.polygon, xy[:, 0], xy[:, 1])]
        if len(xy):
            out.append(g.to_world(xy))
    return np.vstack(out) if out else np.zeros((0, 3))


def _thin(points: np.ndarray, voxel: float, cap: int) -> np.ndarray:
    """One point per voxel (the first in input order), the voxel doubled
    until at most ``cap`` remain: a bounded count, deterministic."""
    v = voxel
    while True:
        if len(points) == 0:
            return points
        keys = np.floor((points - points.min(axis=0)) / v).astype(np.int64)
        _, first = np.unique(keys, axis=0, return_index=True)
        kept = points[np.sort(first)]
        if len(kept) <= cap:
            return kept
        v *= 2.0


def site_obstacles(
    scan: cKDTree | None,
    scan_points: np.ndarray,
    faces: cKDTree | None,
    face_points: np.ndarray,
    centre: np.ndarray,
    p: JumpSetParams,
) -> np.ndarray:
    """(N, 3) obstacle points of a site, model frame: scan points and face
    samples within ``radius_m`` of ``centre``, thinned (:func:`_thin`)."""
    parts = []
    for tree, pts in ((scan, scan_points), (faces, face_points)):
        if tree is not None and len(pts):
            idx = tree.query_ball_point(centre, p.radius_m)
            if len(idx):
                parts.append(pts[np.sort(np.asarray(idx, dtype=np.int64))])
    allp = np.vstack(parts) if parts else np.zeros((0, 3))
    return _thin(allp, p.voxel_m, p.max_points)


def _to_frame(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Points in the frame of pose ``T`` (rigid inverse)."""
    R, t = T[:3, :3], T[:3, 3]
    return (np.asarray(points, float) - t) @ R


def _surface(site: JumpSite) -> tuple[np.ndarray, np.ndarray, np.ndarray, Any] | None:
    """The landing face in the standing base frame, as the jump planner's
    ``surface`` (origin, x, y, outline in (x, y))."""
    ln = site.landing_line
    if ln is None:
        return None
    R = site.standing[:3, :3]
    origin = _to_frame(site.standing, ln.origin[None])[0]
    return origin, R.T @ ln.direction, R.T @ ln.across, ln.polygon


def unreachable_reason(robot: Any, relative: np.ndarray) -> str | None:
    """Why foot 1 can never land at ``relative`` (4×4, standing base frame),
    or ``None``: the wrist points are farther apart than the arm
    (:func:`planners.switching.jump.wrist_distance` > link2 + link3 + link4,
    an exact bound: no joint values reach it; seed §3.2)."""
    model = robot if hasattr(robot, "params") else None
    d, arm = wrist_distance(relative, model), arm_length(model)
    if d <= arm:
        return None
    return (
        f"UnreachableError: the landing is out of the arm's reach: its wrist point (0.1 m off "
        f"the face) is {d:.3f} m from joint 2 (0.1 m above the standing sole), the arm "
        f"(link2 + link3 + link4) is {arm:.2f} m"
    )


def _is_robot(robot: Any) -> bool:
    """A jump robot or a robot model :meth:`JumpRobot.from_model` adapts
    (not a test's stand-in object)."""
    return isinstance(robot, JumpRobot) or (
        hasattr(robot, "ik_solutions") and hasattr(robot, "collision_shapes")
    )


def adapt_robot(robot: Any, params: JumpParams) -> JumpRobot | None:
    """The jump planner's robot (:meth:`JumpRobot.from_model`, adapted once),
    ``None`` for an object that is no robot model (tests' stub planners)."""
    if isinstance(robot, JumpRobot):
        return robot
    if _is_robot(robot):
        return JumpRobot.from_model(robot, ik_seeds=params.ik_seeds)
    return None


def reach_test(
    robot: Any,
    model: StructureModel,
    points: np.ndarray,
    params: JumpSetParams | None = None,
    *,
    adapted: JumpRobot | None = None,
) -> Callable[[np.ndarray, np.ndarray, np.ndarray], bool]:
    """``reach(standing, landing, joint)`` for
    :func:`planners.inspection.layout.layout_program`: can foot 1 land at
    ``landing`` from foot 2 at ``standing`` (4×4, model frame)?  First the
    exact arm-length bound (:func:`unreachable_reason`), then the landing
    configurations phase C would accept
    (:func:`planners.switching.jump.landing_configurations`: IK, straight
    approach clear of the site's obstacles and of the robot itself, foot 2
    able to lift off) — no RRT, about 0.1 s a placement.  Obstacles per
    joint as :func:`plan_site_jumps` builds them (cached by joint)."""
    p = params or JumpSetParams()
    rob = adapted if adapted is not None else adapt_robot(robot, p.jump)
    if rob is None:
        raise PlannerError("reach_test needs a robot model (ik_solutions, collision_shapes)")
    pts = np.asarray(points, float).reshape(-1, 3)
    scan = cKDTree(pts) if len(pts) else None
    fpts = face_samples(model, p.face_step_m)
    ftree = cKDTree(fpts) if len(fpts) else None
    cache: dict[tuple[float, ...], np.ndarray] = {}
    model_robot = robot if hasattr(robot, "params") else None

    def reach(standing: np.ndarray, landing: np.ndarray, joint: np.ndarray) -> bool:
        rel = np.linalg.inv(standing) @ landing
        if wrist_distance(rel, model_robot) > arm_length(model_robot):
            return False
        key = tuple(np.round(np.asarray(joint, float), 6))
        if key not in cache:
            cache[key] = site_obstacles(scan, pts, ftree, fpts, np.asarray(joint, float), p)
        obs = _to_frame(standing, cache[key])
        return len(landing_configurations(rob, rel, obstacles=obs, params=p.jump, limit=1)) > 0

    return reach


def plan_geometry(
    robot: Any,
    foothold: np.ndarray,
    obstacles: np.ndarray,
    surface: tuple[np.ndarray, np.ndarray, np.ndarray, Any] | None,
    params: JumpParams,
) -> tuple[JumpPlan | None, str | None]:
    """Plan one jump geometry (a pure function of its arguments, so unique
    geometries can be mapped over a process pool): the foothold of foot 1
    (4×4, standing base frame), obstacle points and the landing face in
    that frame.  Returns (plan, None), or (None, the planner's reason)."""
    try:
        return (
            plan_inchworm_jump(
                robot, foothold, obstacles=obstacles, surface=surface, params=params
            ),
            None,
        )
    except CancelledError:
        raise
    except PlannerError as exc:
        return None, f"{type(exc).__name__}: {exc}"


def _landing_fit(
    site: JumpSite, T: np.ndarray, foot: tuple[float, float], p: JumpSetParams
) -> tuple[bool, float]:
    """Does a foot at ``T`` (model frame) stand on the landing face: sole
    within ``landing_tolerance_m`` of its plane, normal within
    ``landing_tolerance_deg``, footprint inside the outline?  (ok, misfit:
    the sole's distance from the plane, m)."""
    ln = site.landing_line
    if ln is None:
        return False, math.inf
    off = abs(float((T[:3, 3] - ln.origin) @ ln.normal))
    ang = math.degrees(math.acos(float(np.clip(T[:3, 2] @ ln.normal, -1.0, 1.0))))
    hl, hw = foot[0] / 2, foot[1] / 2
    corners = np.array([[hl, hw, 0], [-hl, hw, 0], [-hl, -hw, 0], [hl, -hw, 0]]) @ T[:3, :3].T
    c = corners + T[:3, 3] - ln.origin
    st = np.column_stack([c @ ln.direction, c @ ln.across])
    inside = bool(ln.polygon.covers(Polygon(st)))
    ok = off <= p.landing_tolerance_m and ang <= p.landing_tolerance_deg and inside
    return ok, off


def plan_site_jumps(
    robot: Any,
    layout: ProgramLayout,
    model: StructureModel,
    points: np.ndarray,
    params: JumpSetParams | None = None,
    *,
    foot: tuple[float, float] = (0.18, 0.12),
    progress: Progress | None = None,
    mapper: Callable[[Callable[..., Any], list[tuple[Any, ...]]], list[Any]] | None = None,
) -> PlannedJumps:
    """Plan the jump of every site of ``layout`` (seed §3.2), each unique
    geometry once.

    ``robot``: the ARA model or a :class:`planners.switching.jump.JumpRobot`
    (adapt it once: every plan shares the sphere covers); ``points``: the
    (cropped, metre) scan, model frame; ``foot``: the sole (length, width)
    for the landing test; ``progress(fraction, "jump i/n")`` before each
    unique geometry; ``mapper(f, args)``: maps :func:`plan_geometry` over
    the unique geometries' argument tuples (default: in order, here; a
    process pool's ``map`` fits).

    Steps: obstacles per site (:func:`site_obstacles`, KD-trees built once);
    the sharing key per site (:func:`jump_key`); the first site of each key
    planned (the k-th unique geometry with seed ``jump.seed + k``); every
    site placed at its standing pose, its feet tested on the landing face
    and the others re-checked against their own obstacles.
    """
    p = params or JumpSetParams()
    t0 = time.perf_counter()
    members = {m.id: m for m in model.members}
    pts = np.asarray(points, float).reshape(-1, 3)
    scan = cKDTree(pts) if len(pts) else None
    fpts = face_samples(model, p.face_step_m)
    ftree = cKDTree(fpts) if len(fpts) else None
    obstacles: dict[int, np.ndarray] = {}
    keys: list[tuple[Any, ...]] = []
    unique_of: dict[int, int] = {}
    first: list[int] = []
    real = _is_robot(robot)
    skipped: dict[int, str] = {}
    for i, site in enumerate(layout.sites):
        if site.error is not None:
            continue
        if real:
            why = unreachable_reason(robot, site.relative)
            if why is None and site.reachable is False:
                why = (
                    f"UnreachableError: foot 1 cannot land from any of the {site.reach_tries} "
                    "placements tried (no IK solution with a clear straight approach, "
                    "free of the robot itself, from which foot 2 can lift)"
                )
            if why is not None:
                skipped[i] = why
                continue
        centre = 0.5 * (site.standing[:3, 3] + site.landing[:3, 3])
        obstacles[i] = _to_frame(site.standing, site_obstacles(scan, pts, ftree, fpts, centre, p))
        key = jump_key(site, members, p)
        k = next(
            (
                k
                for k, j in enumerate(first)
                if keys[k][2:] == key[2:] and same_geometry(site, layout.sites[j], p)
            ),
            None,
        )
        if k is None:
            k = len(first)
            keys.append(key)
            first.append(i)
        unique_of[i] = k
    timings = {"obstacles": time.perf_counter() - t0}

    t0 = time.perf_counter()
    args = [
        (
            robot,
            layout.sites[i].relative,
            obstacles[i],
            _surface(layout.sites[i]),
            replace(p.jump, seed=p.jump.seed + k),
        )
        for k, i in enumerate(first)
    ]
    if mapper is None:
        results = []
        for k, a in enumerate(args):
            if progress is not None:
                progress(k / max(len(args), 1), f"jump {k + 1}/{len(args)}")
            results.append(plan_geometry(*a))
    else:
        results = list(mapper(plan_geometry, args))
    plans = [r[0] for r in results]
    errors = [r[1] for r in results]
    timings["plan"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    placed: list[PlacedJump] = []
    for i, site in enumerate(layout.sites):
        if site.error is not None or i in skipped:
            err = site.error if site.error is not None else skipped[i]
            placed.append(PlacedJump(i, None, site.standing, error=err))
            continue
        k = unique_of[i]
        plan = plans[k]
        if plan is None:
            placed.append(PlacedJump(i, k, site.standing, error=errors[k]))
            continue
        if first[k] == i:
            clear, selfc = plan.clearance, plan.self_clearance
        else:
            clear, selfc = jump_clearance(robot, plan, obstacles[i], params=args[k][4])
        f1 = site.standing @ plan.foot1_target
        f2 = site.standing @ plan.foot2_target
        ok1, mis1 = _landing_fit(site, f1, foot, p)
        ok2, mis2 = _landing_fit(site, f2, foot, p)
        placed.append(
            PlacedJump(
                i,
                k,
                site.standing,
                foot1=f1,
                foot2=f2,
                min_clearance_m=float(np.min(clear)),
                min_self_clearance_m=float(np.min(selfc)),
                on_steel=ok1 and ok2,
                landing_misfit_m=max(mis1, mis2),
            )
        )
    timings["recheck"] = time.perf_counter() - t0
    if progress is not None:
        progress(1.0, f"jumps planned ({len(args)} unique of {len(layout.sites)})")
    return PlannedJumps(plans, errors, keys, placed, len(args), timings)
