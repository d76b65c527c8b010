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
from planners.blasting import sequencing as _seq
from planners.blasting.collision import Box, Obstacles, Spheroids, clearance
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
                   f"coverage {self.coverage:.2%} (min {coverage_min:.0%})"),
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
    """
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    surface = _coerce_surface(surface)
    noz = get_nozzle(nozzle)
    ds = check_stream_length(stream_length_mm)
    if sequencer not in ("default", "ga"):
        raise InvalidInputError(f"sequencer must be 'default' or 'ga', got {sequencer!r}")
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
    spacing = np.sqrt(3.0) * r

    # -- global nozzle tilt (§3.2.1) ----------------------------------------------------
    # The seed's surfaces put the wrist centre almost on the J1 axis (shoulder
    # singularity); tilting every spot's nozzle the same way (45–90° to the
    # surface is allowed) moves it off.  The footprint becomes an ellipse
    # stretched 1/cos β along the tilt: coverage is computed in the plane
    # compressed by cos β along that direction, where it is a disc again
    # (area ratios, hence coverage and overspray, are unchanged by the map).
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
    squeeze = _squeeze_map(beta, tilt_dir)  # plane → footprint-is-a-disc frame
    unsqueeze = np.linalg.inv(squeeze)
    poly_fp = shapely.affinity.affine_transform(
        poly, [squeeze[0, 0], squeeze[0, 1], squeeze[1, 0], squeeze[1, 1], 0.0, 0.0]
    )

    # -- coverage (§3.2), in the footprint frame --------------------------------------------
    _progress(progress, 0.0, "coverage")
    angle = _lattice_angle(poly_fp)
    lattice = _cov.hex_lattice(poly_fp, r, angle=angle)
    lat_cls = _cov.classify(lattice, poly_fp, r)
    if editing == "improved":
        ed = _cov.edit_improved(
            poly_fp, r, lattice=lattice, small_r=small_r, coverage_target=coverage_target,
            overspray_budget=overspray_budget,
        )  # fmt: skip
        c_fp, radii, cls, small = ed.centers, ed.radii, ed.classes, ed.small
    elif editing == "seed":
        c_fp, cls = _cov.edit_seed(lattice, poly_fp, r)
        radii, small = np.full(len(c_fp), r), np.zeros(len(c_fp), dtype=bool)
    else:
        keep = lat_cls != _cov.OUTSIDE
        c_fp, cls = lattice[keep], lat_cls[keep]
        radii, small = np.full(len(c_fp), r), np.zeros(len(c_fp), dtype=bool)
    if len(c_fp) == 0:
        raise InfeasibleError(
            f"no blasting disc of radius {r * 1000:.1f} mm fits the surface (area {surface.area:.4f} m²); "
            "use a smaller nozzle or a shorter stream length"
        )
    stream = np.where(small, fill_ds or ds, ds)
    m_plan = _cov.measure(poly_fp, c_fp, radii)
    c2 = c_fp @ unsqueeze.T
    timings["coverage_s"] = time.perf_counter() - t0
    N = len(c2)
    world = surface.to_world(c2)
    tilt = np.full(N, np.degrees(beta))
    params = {
        "nozzle": noz.name, "stream_length_mm": ds, "disc_radius_m": r, "fill_stream_mm": fill_ds,
        "small_radius_m": small_r, "editing": editing, "sequencer": sequencer, "seed": seed,
        "lattice_angle_rad": angle, "turn_threshold_deg": _seq.TURN_THRESHOLD_DEG,
        "tilt_deg": float(np.degrees(beta)), "tilt_direction_2d": tilt_dir.tolist(),
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
        axis0 = _tilted_axis(surface, side, beta, tilt_dir)
        axes = np.repeat(axis0[None], N, axis=0)  # blast axis into the surface
        standoff = (stream / 1000.0 + nozzle_length_m)[:, None]
        flange = world - axes * standoff
        Qs, oks = robot.ik_axis(flange, axes, q_start)
        ok_free = _collision_free(robot, Qs, oks, obst, nozzle_length_m, kp)
        # spots with no collision-free closed-form solution: tilt, then Eq. 3.11
        for i in np.nonzero(~ok_free.any(axis=1))[0]:
            tilts = np.arange(5.0, MAX_TILT_DEG - np.degrees(beta) + 1e-9, 5.0)
            cand = _arm.tilted_axes(axes[i], tilts) if len(tilts) else np.zeros((0, 3))
            fl = world[i] - cand * standoff[i]
            Qt, okt = robot.ik_axis(fl, cand, q_start)
            freet = _collision_free(robot, Qt, okt, obst, nozzle_length_m, kp)
            good = np.nonzero(freet.any(axis=1))[0]
            if len(good):
                j = int(good[0])  # tilts ascend: least extra tilt first
                axes[i], flange[i] = cand[j], fl[j]
                Qs[i], oks[i], ok_free[i] = Qt[j], okt[j], freet[j]
                n_in = -side * surface.normal
                tilt[i] = float(np.degrees(np.arccos(np.clip(cand[j] @ n_in, -1.0, 1.0))))
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
    if sequencer == "ga":
        sub = _seq.sequence_ga(P2, penalty=pen, c=cpen, seed=seed).order
    else:
        sub = _seq.sequence_default(P2, row_pitch=1.5 * r, angles=(angle,), penalty=pen, c=cpen)
    order = idx[sub]
    st = _seq.stats(P2, sub, spacing, pen, cpen)
    timings["sequencing_s"] = time.perf_counter() - t2

    m_done = m_plan if keep.all() else _cov.measure(poly_fp, c_fp[idx], radii[idx])
    plan = BlastPlan(
        radius=r, centers=world, centers_2d=c2, radii=radii, classes=np.asarray(cls, dtype=np.int8),
        stream_mm=stream, tilt_deg=tilt, order=order, skipped=np.nonzero(~keep)[0],
        distance_m=st.distance_m, turns=st.turns, objective=st.objective,
        lower_bound_m=st.lower_bound_m, mst_m=st.mst_m, coverage=m_done.coverage,
        overspray=m_done.overspray, coverage_planned=m_plan.coverage,
        overspray_planned=m_plan.overspray, lattice_centers_2d=lattice, lattice_classes=lat_cls,
        spacing_m=spacing, params=params, timings_s=timings,
    )  # fmt: skip

    # -- trajectory (§3.4.1.3, Eq. 3.12–3.13) and clearance (§3.4.2) ----------------------
    if robot is not None:
        t3 = time.perf_counter()
        _progress(progress, 0.75, "trajectory")

        def clear_fn(qq: np.ndarray) -> np.ndarray:
            c = _arm.waypoint_clearance(
                robot, qq, obst, nozzle_length_m, kp, FOCI, sign_only=True, margin=SAFETY_M
            )
            return c - SAFETY_M  # > 0: free with the safety margin

        q, seg, spot = _trajectory(
            robot, order, flange, axes, Qs, oks, q_start, step_m, approach_waypoints, clear_fn
        )
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


def _squeeze_map(beta: float, direction: np.ndarray) -> np.ndarray:
    """2×2 map compressing the plane by cos β along ``direction``: a tilted
    footprint (ellipse, semi-axes r/cos β along the tilt and r across; the
    first-order conic section of a narrow cone) becomes a disc of radius r."""
    d = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    return np.eye(2) - (1.0 - np.cos(beta)) * np.outer(d, d)


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


def _trajectory(
    robot, order, flange, axes, Qs, oks, q_start, step_m, approach_waypoints, clear_fn
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Way-points: start pose, ``approach_waypoints`` joint-space points to the
    first spot, then straight moves between spots every ``step_m``.

    Branches are chosen by DP over all way-points (least joint change); a
    jump larger than 15° between neighbours becomes a joint-space
    reconfiguration.  Way-points whose ellipsoids penetrate an obstacle are
    rejected (their state is removed and the DP re-run, up to 4 times), and
    the approach and reconfigurations try a direct move, then "rotate
    folded, then extend" and "extend, then rotate" via-points, keeping the
    first one that is clear (else the clearest; the clearance check then
    fails and the plan cannot be approved)."""
    # Cartesian way-points between consecutive spots
    P, A, spot = [flange[order[0]]], [axes[order[0]]], [order[0]]
    for a_i, b_i in itertools.pairwise(order):
        L = float(np.linalg.norm(flange[b_i] - flange[a_i]))
        n = max(1, int(np.ceil(L / step_m)))
        t = np.arange(1, n + 1)[:, None] / n
        P.append(flange[a_i] + t * (flange[b_i] - flange[a_i]))
        ax = axes[a_i] + t * (axes[b_i] - axes[a_i])
        A.append(ax / np.linalg.norm(ax, axis=1, keepdims=True))
        spot.append(np.r_[np.full(n - 1, -1), b_i])
    P = np.vstack([np.atleast_2d(p) for p in P])
    A = np.vstack([np.atleast_2d(a) for a in A])
    spot = np.concatenate([np.atleast_1d(s) for s in spot]).astype(int)
    Q, ok = robot.ik_axis(P, A, q_start)
    at = spot >= 0
    # spots use their own solution set (tilt / approximate IK included)
    Q[at] = Qs[spot[at]]
    ok[at] = oks[spot[at]]
    for _ in range(4):
        usable = ok.any(axis=1)
        usable[at] = True
        Qu, oku, spu = Q[usable], ok[usable], spot[usable]
        br = _arm.choose_branches(Qu, oku, q_start)
        qb = Qu[np.arange(len(Qu)), br]
        bad = clear_fn(qb) <= 0
        bad &= spu < 0  # spots were checked already
        if not bad.any():
            break
        rows = np.nonzero(usable)[0][bad]
        ok[rows, br[bad]] = False
    Q, ok, spot = Qu, oku, spu
    approach = _approach(q_start, qb[0], approach_waypoints, clear_fn)
    out = [q_start[None], approach]
    seg = [np.array([0]), np.full(len(approach), 1)]
    sp = [np.array([-1]), np.r_[np.full(len(approach) - 1, -1), spot[0]]]
    for k in range(1, len(qb)):
        dq = np.abs(qb[k] - qb[k - 1]).max()
        if dq > JUMP_RAD:
            n = max(int(np.ceil(dq / np.deg2rad(2.0))), 2)
            out.append(_approach(qb[k - 1], qb[k], n, clear_fn))
            seg.append(np.full(n, 3))
            sp.append(np.r_[np.full(n - 1, -1), spot[k]])
        else:
            out.append(qb[k][None])
            seg.append(np.array([2]))
            sp.append(np.array([spot[k]]))
    return np.vstack(out), np.concatenate(seg), np.concatenate(sp)


def _approach(q0: np.ndarray, q1: np.ndarray, m: int, clear_fn) -> np.ndarray:
    """m joint-space way-points from q0 to q1 (seed §4.2.4): direct, or via a
    pose that first turns J1/J4/J5 with the arm folded as in q0 (then
    extends), or first extends (then turns); the first clear one wins, else
    the one with the largest minimum clearance."""
    vias = [None, np.r_[q1[0], q0[1:3], q1[3:]], np.r_[q0[0], q1[1:3], q0[3:5], q1[5]]]
    best, best_c = None, -np.inf
    for via in vias:
        if via is None:
            path = _arm.joint_path(q0, q1, m)
        else:
            d1 = np.abs(via - q0).max()
            d2 = np.abs(q1 - via).max()
            m1 = int(np.clip(round(m * d1 / max(d1 + d2, 1e-12)), 1, m - 1))
            path = np.vstack([_arm.joint_path(q0, via, m1), _arm.joint_path(via, q1, m - m1)])
        c = float(np.min(clear_fn(path)))
        if c > 0:
            return path
        if c > best_c:
            best, best_c = path, c
    return best
