"""Sand-blasting planner (seed 004, Chapters 3–4).

``plan_blasting(surface, ...)`` (DESIGN §5) runs the chain of seed Fig. 3.1:
nozzle model (Eq. 3.1) → hexagonal disc pattern (§3.2.2) → classification
(Eq. 3.2) and boundary editing (§3.2.3, or ours) → sequencing (Eq. 3.3–3.4,
3.15; the seed's GA or ours) → with a robot: IK per spot with the least
joint change (§3.4.1), way-points and speed limits (Eq. 3.12–3.13), and the
force-field ellipsoid clearance (§3.4.2) at every way-point.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import shapely
import shapely.affinity

from planners.blasting import arm as _arm
from planners.blasting import coverage as _cov
from planners.blasting import motion as _motion
from planners.blasting import sequencing as _seq
from planners.blasting.bound import pointwise_bound, zero_overspray_reach
from planners.blasting.collision import Box, Obstacles, Spheroids, clearance
from planners.blasting.footprint import Cone, ellipse_matrices, exact_ellipse
from planners.blasting.nozzle import (
    NOZZLES,
    Nozzle,
    blast_radius_m,
    check_stream_length,
    get_nozzle,
)
from planners.blasting.surface import Surface
from planners.errors import InfeasibleError, InvalidInputError

__all__ = [
    "NOZZLES",
    "BlastPlan",
    "Box",
    "Nozzle",
    "Obstacles",
    "Spheroids",
    "Surface",
    "blast_radius_m",
    "plan_blasting",
]

START_POSE_DEG = (0.0, -75.0, 160.0, 0.0, 30.0, 0.0)  # seed §4.2.4
KP = (1.05, 1.10, 1.10)  # seed §4.2.5
FOCI = ((1, 2), (3, 4), (4, -1))  # chosen: upper arm, forearm, wrist + nozzle (params.toml)
MAX_TILT_DEG = 45.0  # seed §3.2.1: nozzle 45–90° to the surface
JUMP_RAD = np.deg2rad(15.0)  # a larger joint change between close way-points is a reconfiguration
SAFETY_M = 0.002  # chosen: a configuration is free only with this much ellipsoid clearance
STEP_RAD = np.deg2rad(2.0)  # largest joint step between way-points of a joint-space move
RETRACT_M = np.array([0.1, 0.2])  # chosen: back-off distances along the nozzle axis for via moves
CLEAR_REL_TOL = 0.05  # chosen: planning bounds may understate a gap by 5 % (the report is exact)
CLEAR_HORIZON_M = 0.25  # clearances beyond this are kept as lower bounds (enough to certify moves)
COVERAGE_TARGET = 0.99  # issue 5: coverage ≥ 99 %
OVERSPRAY_TARGET = 0.005  # issue 5: overspray ≤ 0.5 %
JOINT_PLANNERS = ("rrt", "none")
# chosen: RRT-Connect iterations per blocked move and per plan (deterministic
# budget; an iteration costs ~0.1–0.3 s of clearance evaluations on the
# 2-core machine); a move not found within it leaves its spot unreached
RRT_MAX_ITER = 150
RRT_BUDGET_ITER = 300


@dataclass
class BlastPlan:
    """Result of :func:`plan_blasting`.

    Discs (index = disc id): ``centers`` (N,3) world, ``centers_2d`` (N,2)
    plane, ``radii`` (N,), ``classes`` (N,) — Eq. 3.2 class of the lattice
    disc it came from (1 inside, 3 boundary; 4 = added by our cover step),
    ``stream_mm`` (N,), ``tilt_deg`` (N,).  ``order`` visits disc ids;
    ``skipped`` are disc ids no collision-free configuration reaches (not in
    ``order``).  Coverage/overspray are rasterised over the visited discs.
    With a robot: ``joint_trajectory`` (T,6) rad, ``times`` (T,) s,
    ``clearance`` (T,) m (signed; ``inf`` without obstacles),
    ``waypoint_spot`` (T,) disc id at a spot or −1, ``segment`` (T,) 0 start
    pose, 1 approach, 2 blasting move, 3 reconfiguration; per disc
    ``ik_residual_mm`` and ``ik_residual_deg`` (0 for closed-form solutions).

    Footprints (exact cone–plane sections, :mod:`planners.blasting.footprint`):
    ``centers`` are their centres; the nozzle axis meets the surface at
    ``aim_points`` (N,3) / ``aim_points_2d``; ``semi_axes`` (N,2) = (a along
    ``major_dir_2d``, b) in metres.  ``coverage_reach``: share of the surface
    discs of the smallest admissible footprint reach without overspray;
    ``coverage_bound``: certified upper bound on coverage within the 0.5 %
    overspray target (computed when coverage < 99 %, see
    :mod:`planners.blasting.bound`).  ``unreached``: disc ids whose pose is
    free but that no certified joint-space path reaches (also in
    ``skipped``); ``motion``: joint planner statistics.
    """

    radius: float
    centers: np.ndarray
    centers_2d: np.ndarray
    radii: np.ndarray
    classes: np.ndarray
    stream_mm: np.ndarray
    tilt_deg: np.ndarray
    order: np.ndarray
    skipped: np.ndarray
    distance_m: float
    turns: int
    objective: float
    lower_bound_m: float
    mst_m: float
    coverage: float
    overspray: float
    coverage_planned: float
    overspray_planned: float
    lattice_centers_2d: np.ndarray
    lattice_classes: np.ndarray
    spacing_m: float
    params: dict[str, Any] = field(default_factory=dict)
    timings_s: dict[str, float] = field(default_factory=dict)
    joint_trajectory: np.ndarray | None = None
    times: np.ndarray | None = None
    clearance: np.ndarray | None = None
    waypoint_spot: np.ndarray | None = None
    segment: np.ndarray | None = None
    ik_residual_mm: np.ndarray | None = None
    ik_residual_deg: np.ndarray | None = None
    joint_limits: np.ndarray | None = None
    speed_limit_rad_s: float | None = None
    aim_points: np.ndarray | None = None
    aim_points_2d: np.ndarray | None = None
    semi_axes: np.ndarray | None = None
    major_dir_2d: np.ndarray | None = None
    coverage_reach: float | None = None
    coverage_bound: float | None = None
    min_radius_m: float | None = None
    unreached: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    motion: dict[str, float] = field(default_factory=dict)

    def _coverage_message(self, coverage_min: float) -> str:
        msg = f"coverage {self.coverage:.2%} (min {coverage_min:.0%})"
        if self.coverage < coverage_min:
            extra = _coverage_limit_text(self)
            if extra:
                msg += ": " + extra
        return msg

    @property
    def ratio_to_lower_bound(self) -> float:
        return self.distance_m / self.lower_bound_m if self.lower_bound_m > 0 else 1.0

    @property
    def max_joint_speed_rad_s(self) -> float:
        if self.joint_trajectory is None or len(self.times) < 2:
            return 0.0
        dt = np.diff(self.times)
        dq = np.abs(np.diff(self.joint_trajectory, axis=0)).max(axis=1)
        v = np.where(dt > 0, dq / np.where(dt > 0, dt, 1.0), np.where(dq > 0, np.inf, 0.0))
        return float(v.max())

    @property
    def min_clearance_m(self) -> float:
        return (
            float(np.min(self.clearance))
            if self.clearance is not None and len(self.clearance)
            else np.inf
        )

    @property
    def within_joint_limits(self) -> bool:
        if self.joint_trajectory is None:
            return True
        lo, hi = self.joint_limits[:, 0], self.joint_limits[:, 1]
        q = self.joint_trajectory
        return bool(np.all(q >= lo - 1e-9) and np.all(q <= hi + 1e-9))

    def checks(
        self,
        *,
        coverage_min: float = 0.99,
        overspray_max: float = 0.005,
        residual_max_mm: float = 0.1,
    ) -> list[dict[str, Any]]:
        """Plan checks (DESIGN §4) as dicts: name, passed, value, limit, message."""
        out = [
            _check("coverage", self.coverage >= coverage_min, self.coverage, coverage_min,
                   self._coverage_message(coverage_min)),
            _check("overspray", self.overspray <= overspray_max, self.overspray, overspray_max,
                   f"overspray {self.overspray:.3%} of the surface (max {overspray_max:.1%})"),
        ]  # fmt: skip
        if self.joint_trajectory is not None:
            v = self.max_joint_speed_rad_s
            res = float(np.max(self.ik_residual_mm)) if len(self.ik_residual_mm) else 0.0
            out += [
                _check("joint_limits", self.within_joint_limits, self.within_joint_limits, True,
                       "all way-points inside the joint limits" if self.within_joint_limits
                       else "a way-point leaves the joint limits"),
                _check("joint_speed", v <= self.speed_limit_rad_s * (1 + 1e-9), np.degrees(v),
                       np.degrees(self.speed_limit_rad_s),
                       f"max joint speed {np.degrees(v):.2f}°/s (limit {np.degrees(self.speed_limit_rad_s):.0f}°/s)"),
                _check("clearance", self.min_clearance_m > 0, self.min_clearance_m, 0.0,
                       f"min ellipsoid clearance {self.min_clearance_m * 1000:.1f} mm"),
                _check("ik_residual", res <= residual_max_mm, res, residual_max_mm,
                       f"max IK position residual {res:.4f} mm"),
                _check("skipped_spots", len(self.skipped) == 0, len(self.skipped), 0,
                       f"{len(self.skipped)} discs unreachable without collision"),
            ]  # fmt: skip
        return out


def _coverage_limit_text(plan: BlastPlan) -> str:
    parts = []
    if plan.min_radius_m is not None and plan.coverage_reach is not None:
        parts.append(
            f"without overspray footprints ≥ Ø{2000 * plan.min_radius_m:.1f} mm (shortest stream) "
            f"reach {plan.coverage_reach:.2%} of the surface"
        )
    if plan.coverage_bound is not None:
        parts.append(
            f"certified: at most {plan.coverage_bound:.2%} is reachable within "
            f"{OVERSPRAY_TARGET:.1%} overspray (pointwise bound)"
        )
    if len(plan.skipped):
        parts.append(f"{len(plan.skipped)} discs skipped (no collision-free pose or path)")
    return "; ".join(parts)


def _check(name: str, passed: bool, value: Any, limit: Any, message: str) -> dict[str, Any]:
    v = (
        float(value)
        if isinstance(value, (int, float, np.floating, np.integer)) and not isinstance(value, bool)
        else value
    )
    return {"name": name, "passed": bool(passed), "value": v, "limit": limit, "message": message}


def _progress(cb: Callable[[float, str], None] | None, f: float, stage: str) -> None:
    if cb is not None:
        cb(f, stage)


def _coerce_surface(surface: object) -> Surface:
    if isinstance(surface, Surface):
        return surface
    raise InvalidInputError(
        f"surface must be a planners.blasting.Surface (or built with Surface.from_points), got {type(surface).__name__}"
    )


def plan_blasting(
    surface: Surface,
    *,
    nozzle: str | Nozzle = "medium",
    stream_length_mm: float = 300.0,
    sequencer: str = "default",
    robot: Any = None,
    obstacles: Obstacles | Sequence[Box | np.ndarray] = (),
    seed: int = 0,
    disc_radius_m: float | None = None,
    editing: str = "improved",
    fill_stream_mm: float | None = 100.0,
    coverage_target: float = 0.993,
    overspray_budget: float = 0.004,
    collision_penalty_m: float = 1.0,
    kp: Sequence[float] = KP,
    nozzle_length_m: float = 0.1,
    speed_limit_deg_s: float = 30.0,
    traverse_speed_m_s: float = 0.1,
    step_m: float = 0.01,
    approach_waypoints: int = 100,
    start_pose_deg: Sequence[float] = START_POSE_DEG,
    tilt_deg: float | str = "auto",
    joint_planner: str = "none",
    progress: Callable[[float, str], None] | None = None,
) -> BlastPlan:
    """Plan blasting of a planar ``surface`` (DESIGN §5).

    Disc radius from Eq. 3.1 (``nozzle``, ``stream_length_mm`` in 100–500 mm)
    unless ``disc_radius_m`` is given (the seed's scenes use 0.04 m).
    ``editing``: ``"improved"`` (ours), ``"seed"`` (§3.2.3) or ``"none"``;
    with ``fill_stream_mm`` ours may add discs at that shorter stream length
    (smaller, Eq. 3.1) where full discs cannot reach without overspray.
    ``sequencer``: ``"default"`` (ours) or ``"ga"`` (the seed's, §3.3.2).
    ``robot``: a model with ``frames``/``ik_axis`` (``robots.load_robot(
    "denso_vm6083")`` placed with ``with_base``), nozzle on the side of the
    plane where the robot base is; ``obstacles``: :class:`Box` es and (M,3)
    point arrays (world frame, metres).  Deterministic for a given ``seed``.
    ``joint_planner``: ``"none"`` (default) keeps the clearest via-point
    move for a transition that is not certified free (the clearance check
    then fails); ``"rrt"`` plans such moves with RRT-Connect
    (:mod:`planners.blasting.motion`, budget :data:`RRT_MAX_ITER` per move,
    :data:`RRT_BUDGET_ITER` per plan) and leaves out spots it cannot reach.
    Not the default: a spot blasted from a pose with millimetres of
    clearance traps the search, and every later spot is then tried from it
    (on Surface 2 with a blocking box: 63 of 66 spots unreached, ~80 s).
    """
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    surface = _coerce_surface(surface)
    noz = get_nozzle(nozzle)
    ds = check_stream_length(stream_length_mm)
    if sequencer not in ("default", "ga"):
        raise InvalidInputError(f"sequencer must be 'default' or 'ga', got {sequencer!r}")
    if joint_planner not in JOINT_PLANNERS:
        raise InvalidInputError(
            f"joint_planner must be one of {', '.join(JOINT_PLANNERS)}, got {joint_planner!r}"
        )
    if editing not in ("improved", "seed", "none"):
        raise InvalidInputError(f"editing must be 'improved', 'seed' or 'none', got {editing!r}")
    if disc_radius_m is not None:
        r = float(disc_radius_m)
        if not (np.isfinite(r) and r > 0):
            raise InvalidInputError(
                f"disc_radius_m must be a positive number of metres, got {disc_radius_m!r}"
            )
    else:
        r = noz.radius_mm(ds) / 1000.0
    small_r, fill_ds = None, None
    if fill_stream_mm is not None and editing == "improved":
        fill_ds = check_stream_length(fill_stream_mm)
        if fill_ds < ds:
            small_r = r * noz.radius_mm(fill_ds) / noz.radius_mm(ds)
    obst = Obstacles.coerce(obstacles)
    kp = tuple(float(k) for k in kp)
    if len(kp) != len(FOCI) or min(kp) <= 1.0:
        raise InvalidInputError(
            f"kp must be {len(FOCI)} numbers > 1 (seed: 1.05, 1.10, 1.10), got {kp}"
        )
    poly = surface.polygon
    cone = Cone.of(noz, r, ds / 1000.0)
    spacing = np.sqrt(3.0) * r

    # -- global nozzle tilt (§3.2.1) ----------------------------------------------------
    # The seed's surfaces put the wrist centre almost on the J1 axis
    # (shoulder singularity); tilting every spot's nozzle the same way (45–90°
    # to the surface is allowed) moves it off.  The footprint becomes the
    # exact conic section (footprint.py): an ellipse with semi-axes a (along
    # the tilt) and b, centred c beyond the point where the axis meets the
    # surface.  Coverage is planned in the plane compressed by b/a along the
    # tilt, where every footprint of that tilt is a disc (of radius b at the
    # nominal stream; all scale with the apex distance); area ratios, hence
    # coverage and overspray, are unchanged by that map.  Each spot is aimed
    # c before its footprint centre.
    side = 1.0
    beta, tilt_dir = 0.0, np.array([1.0, 0.0])
    q_start = np.deg2rad(np.asarray(start_pose_deg, dtype=float))
    if robot is not None:
        if q_start.shape != (6,):
            raise InvalidInputError(f"start_pose_deg must have 6 angles, got {len(start_pose_deg)}")
        side = 1.0 if (robot.base[:3, 3] - surface.origin) @ surface.normal >= 0 else -1.0
        if tilt_deg == "auto":
            beta, tilt_dir = _choose_tilt(
                robot, surface, side, ds / 1000.0 + nozzle_length_m, q_start
            )
        else:
            beta = float(np.deg2rad(float(tilt_deg)))
            if not (0.0 <= beta <= np.deg2rad(MAX_TILT_DEG)):
                raise InvalidInputError(
                    f"tilt_deg must be 'auto' or 0–{MAX_TILT_DEG:g}°, got {tilt_deg!r}"
                )
    elif tilt_deg not in ("auto", 0, 0.0):
        raise InvalidInputError("tilt_deg needs a robot (it is chosen for reachability)")
    L0 = float(cone.length(ds / 1000.0))
    a0, b0, c0 = (float(v) for v in exact_ellipse(L0, cone.tan_alpha, beta))
    squeeze = _squeeze_map(b0 / a0, tilt_dir)  # plane → footprint-is-a-disc frame
    unsqueeze = np.linalg.inv(squeeze)
    poly_fp = shapely.affinity.affine_transform(
        poly, [squeeze[0, 0], squeeze[0, 1], squeeze[1, 0], squeeze[1, 1], 0.0, 0.0]
    )
    rp = b0  # footprint radius in that frame at the nominal stream (= r untilted)
    rp_small = rp * small_r / r if small_r else None

    # -- coverage (§3.2), in the footprint frame --------------------------------------------
    _progress(progress, 0.0, "coverage")
    angle = _lattice_angle(poly_fp)
    lattice = _cov.hex_lattice(poly_fp, rp, angle=angle)
    lat_cls = _cov.classify(lattice, poly_fp, rp)
    if editing == "improved":
        ed = _cov.edit_improved(
            poly_fp, rp, lattice=lattice, small_r=rp_small, coverage_target=coverage_target,
            overspray_budget=overspray_budget, r_min=rp_small,
        )  # fmt: skip
        c_fp, radii, cls = ed.centers, ed.radii, ed.classes
    elif editing == "seed":
        c_fp, cls = _cov.edit_seed(lattice, poly_fp, rp)
        radii = np.full(len(c_fp), rp)
    else:
        keep = lat_cls != _cov.OUTSIDE
        c_fp, cls = lattice[keep], lat_cls[keep]
        radii = np.full(len(c_fp), rp)
    if len(c_fp) == 0:
        raise InfeasibleError(
            f"no blasting disc of radius {r * 1000:.1f} mm fits the surface (area {surface.area:.4f} m²); "
            "use a smaller nozzle or a shorter stream length"
        )
    # every footprint of the cone scales with the apex distance L: a disc of
    # radius ρ in the footprint frame is blasted from L = L0·ρ/rp
    scale = radii / rp
    stream = np.clip((L0 * scale - cone.apex_m) * 1000.0, fill_ds or ds, ds)
    m_plan = _cov.measure(poly_fp, c_fp, radii)
    c2 = c_fp @ unsqueeze.T
    N = len(c2)
    semi = np.stack([a0 * scale, b0 * scale], axis=1)
    major = np.repeat(tilt_dir[None], N, axis=0)
    aim2 = c2 - (c0 * scale)[:, None] * tilt_dir
    timings["coverage_s"] = time.perf_counter() - t0
    world = surface.to_world(c2)
    tilt = np.full(N, np.degrees(beta))
    params = {
        "nozzle": noz.name, "stream_length_mm": ds, "disc_radius_m": r, "fill_stream_mm": fill_ds,
        "small_radius_m": small_r, "editing": editing, "sequencer": sequencer, "seed": seed,
        "lattice_angle_rad": angle, "turn_threshold_deg": _seq.TURN_THRESHOLD_DEG,
        "tilt_deg": float(np.degrees(beta)), "tilt_direction_2d": tilt_dir.tolist(),
        "cone_tan_alpha": cone.tan_alpha, "cone_apex_m": cone.apex_m,
        "footprint_semi_axes_m": [a0, b0], "footprint_center_shift_m": c0,
        "joint_planner": joint_planner,
    }  # fmt: skip

    # -- robot: poses and collision status per spot ---------------------------------------
    keep = np.ones(N, dtype=bool)
    Qs = oks = None
    residual_mm = np.zeros(N)
    residual_deg = np.zeros(N)
    penalty = None
    if robot is not None:
        t1 = time.perf_counter()
        _progress(progress, 0.25, "inverse kinematics")
        n_in = -side * surface.normal
        axis0 = _tilted_axis(surface, side, beta, tilt_dir)
        axes = np.repeat(axis0[None], N, axis=0)  # blast axis into the surface
        standoff = (stream / 1000.0 + nozzle_length_m)[:, None]
        flange = surface.to_world(aim2) - axes * standoff
        Qs, oks = robot.ik_axis(flange, axes, q_start)
        ok_free = _collision_free(robot, Qs, oks, obst, nozzle_length_m, kp)
        # spots with no collision-free closed-form solution: tilt, then Eq. 3.11
        for i in np.nonzero(~ok_free.any(axis=1))[0]:
            tilts = np.arange(5.0, MAX_TILT_DEG - np.degrees(beta) + 1e-9, 5.0)
            cand = _arm.tilted_axes(axes[i], tilts) if len(tilts) else np.zeros((0, 3))
            # exact footprint of each candidate axis, aimed so it stays centred
            bc = np.arccos(np.clip(cand @ n_in, -1.0, 1.0))
            e3 = cand - np.cos(bc)[:, None] * n_in
            e2 = np.stack([e3 @ surface.x_axis, e3 @ surface.y_axis], axis=1)
            e2 /= np.maximum(np.linalg.norm(e2, axis=1, keepdims=True), 1e-12)
            ac, bcm, cc = exact_ellipse(L0 * scale[i], cone.tan_alpha, bc)
            aims = c2[i] - cc[:, None] * e2
            fl = surface.to_world(aims) - cand * standoff[i]
            Qt, okt = robot.ik_axis(fl, cand, q_start)
            freet = _collision_free(robot, Qt, okt, obst, nozzle_length_m, kp)
            good = np.nonzero(freet.any(axis=1))[0]
            if len(good):
                j = int(good[0])  # tilts ascend: least extra tilt first
                axes[i], flange[i], aim2[i] = cand[j], fl[j], aims[j]
                Qs[i], oks[i], ok_free[i] = Qt[j], okt[j], freet[j]
                tilt[i] = float(np.degrees(bc[j]))
                semi[i] = (ac[j], bcm[j])
                major[i] = e2[j]
                continue
            if oks[i].any() or okt.any():
                # reachable, but every configuration penetrates: rejected
                keep[i] = False
                continue
            # out of reach (or limits) for every axis tried: Eq. 3.11 optimum
            ap = _arm.approximate_ik(robot, flange[i], axes[i], q_start, seed=seed)
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
        oks = ok_free
        if not obst.empty:
            penalty = _penalty_matrix(
                robot, surface, c2, keep, r, obst, axes[0], standoff, nozzle_length_m, kp, q_start
            )
        timings["ik_collision_s"] = time.perf_counter() - t1

    idx = np.nonzero(keep)[0]
    if len(idx) == 0:
        raise InfeasibleError("no disc of the surface can be blasted without a collision")

    # -- sequencing (§3.3) -----------------------------------------------------------------
    t2 = time.perf_counter()
    _progress(progress, 0.5, "sequencing")
    P2 = c2[idx]
    pen = penalty[np.ix_(idx, idx)] if penalty is not None else None
    cpen = collision_penalty_m if pen is not None else 0.0

    def sequence(g: np.ndarray) -> np.ndarray:
        pg = pen[np.ix_(g, g)] if pen is not None else None
        if len(g) <= 2:
            return g
        if sequencer == "ga":
            return g[_seq.sequence_ga(P2[g], penalty=pg, c=cpen, seed=seed).order]
        return g[
            _seq.sequence_default(P2[g], row_pitch=1.5 * r, angles=(angle,), penalty=pg, c=cpen)
        ]

    family = np.full(N, -1)
    groups = _family_groups(oks[idx]) if Qs is not None else None
    if groups is None:
        sub = sequence(np.arange(len(idx)))
    else:
        sub = _join_tours([sequence(g) for g, _ in groups], P2)
        for g, f in groups:
            family[idx[g]] = f
    order = idx[sub]
    timings["sequencing_s"] = time.perf_counter() - t2

    # -- trajectory (§3.4.1.3, Eq. 3.12–3.13) and clearance (§3.4.2) ----------------------
    traj = None
    if robot is not None:
        t3 = time.perf_counter()
        _progress(progress, 0.75, "trajectory")
        traj = _trajectory(
            robot, order, flange, axes, Qs, oks, q_start, step_m, approach_waypoints, obst,
            nozzle_length_m, kp, joint_planner, seed, family,
        )  # fmt: skip
        traj.stats["family_groups"] = 1 if groups is None else len(groups)
        if len(traj.unreached):
            keep[traj.unreached] = False
            order = order[~np.isin(order, traj.unreached)]

    # -- results ------------------------------------------------------------------------------
    pos = {int(d): k for k, d in enumerate(idx)}
    sub = np.array([pos[int(d)] for d in order], dtype=int)
    st = _seq.stats(P2, sub, spacing, pen, cpen)
    per_spot = robot is not None and not np.allclose(tilt[keep], np.degrees(beta))
    vis = np.nonzero(keep)[0]
    if per_spot:
        # some spots carry their own tilt: measure every footprint as it is
        mats = ellipse_matrices(semi[vis, 0], semi[vis, 1], major[vis])
        m_done = _cov.measure(poly, c2[vis], semi[vis, 1], mats)
    else:
        m_done = m_plan if keep.all() else _cov.measure(poly_fp, c_fp[vis], radii[vis])
    reach = zero_overspray_reach(poly_fp, float(rp_small or rp))
    bound_val = None
    if m_done.coverage < COVERAGE_TARGET and editing == "improved":
        bound_val = pointwise_bound(poly_fp, float(rp_small or rp), OVERSPRAY_TARGET).coverage_max
    plan = BlastPlan(
        radius=r, centers=world, centers_2d=c2, radii=radii, classes=np.asarray(cls, dtype=np.int8),
        stream_mm=stream, tilt_deg=tilt, order=order, skipped=np.nonzero(~keep)[0],
        distance_m=st.distance_m, turns=st.turns, objective=st.objective,
        lower_bound_m=st.lower_bound_m, mst_m=st.mst_m, coverage=m_done.coverage,
        overspray=m_done.overspray, coverage_planned=m_plan.coverage,
        overspray_planned=m_plan.overspray, lattice_centers_2d=lattice, lattice_classes=lat_cls,
        spacing_m=spacing, params=params, timings_s=timings, aim_points=surface.to_world(aim2),
        aim_points_2d=aim2, semi_axes=semi, major_dir_2d=major, coverage_reach=reach,
        coverage_bound=bound_val, min_radius_m=float(rp_small or rp),
    )  # fmt: skip
    if traj is not None:
        q, seg, spot = traj.q, traj.segment, traj.spot
        clear = _arm.waypoint_clearance(robot, q, obst, nozzle_length_m, kp, FOCI)
        nominal = np.zeros(len(q) - 1)
        blast = seg[1:] == 2
        F = robot.frames(q)[:, -1, :3, 3]
        nominal[blast] = np.linalg.norm(np.diff(F, axis=0), axis=1)[blast] / traverse_speed_m_s
        v = np.deg2rad(speed_limit_deg_s)
        plan.joint_trajectory = q
        plan.times = _arm.time_stamps(q, nominal, v)
        plan.clearance = clear
        plan.segment = seg
        plan.waypoint_spot = spot
        plan.ik_residual_mm = residual_mm
        plan.ik_residual_deg = residual_deg
        plan.joint_limits = robot.joint_limits.copy()
        plan.speed_limit_rad_s = v
        plan.unreached = np.asarray(traj.unreached, dtype=int)
        plan.motion = traj.stats
        timings["trajectory_s"] = time.perf_counter() - t3
    timings["total_s"] = time.perf_counter() - t0
    _progress(progress, 1.0, "done")
    return plan


def _lattice_angle(poly) -> float:
    """Rows along the long side of the minimum rotated rectangle: fewer,
    longer rows mean fewer row changes (turns)."""
    rect = poly.minimum_rotated_rectangle
    xy = np.asarray(rect.exterior.coords)[:4]
    e = np.diff(np.vstack([xy, xy[:1]]), axis=0)
    k = int(np.argmax(np.linalg.norm(e, axis=1)))
    return float(np.arctan2(e[k, 1], e[k, 0]) % np.pi)


def _tilted_axis(surface: Surface, side: float, beta: float, direction: np.ndarray) -> np.ndarray:
    """Blast axis (into the surface) tilted by β toward the in-plane
    ``direction`` (plane coordinates)."""
    e = direction[0] * surface.x_axis + direction[1] * surface.y_axis
    return np.cos(beta) * (-side * surface.normal) + np.sin(beta) * e


def _squeeze_map(ratio: float, direction: np.ndarray) -> np.ndarray:
    """2×2 map compressing the plane by ``ratio`` (= b/a of the tilted
    footprint, :func:`planners.blasting.footprint.squeeze_ratio`) along
    ``direction``: every footprint of that tilt becomes a disc."""
    d = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    return np.eye(2) - (1.0 - float(ratio)) * np.outer(d, d)


def _choose_tilt(
    robot, surface: Surface, side: float, standoff: float, q_start: np.ndarray
) -> tuple[float, np.ndarray]:
    """Global tilt (β, in-plane direction) that keeps every sampled surface
    point reachable in one arm family (shoulder × elbow branch) and the wrist
    centre as far from the J1 axis as possible (up to 0.15 m: beyond that a
    0.1 m/s nozzle needs < 40°/s on J1), smallest β first.
    Candidates: β ∈ {0, 10, 20, 30, 40}°, 12 directions."""
    poly = surface.polygon
    minx, miny, maxx, maxy = poly.bounds
    h = max(maxx - minx, maxy - miny) / 12.0
    gx, gy = np.meshgrid(np.arange(minx, maxx + h, h), np.arange(miny, maxy + h, h))
    g = np.stack([gx.ravel(), gy.ravel()], axis=1)
    g = g[shapely.contains_xy(poly, g[:, 0], g[:, 1])]
    ext = np.asarray(
        poly.exterior.coords if poly.geom_type == "Polygon" else poly.convex_hull.exterior.coords
    )
    pts = surface.to_world(np.vstack([g, ext]))
    Binv = np.linalg.inv(robot.base)
    best = None
    for beta_deg in (0.0, 10.0, 20.0, 30.0, 40.0):
        dirs = [0.0] if beta_deg == 0 else np.linspace(0, 2 * np.pi, 12, endpoint=False)
        for phi in dirs:
            d2 = np.array([np.cos(phi), np.sin(phi)])
            a = _tilted_axis(surface, side, np.deg2rad(beta_deg), d2)
            fl = pts - a * standoff
            _, ok = robot.ik_axis(fl, np.repeat(a[None], len(fl), axis=0), q_start)
            # one arm family (shoulder × elbow; either wrist) for all points
            # means no reconfiguration is needed while blasting
            reach = float((ok[:, :4] | ok[:, 4:]).mean(axis=0).max())
            wc = (fl - a * robot.d[5]) @ Binv[:3, :3].T + Binv[:3, 3]
            rho = min(float(np.hypot(wc[:, 0], wc[:, 1]).min()), 0.15)
            key = (round(reach, 3), round(rho, 3), -beta_deg)
            if best is None or key > best[0]:
                best = (key, np.deg2rad(beta_deg), d2)
    return best[1], best[2]


def _collision_free(
    robot, Q: np.ndarray, ok: np.ndarray, obst: Obstacles, nozzle_m: float, kp
) -> np.ndarray:
    """ok & positive ellipsoid clearance for every (spot, branch)."""
    if obst.empty or not ok.any():
        return ok.copy()
    flat = Q.reshape(-1, 6)[ok.reshape(-1)]
    clear = _arm.waypoint_clearance(
        robot, flat, obst, nozzle_m, kp, FOCI, sign_only=True, margin=SAFETY_M
    )
    out = ok.copy()
    out[ok] = clear > SAFETY_M
    return out


def _penalty_matrix(
    robot, surface, c2, keep, r, obst, axis, standoff, nozzle_m, kp, q_start
) -> np.ndarray | None:
    """Eq. 3.15 flags: a move i→j is flagged when it passes within r of a
    surface point whose normal pose has no collision-free branch (a grid of
    pitch r over the surface)."""
    import shapely
    from scipy.spatial import cKDTree

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
        pen[i] = (d.reshape(n, len(samples)) < r).any(axis=1)
    np.fill_diagonal(pen, 0.0)
    return pen


def _family_mask(f: np.ndarray) -> np.ndarray:
    """(K,8) branches of arm families ``f`` (K,): IK branch b = 4·wrist + f
    (robots.denso_vm6083.ik_all), so a family is a position branch with
    either wrist."""
    return (np.arange(8)[None, :] % 4) == np.asarray(f)[:, None]


def _family_groups(free: np.ndarray) -> list[tuple[np.ndarray, int]] | None:
    """Spots grouped by arm family when obstacles split them: None when one
    family (position branch, either wrist) reaches every spot collision-free;
    else a greedy set cover — the family reaching most of the spots left
    takes them all — as (spot indices, family), largest first.  Each group
    is then sequenced and blasted in its family, so the arm reconfigures
    (typically a 180° J1 swing) once per group instead of wherever the
    sequence happens to cross between spots only one family reaches."""
    fam = free[:, :4] | free[:, 4:]
    if fam.all(axis=0).any() or not fam.any(axis=1).all():
        return None
    left = np.ones(len(fam), dtype=bool)
    out = []
    while left.any():
        f = int(np.argmax((fam & left[:, None]).sum(axis=0)))
        g = np.nonzero(left & fam[:, f])[0]
        out.append((g, f))
        left[g] = False
    return out


def _join_tours(tours: list[np.ndarray], pts: np.ndarray) -> np.ndarray:
    """Concatenate tours in the given order, each after the first run in the
    direction that starts nearer to where the previous one ended."""
    out = [tours[0]]
    for t in tours[1:]:
        end = pts[out[-1][-1]]
        if np.linalg.norm(pts[t[-1]] - end) < np.linalg.norm(pts[t[0]] - end):
            t = t[::-1]
        out.append(t)
    return np.concatenate(out)


@dataclass
class _Traj:
    q: np.ndarray
    segment: np.ndarray
    spot: np.ndarray
    unreached: np.ndarray
    stats: dict[str, float]


def _trajectory(
    robot, order, flange, axes, Qs, oks, q_start, step_m, approach_waypoints, obst, nozzle_m, kp,
    joint_planner, seed, family=None,
) -> _Traj:  # fmt: skip
    """Way-points: start pose, ``approach_waypoints`` joint-space points to the
    first spot, then straight moves between spots every ``step_m``.

    Branches are chosen by DP over all way-points (least joint change); a
    jump larger than 15° between neighbours becomes a joint-space
    reconfiguration.  Way-points whose ellipsoids penetrate an obstacle are
    rejected (their state is removed and the DP re-run, up to 4 times).
    Every move between way-points is then certified free
    (:func:`planners.blasting.motion.edge_free`, the ellipsoid clearance
    against a bound on how far the arm moves).  A move that is not: the
    approach and reconfigurations try, shortest first, a direct move,
    "rotate folded, then extend" and "extend, then rotate" via-points, each
    optionally through poses backed off 0.1/0.2 m along the nozzle axis at
    either end, and (reconfigurations) out to the start pose and back; with
    ``joint_planner="rrt"`` any move still blocked is planned by
    RRT-Connect in the joint space (shortcut, densified to 2° steps, nozzle
    off), and a spot that no certified path reaches from the previous one is
    left out (``unreached``).  With ``joint_planner="none"`` (the default)
    an uncertified move keeps the shortest candidate whose way-points are
    free, else the clearest one even when it penetrates, so the clearance
    check fails."""
    rng = np.random.default_rng(seed)
    w = _motion.displacement_weights(robot, nozzle_m, kp, FOCI)
    limits = robot.joint_limits

    def clear_val(qq: np.ndarray) -> np.ndarray:
        qq = np.atleast_2d(qq)
        if obst.empty:
            return np.full(len(qq), np.inf)
        c = _arm.waypoint_clearance(
            robot, qq, obst, nozzle_m, kp, FOCI, horizon=CLEAR_HORIZON_M, rel_tol=CLEAR_REL_TOL
        )
        return c - SAFETY_M  # > 0: free with the safety margin

    def clear_sign(qq: np.ndarray) -> np.ndarray:
        c = _arm.waypoint_clearance(
            robot, qq, obst, nozzle_m, kp, FOCI, sign_only=True, margin=SAFETY_M
        )
        return c - SAFETY_M

    fam = np.full(len(Qs), -1) if family is None else np.asarray(family)
    # Cartesian way-points between consecutive spots; each carries the arm
    # family its spots were grouped in (-1: any)
    P, A, spot = [flange[order[0]]], [axes[order[0]]], [order[0]]
    wfam = [fam[order[0]]]
    for a_i, b_i in itertools.pairwise(order):
        L = float(np.linalg.norm(flange[b_i] - flange[a_i]))
        n = max(1, int(np.ceil(L / step_m)))
        t = np.arange(1, n + 1)[:, None] / n
        P.append(flange[a_i] + t * (flange[b_i] - flange[a_i]))
        ax = axes[a_i] + t * (axes[b_i] - axes[a_i])
        A.append(ax / np.linalg.norm(ax, axis=1, keepdims=True))
        spot.append(np.r_[np.full(n - 1, -1), b_i])
        between = fam[a_i] if fam[a_i] == fam[b_i] else -1
        wfam.append(np.r_[np.full(n - 1, between), fam[b_i]])
    P = np.vstack([np.atleast_2d(p) for p in P])
    A = np.vstack([np.atleast_2d(a) for a in A])
    spot = np.concatenate([np.atleast_1d(s) for s in spot]).astype(int)
    wfam = np.concatenate([np.atleast_1d(f) for f in wfam]).astype(int)
    Q, ok = robot.ik_axis(P, A, q_start)
    at = spot >= 0
    # spots use their own solution set (tilt / approximate IK included)
    Q[at] = Qs[spot[at]]
    ok[at] = oks[spot[at]]
    grouped = wfam >= 0
    if grouped.any():
        ok[grouped] &= _family_mask(wfam[grouped])
    for _ in range(4):
        usable = ok.any(axis=1)
        usable[at] = True
        Qu, oku, spu = Q[usable], ok[usable], spot[usable]
        br = _arm.choose_branches(Qu, oku, q_start)
        qb = Qu[np.arange(len(Qu)), br]
        bad = (clear_sign(qb) <= 0) if not obst.empty else np.zeros(len(qb), dtype=bool)
        bad &= spu < 0  # spots were checked already
        if not bad.any():
            break
        rows = np.nonzero(usable)[0][bad]
        ok[rows, br[bad]] = False
    spot, Pu, Au = spu, P[usable], A[usable]
    n_wp = len(qb)

    def retracts(k: int) -> list[np.ndarray]:
        """Poses of way-point ``k`` with the flange backed off along the
        nozzle axis (same arm family, nearest branch), clear of obstacles:
        moving in or out along the axis keeps the wrist out of the surface."""
        if k < 0 or obst.empty:
            return []
        pr = Pu[k][None] - RETRACT_M[:, None] * Au[k][None]
        Qr, okr = robot.ik_axis(pr, np.repeat(Au[k][None], len(pr), axis=0), qb[k])
        out = []
        for j in range(len(pr)):
            if not okr[j].any():
                continue
            d = np.where(okr[j], np.abs(Qr[j] - qb[k]).max(axis=1), np.inf)
            out.append(Qr[j, int(np.argmin(d))])
        if not out:
            return []
        R = np.stack(out)
        return list(R[clear_val(R) > 0])

    c_wp = clear_val(qb)
    # certify the short blasting moves in one batch
    step_ok = np.zeros(n_wp, dtype=bool)
    if n_wp > 1:
        short = np.abs(np.diff(qb, axis=0)).max(axis=1) <= JUMP_RAD
        k = np.nonzero(short)[0]
        if obst.empty:
            step_ok[k + 1] = True
        elif len(k):
            step_ok[k + 1] = _motion.edge_free(
                qb[k], qb[k + 1], clear_val, w, ca=c_wp[k], cb=c_wp[k + 1]
            )
    out = [q_start[None]]
    seg = [np.array([0])]
    sp = [np.array([-1])]
    cur, c_cur, cur_k = q_start, clear_val(q_start)[0], -1
    reached_first = False
    unreached: list[int] = []
    stats = {
        "rrt_calls": 0, "rrt_failures": 0, "rrt_nodes": 0, "rrt_iterations": 0,
        "rrt_out_of_budget": 0, "via_moves": 0,
    }  # fmt: skip
    skip_to_spot = False
    for k in range(n_wp):
        if spot[k] < 0 and (c_wp[k] <= 0 or not reached_first or skip_to_spot):
            # a penetrating way-point between spots, or one on the way from a
            # spot that was left out: move past it
            continue
        skip_to_spot = False
        if reached_first and cur_k == k - 1 and step_ok[k]:
            out.append(qb[k][None])
            seg.append(np.array([2]))
            sp.append(np.array([spot[k]]))
            cur, c_cur, cur_k = qb[k], c_wp[k], k
            continue
        dq = float(np.abs(qb[k] - cur).max())
        if reached_first and dq <= JUMP_RAD and (obst.empty or _motion.edge_free(
                cur[None], qb[k][None], clear_val, w, ca=[c_cur], cb=[c_wp[k]])[0]):  # fmt: skip
            out.append(qb[k][None])
            seg.append(np.array([2]))
            sp.append(np.array([spot[k]]))
            cur, c_cur, cur_k = qb[k], c_wp[k], k
            continue
        m = approach_waypoints if not reached_first else max(int(np.ceil(dq / STEP_RAD)), 2)
        path = _transition(
            cur, qb[k], m, clear_val, clear_sign, w, limits, rng, joint_planner, obst.empty, stats,
            c_cur, c_wp[k], retracts(cur_k), retracts(k), q_start if reached_first else None,
            not reached_first,
        )  # fmt: skip
        if path is None:
            if spot[k] >= 0:
                unreached.append(int(spot[k]))
                skip_to_spot = True
            continue
        out.append(path)
        seg.append(np.full(len(path), 3 if reached_first else 1))
        sp.append(np.r_[np.full(len(path) - 1, -1), spot[k]])
        cur, c_cur, cur_k = qb[k], c_wp[k], k
        if spot[k] >= 0:
            reached_first = True
    if not reached_first:
        raise InfeasibleError(
            "no spot can be reached from the start pose on a collision-free path "
            f"({stats['rrt_calls']} joint-space searches failed)"
        )
    return _Traj(
        np.vstack(out), np.concatenate(seg), np.concatenate(sp),
        np.asarray(sorted(set(unreached)), dtype=int), stats,
    )  # fmt: skip


def _resample(path: np.ndarray, m: int) -> np.ndarray:
    """Exactly ``m`` way-points along the polyline ``path`` (first vertex
    excluded, last included) that contain every corner, so the way-points
    trace the certified polyline itself: each of the K segments gets
    ≥ 1 evenly spaced points, the rest shared by largest remainder in
    proportion to its largest joint move.  With K > m the corners alone
    are returned (K points)."""
    path = np.asarray(path, dtype=float)
    K = len(path) - 1
    if K <= 0:
        return np.repeat(path[-1:], m, axis=0)
    if m <= K:
        return path[1:].copy()
    seglen = np.abs(np.diff(path, axis=0)).max(axis=1)
    share = (m - K) * seglen / seglen.sum() if seglen.sum() > 0 else np.full(K, (m - K) / K)
    n = 1 + np.floor(share).astype(int)
    rest = m - int(n.sum())
    if rest > 0:
        n[np.argsort(-(share - np.floor(share)), kind="stable")[:rest]] += 1
    out = [_arm.joint_path(a, b, int(k)) for a, b, k in zip(path[:-1], path[1:], n, strict=True)]
    return np.vstack(out)


def _via_polylines(
    q0: np.ndarray,
    q1: np.ndarray,
    r0: list[np.ndarray],
    r1: list[np.ndarray],
    home: np.ndarray | None = None,
) -> list[np.ndarray]:
    """Candidate corner sequences q0 → … → q1, shortest first: the direct
    move, "turn folded, then extend" and "extend, then turn", each optionally
    entered and left through a pose backed off along the nozzle axis
    (``r0`` at q0, ``r1`` at q1); and, with ``home``, out through the
    retract poses to the home pose and back in (the way a crew clears a
    blocked arm)."""

    def mids(a: np.ndarray, b: np.ndarray) -> list[list[np.ndarray]]:
        return [[], [np.r_[b[0], a[1:3], b[3:]]], [np.r_[a[0], b[1:3], a[3:5], b[5]]]]

    cands = []
    for a in [None, *r0]:
        for b in [None, *r1]:
            ea = q0 if a is None else a
            eb = q1 if b is None else b
            for mid in mids(ea, eb):
                corners = [q0, *([] if a is None else [a]), *mid, *([] if b is None else [b]), q1]
                cands.append(np.stack(corners))
            if home is not None:
                pa, pb = [] if a is None else [a], [] if b is None else [b]
                cands.append(np.stack([q0, *pa, home, *pb, q1]))
    length = [float(np.abs(np.diff(c, axis=0)).max(axis=1).sum()) for c in cands]
    return [cands[i] for i in np.argsort(length, kind="stable")]


def _transition(
    q0, q1, m, clear_val, clear_sign, w, limits, rng, joint_planner, free_space, stats, c0, c1,
    r0=(), r1=(), home=None, exact_m=True,
) -> np.ndarray | None:  # fmt: skip
    """Joint-space move q0 → q1 as way-points (q0 excluded): the shortest
    certified-free candidate of :func:`_via_polylines` (``r0``/``r1``:
    retract poses at the two ends), else (``joint_planner="rrt"``)
    RRT-Connect + shortcut; None when nothing certified is found.  With
    ``joint_planner="none"`` the shortest candidate whose way-points are
    free is returned, else the clearest.  ``exact_m``: exactly ``m``
    way-points (the approach, §4.2.4); otherwise at least ``m`` and no joint
    step above :data:`STEP_RAD` on a candidate's own polyline."""
    direct = _arm.joint_path(q0, q1, m)
    if free_space:
        return direct
    polys = _via_polylines(q0, q1, list(r0), list(r1), home)

    def n_points(p: np.ndarray) -> int:
        if exact_m:
            return m
        steps = np.ceil(np.abs(np.diff(p, axis=0)).max(axis=1) / STEP_RAD)
        return max(m, int(np.maximum(steps, 1).sum()))

    # one batched sign-only look at every candidate's way-points rules most
    # of them out before the (more expensive) certification
    paths = [direct if len(p) == 2 else _resample(p, n_points(p)) for p in polys]
    sign = clear_sign(np.vstack(paths))
    cut = np.cumsum([len(p) for p in paths])[:-1]
    worst = [float(c.min()) for c in np.split(sign, cut)]  # exact where ≤ 0
    hit = [c <= 0 for c in worst]
    for poly, path, h in zip(polys, paths, hit, strict=True):
        if h:
            continue
        cs = np.r_[c0, clear_val(poly[1:-1]) if len(poly) > 2 else [], c1]
        if cs.min() > 0 and _motion.edge_free(poly[:-1], poly[1:], clear_val, w,
                                              ca=cs[:-1], cb=cs[1:]).all():  # fmt: skip
            if len(poly) > 2:
                stats["via_moves"] += 1
            return path
    if joint_planner == "none":
        # nothing certified between way-points: the shortest candidate whose
        # way-points are free, else the clearest (the clearance check fails)
        if not all(hit):
            return paths[hit.index(False)]
        return paths[int(np.argmax(worst))]
    budget = RRT_BUDGET_ITER - stats["rrt_iterations"]
    if budget <= 0:
        stats["rrt_out_of_budget"] += 1
        return None
    stats["rrt_calls"] += 1
    res = _motion.rrt_connect(
        q0, q1, clear_val, limits, w, rng=rng, max_iter=min(RRT_MAX_ITER, budget)
    )
    stats["rrt_nodes"] += res.nodes
    stats["rrt_iterations"] += res.iterations
    if res.path is None:
        stats["rrt_failures"] += 1
        return None
    path = _motion.shortcut(res.path, clear_val, w, rng=rng)
    # as many way-points as the move needs at ≤ 2° per step, at least m
    # (the approach: exactly m = 100 unless the path has more corners)
    n_dense = len(_motion.densify(path, STEP_RAD))
    return _resample(path, m) if n_dense <= m else _motion.densify(path, STEP_RAD)
