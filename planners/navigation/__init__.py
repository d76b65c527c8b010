"""ARA navigation chain (seed Ch. 4): point cloud → bars and cross areas →
structure graph → inspection route (VOCPP) → boundary-safe robot path.

Entry point :func:`plan_navigation` (DESIGN §5).  Stages, each in its module:

1. :mod:`.preprocess` — pass-through, voxel grid, RANSAC plane, projection (Ch. 4 intro);
2. :mod:`.segmentation` — bars / cross areas (Alg. 3 as ``"thesis"``, a
   deterministic strip-based ``"default"``), neighbour borders (§4.1);
3. :mod:`.boundaries` — NCBE boundary per cluster (Alg. 1);
4. :mod:`.graph` — structure graph (Alg. 4, fixed to follow every bar);
5. :func:`planners.vocpp.plan_route` — the route (Alg. 5, exact by default);
6. :mod:`.pibc` + :mod:`.rrt` — per-edge RRT-Connect in (x, y, yaw) whose
   samples are valid when every footprint point is on steel (Alg. 6).

Synthetic structures with ground truth for tests and samples live in
:mod:`.synthetic` (``SAMPLES``, ``STRUCTURES``).

The chain itself is :mod:`.pipeline`; parameters and result are :mod:`.params`.
This package only re-exports them.
"""

from planners.navigation.boundaries import Cluster
from planners.navigation.params import (
    MOTION_MODELS,
    SEGMENTATION_METHODS,
    NavigationParams,
    NavigationResult,
)
from planners.navigation.pipeline import plan_navigation
from planners.navigation.rrt import EdgePath

__all__ = [
    "MOTION_MODELS",
    "SEGMENTATION_METHODS",
    "Cluster",
    "EdgePath",
    "NavigationParams",
    "NavigationResult",
    "plan_navigation",
]
