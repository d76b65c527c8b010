"""Pre-processing of the navigation chain (seed Ch. 4 introduction, §5.2.1).

"The PCL data of the steel bridge is filtered and then projected into a 2D
plane, which is the xy plane of the robot coordinate frame": pass-through
filter → voxel down-sampling → RANSAC plane → reject off-plane outliers →
orthogonal projection onto the fitted plane, expressed in a plane frame
whose x axis is the robot's x axis projected onto the plane (so plane
coordinates ≈ robot xy for a robot standing on the structure).  The frame is
kept so every 2D result can be lifted back to xyz in the input frame.
Uses the shared primitives of :mod:`planners.pointcloud`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from planners.errors import EmptyInputError, InfeasibleError, InvalidInputError
from planners.pointcloud import fit_plane_ransac, passthrough, voxel_downsample
from planners.pointcloud.ransac import PlaneFit


@dataclass(frozen=True)
class PlaneFrame:
    """``p3 = origin + u·e1 + v·e2`` maps plane coordinates to the input frame."""

    origin: np.ndarray  # (3,)
    e1: np.ndarray  # (3,)
    e2: np.ndarray  # (3,)
    normal: np.ndarray  # (3,) = e1 × e2

    def to_plane(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) → (N, 2) orthogonal projection in plane coordinates."""
        d = np.asarray(points, dtype=float).reshape(-1, 3) - self.origin
        return np.column_stack([d @ self.e1, d @ self.e2])

    def lift(self, uv: np.ndarray) -> np.ndarray:
        """(N, 2) plane coordinates → (N, 3) points on the plane, input frame."""
        uv = np.asarray(uv, dtype=float).reshape(-1, 2)
        return self.origin + uv[:, :1] * self.e1 + uv[:, 1:2] * self.e2

    @classmethod
    def from_plane(cls, normal: np.ndarray, d: float) -> PlaneFrame:
        """Frame of plane ``n·p + d = 0``: origin = the robot origin's foot point,
        e1 = robot x projected onto the plane (robot y when x ∥ n), normal = e1 × e2
        oriented to have a positive z component (robot z up)."""
        n = np.asarray(normal, dtype=float)
        n = n / np.linalg.norm(n)
        if n[2] < 0:
            n, d = -n, -d
        origin = -d * n
        ref = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        e1 = ref - (ref @ n) * n
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(n, e1)
        return cls(origin=origin, e1=e1, e2=e2, normal=n)


@dataclass
class Preprocessed:
    """Output of :func:`preprocess`."""

    points3d: np.ndarray  # (M, 3) processed points projected onto the plane, input frame
    points2d: np.ndarray  # (M, 2) the same in plane coordinates
    frame: PlaneFrame
    plane: PlaneFit
    counts: dict[str, int]  # points after each step


def preprocess(
    points: np.ndarray,
    *,
    crop_box_m: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None,
    passthrough_x_m: tuple[float, float] | None = (-1.0, 6.0),
    passthrough_y_m: tuple[float, float] | None = (-4.0, 4.0),
    passthrough_z_m: tuple[float, float] | None = (-0.5, 0.5),
    voxel_m: float = 0.01,
    ransac_threshold_m: float = 0.015,
    ransac_iterations: int = 300,
    min_plane_points: int = 200,
    speckle_radius_m: float = 0.03,
    speckle_min_neighbours: int = 3,
    seed: int = 0,
) -> Preprocessed:
    """Filter, down-sample, fit the structure plane and project onto it (seed Ch. 4 intro).

    ``points`` must be finite (N, 3); ``crop_box_m`` keeps the points inside
    an axis-aligned box of the cloud's frame, the pass-through windows then
    apply in the robot frame (``None``: none on that axis).  After the plane's
    outliers are removed, in-plane specks (fewer than
    ``speckle_min_neighbours`` neighbours within ``speckle_radius_m``) are
    dropped too: they are clutter that happens to touch the plane.
    Raises :class:`EmptyInputError` when a step leaves nothing and
    :class:`InfeasibleError` when no plane with ``min_plane_points`` is found.
    """
    pts = np.asarray(points, dtype=float)
    counts = {"input": len(pts)}
    if crop_box_m is not None:
        lo, hi = np.asarray(crop_box_m, dtype=float)
        pts = pts[np.all((pts >= lo) & (pts <= hi), axis=1)]
        counts["crop_box"] = len(pts)
        if len(pts) < 3:
            raise EmptyInputError(
                f"only {len(pts)} point(s) inside the crop box {lo.tolist()} – {hi.tolist()} m "
                f"(the cloud spans {np.asarray(points).min(axis=0).round(3).tolist()} – "
                f"{np.asarray(points).max(axis=0).round(3).tolist()} m)"
            )
    keep = passthrough(pts, x=passthrough_x_m, y=passthrough_y_m, z=passthrough_z_m)
    pts = pts[keep]
    counts["passthrough"] = len(pts)
    if len(pts) < 3:
        raise EmptyInputError(
            f"only {len(pts)} point(s) left after the pass-through filter "
            f"(x {passthrough_x_m}, y {passthrough_y_m}, z {passthrough_z_m} m); "
            "widen the limits or check the cloud's frame"
        )
    pts = voxel_downsample(pts, voxel_m)
    counts["voxel"] = len(pts)
    try:
        plane = fit_plane_ransac(
            pts, threshold_m=ransac_threshold_m, iterations=ransac_iterations, seed=seed
        )
    except (EmptyInputError, InvalidInputError) as exc:
        raise InfeasibleError(f"no structure plane found: {exc}") from exc
    if plane.n_inliers < min_plane_points:
        raise InfeasibleError(
            f"no structure plane found: the best RANSAC plane has {plane.n_inliers} inliers "
            f"within {ransac_threshold_m} m, fewer than min_plane_points={min_plane_points}"
        )
    pts = pts[plane.inliers]
    counts["plane"] = len(pts)
    frame = PlaneFrame.from_plane(plane.normal, plane.d)
    uv = frame.to_plane(pts)
    if speckle_min_neighbours > 0 and len(uv):
        n_nb = cKDTree(uv).query_ball_point(uv, speckle_radius_m, return_length=True)
        uv = uv[n_nb > speckle_min_neighbours]  # count includes the point itself
    counts["despeckled"] = len(uv)
    if len(uv) < 3:
        raise EmptyInputError("no points left on the structure plane after outlier removal")
    return Preprocessed(
        points3d=frame.lift(uv), points2d=uv, frame=frame, plane=plane, counts=counts
    )
