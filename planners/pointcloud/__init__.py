"""Shared point-cloud primitives: filters, RANSAC planes, NCBE boundary.

Used by the ARA switching control (seed §3.1, Alg. 1) and the navigation
chain (seed Ch. 4, which reuses NCBE).  Everything is vectorised numpy and
deterministic (explicit seeds); bad input raises :mod:`planners.errors`.
"""

from planners.pointcloud.filters import drop_nonfinite, passthrough, voxel_downsample
from planners.pointcloud.hull import alpha_shape
from planners.pointcloud.ncbe import ncbe_boundary, ncbe_boundary_indices, order_boundary
from planners.pointcloud.ransac import (
    PlaneFit,
    connected_parts,
    detect_planes,
    fit_plane_ransac,
)

__all__ = [
    "PlaneFit",
    "alpha_shape",
    "connected_parts",
    "detect_planes",
    "drop_nonfinite",
    "fit_plane_ransac",
    "ncbe_boundary",
    "ncbe_boundary_indices",
    "order_boundary",
    "passthrough",
    "voxel_downsample",
]
