"""ARA switching control: S = S_pa ∧ S_am ∧ S_hc (seed Eq. 3.1) → mode.

:func:`decide_mode` is the stable entry point of DESIGN §5.  Pipeline (seed
§3.1, §5.2.1): camera → base frame (Eq. 3.3, applied to every point, which
moves the centroid exactly as transforming the centroid does), pass-through,
voxel down-sampling, sequential RANSAC for every plane in view (S_pa,
Eq. 3.2), NCBE + Alg. 2 on each plane (S_am), height check (S_hc, Eq. 3.4).

Mode: "mobile" when some plane has S_pa ∧ S_am ∧ S_hc (the robot can keep
driving); otherwise "inchworm" when some plane has enough area and its
foothold lies within the arm's reach (the seed's S = false case); otherwise
"none" — no safe surface, the robot must not move.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from planners.errors import (
    EmptyInputError,
    InvalidInputError,
    NonRigidTransformError,
    NoPlaneError,
)
from planners.pointcloud import detect_planes, drop_nonfinite, passthrough, voxel_downsample
from planners.pointcloud._validate import as_points
from planners.switching.availability import (
    AreaResult,
    PlaneFrame,
    RectangleCandidate,
    area_check,
    height_check,
)

Progress = Callable[[float, str], None]


@dataclass(frozen=True)
class SwitchingParams:
    """Tunables of :func:`decide_mode` (seed values marked, the rest chosen)."""

    # Pass-through box in the base frame (metres): where target surfaces may be.
    x_range_m: tuple[float, float] | None = (-0.05, 0.8)  # reach zone + margin
    y_range_m: tuple[float, float] | None = (-0.8, 0.8)
    z_range_m: tuple[float, float] | None = (-0.6, 1.0)
    voxel_m: float = 0.01
    ransac_threshold_m: float = 0.01
    ransac_iterations: int = 500
    min_plane_points: int = 150
    max_planes: int = 8
    cluster_radius_m: float | None = 0.03  # split coplanar but separate slabs
    sliding_factor_m: float = 0.01  # NCBE αs (1 cm: see docs/switching.md)
    n_closest: int = 5  # seed Alg. 2: n = 5
    m_neighbours: int = 3  # seed Alg. 2: m = 3
    distance_tolerance: float = 0.02  # seed Alg. 2: t = 0.02
    alpha_m: float = 0.03  # alpha shape for the exact cross-check (≈ 3 voxels)
    # The exact test accepts a rectangle inside the hull grown by this much:
    # Alg. 2 anchors two corners *on* boundary points, which sampling noise
    # puts up to about a voxel outside the hull.
    exact_tolerance_m: float = 0.01
    height_tolerance_m: float = 0.005  # Eq. 3.4 "equal" within this
    parallel_tolerance_deg: float = 5.0
    # Inch-worm reach: foothold centre within reach_m of the base origin
    # (ARA: the straight arm puts the feet 0.5 m apart), and, when given,
    # reach_check(pose) → bool (e.g. an IK test) for the pose or its
    # 180°-about-normal twin (the foot rectangle is symmetric).
    reach_m: float | None = 0.5
    reach_check: Callable[[np.ndarray], bool] | None = None
    drop_nonfinite: bool = False  # False: NaN rows are an error
    on_no_plane: str = "none"  # "none": mode none; "raise": NoPlaneError
    seed: int = 0


@dataclass
class PlaneCandidate:
    """One plane in view with its three availabilities (base frame)."""

    index: int
    normal: np.ndarray  # unit, facing the camera
    centroid: np.ndarray  # base frame (Eq. 3.3)
    centroid_camera: np.ndarray
    n_points: int
    rms_m: float
    points_index: np.ndarray  # rows of SwitchingDecision.points
    frame: PlaneFrame
    area: AreaResult
    area_m2: float
    height_available: bool
    height_error_m: float
    normal_angle_deg: float
    reach_distance_m: float | None
    reachable: bool

    @property
    def area_available(self) -> bool:
        return self.area.available

    @property
    def rectangles(self) -> list[RectangleCandidate]:
        return self.area.rectangles

    @property
    def switching(self) -> bool:
        """Eq. 3.1 for this plane."""
        return self.area_available and self.height_available

    foothold_index: int | None = None  # rectangle giving the foothold
    reachable_indices: list[int] = field(default_factory=list)  # passing + reachable

    @property
    def foothold(self) -> np.ndarray | None:
        if self.foothold_index is None:
            return None
        return self.area.rectangles[self.foothold_index].pose


@dataclass
class SwitchingDecision:
    """Result of :func:`decide_mode` (DESIGN §5)."""

    mode: str  # "mobile" | "inchworm" | "none"
    plane_available: bool
    area_available: bool
    height_available: bool
    foothold: np.ndarray | None  # 4×4 in the base frame (inch-worm target)
    plane_index: int | None  # chosen candidate
    height_m: float | None  # chosen plane's centroid z in the base frame
    height_error_m: float | None  # height_m − base_height
    rectangles_passed: int
    rectangles_total: int
    alg2_exact_agreement: float | None  # over every rectangle of every plane
    candidates: list[PlaneCandidate]
    points: np.ndarray  # processed cloud, base frame
    n_points_in: int
    n_dropped_nonfinite: int
    timings_s: dict[str, float] = field(default_factory=dict)
    message: str = ""

    @property
    def chosen(self) -> PlaneCandidate | None:
        return None if self.plane_index is None else self.candidates[self.plane_index]

    @property
    def foothold_candidates(self) -> np.ndarray:
        """(K,4,4) every passing, reachable foothold on the chosen plane, the
        chosen one first (a jump planner tries them in this order)."""
        c = self.chosen
        if c is None or self.mode != "inchworm":
            return np.zeros((0, 4, 4))
        return np.array([c.area.rectangles[i].pose for i in c.reachable_indices])

    def summary(self) -> dict[str, Any]:
        """Small JSON-able digest (numbers and strings only)."""
        c = self.chosen
        return {
            "mode": self.mode,
            "plane_available": self.plane_available,
            "area_available": self.area_available,
            "height_available": self.height_available,
            "n_planes": len(self.candidates),
            "plane_index": self.plane_index,
            "height_m": self.height_m,
            "height_error_m": self.height_error_m,
            "normal_angle_deg": None if c is None else c.normal_angle_deg,
            "rectangles_passed": self.rectangles_passed,
            "rectangles_total": self.rectangles_total,
            "alg2_exact_agreement": self.alg2_exact_agreement,
            "message": self.message,
        }


def check_rigid(T: object, name: str = "camera_to_base", tol: float = 1e-6) -> np.ndarray:
    """A 4×4 proper rigid transform, or :class:`NonRigidTransformError`."""
    try:
        M = np.asarray(T, dtype=float)
    except (TypeError, ValueError) as exc:
        raise NonRigidTransformError(f"{name} must be a numeric 4×4 matrix ({exc})") from exc
    if M.shape != (4, 4):
        raise NonRigidTransformError(f"{name} must be 4×4, got shape {M.shape}")
    if not np.all(np.isfinite(M)):
        raise NonRigidTransformError(f"{name} has NaN/inf entries")
    if not np.allclose(M[3], [0, 0, 0, 1], atol=tol):
        raise NonRigidTransformError(f"{name} last row must be [0, 0, 0, 1], got {M[3].tolist()}")
    R = M[:3, :3]
    ortho = float(np.abs(R.T @ R - np.eye(3)).max())
    if ortho > tol:
        raise NonRigidTransformError(
            f"{name} rotation is not orthonormal (max |RᵀR − I| = {ortho:.2e}); "
            "scale or shear is not allowed"
        )
    if np.linalg.det(R) < 0:
        raise NonRigidTransformError(f"{name} is a reflection (det R = −1)")
    return M


def _check_foot(foot: object) -> tuple[float, float]:
    try:
        # an object that is not an iterable of two numbers raises TypeError/ValueError here
        length, width = (float(v) for v in foot)  # type: ignore[attr-defined]
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"foot must be (length_m, width_m), got {foot!r}") from exc
    if not (np.isfinite(length) and np.isfinite(width) and length > 0 and width > 0):
        raise InvalidInputError(f"foot dimensions must be positive metres, got {foot!r}")
    return length, width


def flip_about_normal(pose: np.ndarray) -> np.ndarray:
    """The same foothold turned 180° about its normal (x, y → −x, −y)."""
    out = pose.copy()
    out[:3, :2] *= -1.0
    return out


def _reachable(pose: np.ndarray, params: SwitchingParams) -> bool:
    if params.reach_m is not None and float(np.linalg.norm(pose[:3, 3])) > params.reach_m:
        return False
    if params.reach_check is None:
        return True
    return bool(params.reach_check(pose) or params.reach_check(flip_about_normal(pose)))


def evaluate_planes(
    points_base: np.ndarray,
    *,
    foot: tuple[float, float],
    base_height: float | None,
    params: SwitchingParams,
    camera_to_base: np.ndarray | None = None,
    viewpoint: np.ndarray | None = None,
    progress: Progress | None = None,
) -> tuple[list[PlaneCandidate], dict[str, float]]:
    """S_pa and S_am (and S_hc when ``base_height`` is given) for every plane
    in an already filtered cloud.  Normals are oriented towards ``viewpoint``
    (default: the camera origin, else +z)."""
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    planes = detect_planes(
        points_base,
        threshold_m=params.ransac_threshold_m,
        min_points=params.min_plane_points,
        max_planes=params.max_planes,
        iterations=params.ransac_iterations,
        seed=params.seed,
        cluster_radius_m=params.cluster_radius_m,
    )
    timings["ransac"] = time.perf_counter() - t0
    if progress:
        progress(0.5, "area")
    if viewpoint is None and camera_to_base is not None:
        viewpoint = camera_to_base[:3, 3]
    inv = None if camera_to_base is None else np.linalg.inv(camera_to_base)
    out: list[PlaneCandidate] = []
    t0 = time.perf_counter()
    for k, pl in enumerate(planes):  # a handful of planes
        pts = points_base[pl.inliers]
        c = pts.mean(axis=0)
        n = pl.normal.copy()
        look = (viewpoint - c) if viewpoint is not None else np.array([0.0, 0.0, 1.0])
        if n @ look < 0:
            n = -n  # the visible side of the surface faces the camera
        frame = PlaneFrame.from_normal(c, n)
        area = area_check(
            frame.to_plane(pts),
            frame,
            foot=foot,
            n_closest=params.n_closest,
            m_neighbours=params.m_neighbours,
            tolerance=params.distance_tolerance,
            sliding_factor=params.sliding_factor_m,
            alpha_m=params.alpha_m,
            exact_tolerance_m=params.exact_tolerance_m,
        )
        if base_height is None:
            hok, dz, ang = False, float("nan"), float(np.degrees(np.arccos(min(1.0, abs(n[2])))))
        else:
            hok, dz, ang = height_check(
                c,
                n,
                base_height=base_height,
                tolerance_m=params.height_tolerance_m,
                parallel_tolerance_deg=params.parallel_tolerance_deg,
            )
        # Alg. 2 returns the first passing rectangle; for a jump it must also
        # be reachable, so take the first passing one that is.
        passing = [r for r in area.rectangles if r.passed]
        reach = min((float(np.linalg.norm(r.pose[:3, 3])) for r in passing), default=None)
        reach_ok = [r.index for r in passing if _reachable(r.pose, params)]
        foothold_index = reach_ok[0] if reach_ok else None
        if foothold_index is not None:
            reach = float(np.linalg.norm(area.rectangles[foothold_index].pose[:3, 3]))
        reachable = foothold_index is not None
        out.append(
            PlaneCandidate(
                index=k,
                normal=n,
                centroid=c,
                centroid_camera=c if inv is None else (inv @ np.append(c, 1.0))[:3],
                n_points=len(pts),
                rms_m=pl.rms_m,
                points_index=np.nonzero(pl.inliers)[0],
                frame=frame,
                area=area,
                area_m2=float(area.hull.area),
                height_available=hok,
                height_error_m=dz,
                normal_angle_deg=ang,
                reach_distance_m=reach,
                reachable=reachable,
                foothold_index=foothold_index
                if foothold_index is not None
                else (passing[0].index if passing else None),
                reachable_indices=reach_ok,
            )
        )
    timings["area"] = time.perf_counter() - t0
    return out, timings


def decide_mode(
    points: np.ndarray,
    *,
    camera_to_base: np.ndarray,
    base_height: float,
    foot: tuple[float, float],
    params: SwitchingParams | dict[str, Any] | None = None,
    progress: Progress | None = None,
) -> SwitchingDecision:
    """Switching function S = S_pa ∧ S_am ∧ S_hc (seed Eq. 3.1) on a depth scan.

    ``points`` (N,3) in the camera frame; ``camera_to_base`` the 4×4 rigid
    transform T_frb_fc of Eq. 3.3; ``base_height`` the standing surface's z
    in the base frame (metres); ``foot`` = (length_m, width_m).  Raises
    :class:`EmptyInputError` (no points, or none left after the pass-through),
    :class:`InvalidInputError` (bad shape, NaN rows unless
    ``params.drop_nonfinite``), :class:`NonRigidTransformError`, and
    :class:`NoPlaneError` when no plane is found and ``params.on_no_plane`` is
    "raise" (default: mode "none").
    """
    if params is None:
        params = SwitchingParams()
    elif isinstance(params, dict):
        params = replace(SwitchingParams(), **params)
    t_all = time.perf_counter()
    timings: dict[str, float] = {}
    raw = as_points(points, "points", dims=3, finite=False)
    if len(raw) == 0:
        raise EmptyInputError("points is empty; decide_mode needs a depth scan (N, 3)")
    dropped = 0
    if not np.all(np.isfinite(raw)):
        if not params.drop_nonfinite:
            bad = int(np.count_nonzero(~np.all(np.isfinite(raw), axis=1)))
            raise InvalidInputError(
                f"points has {bad} row(s) with NaN/inf; drop them or pass "
                "params drop_nonfinite=True"
            )
        raw, dropped = drop_nonfinite(raw)
    T = check_rigid(camera_to_base)
    try:
        base_height = float(base_height)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"base_height must be metres, got {base_height!r}") from exc
    if not np.isfinite(base_height):
        raise InvalidInputError(f"base_height must be finite, got {base_height!r}")
    foot_lw = _check_foot(foot)
    if params.on_no_plane not in ("none", "raise"):
        raise InvalidInputError(
            f"on_no_plane must be 'none' or 'raise', got {params.on_no_plane!r}"
        )
    if progress:
        progress(0.0, "preprocess")
    t0 = time.perf_counter()
    pts = raw @ T[:3, :3].T + T[:3, 3]  # Eq. 3.3 for every point
    keep = passthrough(pts, x=params.x_range_m, y=params.y_range_m, z=params.z_range_m)
    pts = pts[keep]
    if len(pts) == 0:
        raise EmptyInputError(
            "no points left after the pass-through filter "
            f"(x {params.x_range_m}, y {params.y_range_m}, z {params.z_range_m} m, base frame)"
        )
    pts = voxel_downsample(pts, params.voxel_m)
    timings["preprocess"] = time.perf_counter() - t0
    cands, t_eval = evaluate_planes(
        pts,
        foot=foot_lw,
        base_height=base_height,
        params=params,
        camera_to_base=T,
        progress=progress,
    )
    timings.update(t_eval)
    rects = [r for c in cands for r in c.rectangles]
    agreement = float(np.mean([r.agrees for r in rects])) if rects else None
    if not cands:
        if params.on_no_plane == "raise":
            raise NoPlaneError(
                f"no plane with ≥ {params.min_plane_points} points in {len(pts)} processed points"
            )
        timings["total"] = time.perf_counter() - t_all
        return SwitchingDecision(
            mode="none",
            plane_available=False,
            area_available=False,
            height_available=False,
            foothold=None,
            plane_index=None,
            height_m=None,
            height_error_m=None,
            rectangles_passed=0,
            rectangles_total=0,
            alg2_exact_agreement=None,
            candidates=[],
            points=pts,
            n_points_in=len(raw) + dropped,
            n_dropped_nonfinite=dropped,
            timings_s=timings,
            message="S_pa = false: no planar surface in view (Eq. 3.2); the robot must not move",
        )
    mobile = [c for c in cands if c.switching]
    targets = [c for c in cands if c.area_available and not c.height_available and c.reachable]
    if mobile:
        # Largest same-height surface with room for a foot: keep driving.
        chosen = max(mobile, key=lambda c: c.area_m2)
        mode, foothold = "mobile", None
        msg = "S = S_pa ∧ S_am ∧ S_hc = true: surface ahead at base height with room for a foot"
    elif targets:
        # Nearest reachable foothold (shortest jump), then the larger surface.
        chosen = min(targets, key=lambda c: (c.reach_distance_m, -c.area_m2))
        mode, foothold = "inchworm", chosen.foothold
        msg = (
            f"S = false (S_hc false: Δz = {chosen.height_error_m * 1000:.1f} mm, normal "
            f"{chosen.normal_angle_deg:.1f}°); plane {chosen.index} has room for a foot "
            f"{chosen.reach_distance_m:.3f} m away: inch-worm jump"
        )
    else:
        with_area = [c for c in cands if c.area_available]
        # a plane with area available has a passing rectangle, hence a reach distance
        reaches = [c.reach_distance_m for c in with_area if c.reach_distance_m is not None]
        chosen = max(with_area or cands, key=lambda c: c.area_m2)
        mode, foothold = "none", None
        if with_area:
            msg = (
                "surfaces with room for a foot are not at base height and out of reach "
                f"(nearest foothold {min(reaches):.3f} m > "
                f"{params.reach_m} m); the robot must not move"
            )
        else:
            msg = "S_am = false on every plane: no surface fits a foot; the robot must not move"
    passed = sum(r.passed for r in chosen.rectangles)
    timings["total"] = time.perf_counter() - t_all
    if progress:
        progress(1.0, "done")
    return SwitchingDecision(
        mode=mode,
        plane_available=True,
        area_available=chosen.area_available,
        height_available=chosen.height_available,
        foothold=foothold,
        plane_index=chosen.index,
        height_m=float(chosen.centroid[2]),
        height_error_m=chosen.height_error_m,
        rectangles_passed=passed,
        rectangles_total=len(chosen.rectangles),
        alg2_exact_agreement=agreement,
        candidates=cands,
        points=pts,
        n_points_in=len(raw) + dropped,
        n_dropped_nonfinite=dropped,
        timings_s=timings,
        message=msg,
    )
