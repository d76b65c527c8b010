"""The blasting surface picked from a scanned cloud, and its outline in the
world (seed 004 §1.2, Fig. 1.4: the surface to blast comes from the point
cloud of the mapping stage; the seed gives no algorithm for that step, so
the one here is chosen and stated).

Algorithm:

1. Sequential RANSAC planes with connected-component splitting
   (:func:`planners.pointcloud.ransac.detect_planes`), sorted by inlier count
   so index 0 is the largest plane.
2. The picked plane's inliers, less the points whose own local normal (PCA
   of 12 neighbours) is more than ``facing_deg`` off the plane normal: a
   distance threshold also takes the strip where a perpendicular face (a
   flange) crosses the plane.
3. Less the statistical outliers of what is left (PCL's
   StatisticalOutlierRemoval), which would pull thin spikes into the outline.
4. :meth:`planners.blasting.surface.Surface.from_points`: least-squares plane
   (SVD), concave hull of the projected points, normal toward the robot base.

The cloud's other points, voxel-downsampled to 2 cm, are the obstacle points
of the collision checks (seed §3.5).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import shapely

from planners.blasting.surface import Surface
from planners.errors import InvalidInputError, NoPlaneError

#: chosen: a plane point whose local normal is further off is not of the patch
FACING_DEG = 30.0
#: chosen: the obstacle points' voxel edge (the spheroids' clearance is ≥ 2 cm)
OBSTACLE_VOXEL_M = 0.02


@dataclass(frozen=True)
class PlaneInfo:
    """One detected plane, as the operator chooses among them."""

    index: int
    points: int
    normal: np.ndarray
    centroid: np.ndarray


@dataclass(frozen=True)
class PickedSurface:
    """What :func:`pick_surface` returns.

    ``obstacle_points`` is None when the cloud's other points are not
    obstacles; ``cloud_label`` (N,) is the plane index of every cloud point
    (−1: on no plane), first plane wins.
    """

    surface: Surface
    obstacle_points: np.ndarray | None
    planes: list[PlaneInfo]
    cloud_label: np.ndarray


def pick_surface(
    points: np.ndarray,
    *,
    plane_index: int,
    threshold_m: float,
    toward: np.ndarray,
    obstacles_from_rest: bool = True,
    facing_deg: float = FACING_DEG,
    min_points: int = 100,
) -> PickedSurface:
    """The blasting surface on plane ``plane_index`` (0 = largest) of the
    (N,3) cloud ``points`` (see the module doc for the algorithm).

    Raises :class:`planners.errors.NoPlaneError` when the cloud holds no
    plane of ``min_points`` inliers and
    :class:`planners.errors.InvalidInputError` for an index out of range.
    """
    from planners.pointcloud.filters import statistical_outliers, voxel_downsample
    from planners.pointcloud.normals import facing_mask
    from planners.pointcloud.ransac import detect_planes

    pts = np.asarray(points, dtype=float)
    if plane_index < 0:
        raise InvalidInputError(f"plane_index must be ≥ 0, got {plane_index}")
    planes = detect_planes(
        pts, threshold_m=threshold_m, min_points=min_points, cluster_radius_m=0.05
    )
    if not planes:
        raise NoPlaneError(f"no plane with ≥ {min_points} points found in the cloud")
    # detect_planes reports in discovery order (one plane's pieces together);
    # the operator picks by index, and index 0 is promised to be the largest
    planes = sorted(planes, key=lambda pl: -pl.n_inliers)
    if plane_index >= len(planes):
        raise InvalidInputError(
            f"plane_index {plane_index} out of range: the cloud has {len(planes)} planes"
        )
    picked = planes[plane_index]
    mask = picked.inliers.copy()
    # normals from the whole cloud: the strip's neighbours are on its face
    if len(pts) >= 12:
        mask &= facing_mask(pts, picked.normal, facing_deg)
    idx = np.nonzero(mask)[0]
    mask[idx[statistical_outliers(pts[idx])]] = False
    surface = Surface.from_points(pts[mask], toward=np.asarray(toward, dtype=float))
    label = np.full(len(pts), -1, dtype=np.int32)
    for i, pl in enumerate(planes):
        label[pl.inliers & (label < 0)] = i
    others = pts[~mask] if obstacles_from_rest else None
    if others is not None and len(others):
        others = voxel_downsample(others, OBSTACLE_VOXEL_M)
    info = [
        PlaneInfo(index=i, points=pl.n_inliers, normal=pl.normal, centroid=pl.centroid)
        for i, pl in enumerate(planes)
    ]
    return PickedSurface(surface=surface, obstacle_points=others, planes=info, cloud_label=label)


def outline_world(surface: Surface) -> tuple[np.ndarray, list[np.ndarray]]:
    """The surface's outline (K,3) and holes (list of (M,3)) in the world,
    closed rings on the plane; a multi-part surface is outlined by its convex
    hull and drawn without holes."""
    poly = surface.polygon
    if isinstance(poly, shapely.Polygon):
        ring = np.asarray(poly.exterior.coords)
        holes = [surface.to_world(np.asarray(h.coords)) for h in poly.interiors]
    else:
        hull = poly.convex_hull
        assert isinstance(hull, shapely.Polygon)  # the hull of an area-spanning surface
        ring = np.asarray(hull.exterior.coords)
        holes = []
    return surface.to_world(ring), holes


def nozzle_tip(frames: np.ndarray, length_m: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """Nozzle tip (T,3) and axis (T,3) from the flange frames (T,4,4): the
    tip is ``length_m`` along the flange z axis (the nozzle's mount)."""
    F = np.asarray(frames, dtype=float)
    axis = F[:, :3, 2]
    return F[:, :3, 3] + length_m * axis, axis
