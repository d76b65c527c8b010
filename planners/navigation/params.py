"""Parameters and result of the ARA navigation chain (seed Ch. 4, DESIGN §5):
:class:`NavigationParams` (every option, units in the names) and
:class:`NavigationResult` (everything :func:`planners.navigation.plan_navigation`
computed).
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from dataclasses import asdict, dataclass, field, fields

import networkx as nx
import numpy as np

from planners.errors import InvalidInputError
from planners.navigation.boundaries import Cluster
from planners.navigation.pibc import PIBC_METHODS
from planners.navigation.preprocess import PlaneFrame
from planners.navigation.rrt import EdgePath
from planners.vocpp import METHODS as ROUTE_METHODS
from planners.vocpp import Route

__all__ = [
    "MOTION_MODELS",
    "SEGMENTATION_METHODS",
    "NavigationParams",
    "NavigationResult",
    "Progress",
]

SEGMENTATION_METHODS = ("default", "thesis")
MOTION_MODELS = ("differential", "holonomic")
Progress = Callable[[float, str], None]


@dataclass(frozen=True)
class NavigationParams:
    """Every parameter of :func:`plan_navigation`, with units in the names."""

    # Pre-processing (Ch. 4 intro): a crop box (region of interest, the cloud's
    # own frame; None: the whole cloud), then pass-through limits in the robot
    # frame (None on an axis: no window on it).
    crop_box_m: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    passthrough_x_m: tuple[float, float] | None = (-1.0, 6.0)
    passthrough_y_m: tuple[float, float] | None = (-4.0, 4.0)
    passthrough_z_m: tuple[float, float] | None = (-0.5, 0.5)
    voxel_m: float = 0.01
    ransac_threshold_m: float = 0.015
    ransac_iterations: int = 300
    min_plane_points: int = 200
    speckle_radius_m: float = 0.03
    speckle_min_neighbours: int = 3
    # Segmentation (Alg. 3): "default" (strip-based) or "thesis" (EM-GMM + Eq. 4.1).
    segmentation: str = "default"
    grid_m: float = 0.01
    n_directions: int = 24
    long_factor: float = 2.5
    min_bar_length_m: float = 0.15
    thesis_clusters_min: int = 2
    thesis_clusters_max: int = 12
    thesis_max_points: int = 4000
    # Neighbour clusters: border length ≥ lb (§4.1), contact distance eps.
    border_lb_m: float = 0.03
    border_eps_m: float = 0.05
    # NCBE sliding factor αs (Alg. 1) and graph threshold dmin (Alg. 4).
    sliding_factor_m: float = 0.02
    dmin_m: float = 0.05
    # Route (Alg. 5): "exact" (min T-join) or "thesis" (as printed).
    route_method: str = "exact"
    # Robot footprint in the base frame (ARA robots/ara/params.toml [mobile_footprint]).
    footprint_length_m: float = 0.68
    footprint_width_m: float = 0.16
    footprint_center_x_m: float = -0.25
    footprint_center_y_m: float = 0.0
    footprint_spacing_m: float = 0.04
    # Clearance kept around the footprint while planning (the final check uses
    # the footprint itself), so poses do not graze a boundary.
    footprint_margin_m: float = 0.001
    # PIBC (Alg. 6): "angular" (exact for star-shaped boundaries) or "thesis".
    pibc_method: str = "angular"
    pibc_n_centres: int = 0  # 0 = every boundary near the edge
    pibc_m_closest: int = 3
    # Per-edge RRT-Connect and smoothing.  "differential": turns in place and
    # straight drives only (the ARA's wheels); "holonomic": any (x, y, yaw)
    # motion, the seed's RRT (the wheels cannot slide sideways: not drivable).
    plan_paths: bool = True
    motion_model: str = "differential"
    rrt_step_m: float = 0.08
    rrt_resolution_m: float = 0.01
    turn_resolution_rad: float = 0.05
    rrt_max_iterations: int = 1500
    shortcut_rounds: int = 60
    seed: int = 0

    def validated(self) -> NavigationParams:
        """Self, or :class:`InvalidInputError` naming the bad field."""
        if self.segmentation not in SEGMENTATION_METHODS:
            raise InvalidInputError(
                f"segmentation must be one of {SEGMENTATION_METHODS}, got {self.segmentation!r}"
            )
        if self.route_method not in ROUTE_METHODS:
            raise InvalidInputError(
                f"route_method must be one of {ROUTE_METHODS}, got {self.route_method!r}"
            )
        if self.motion_model not in MOTION_MODELS:
            raise InvalidInputError(
                f"motion_model must be one of {MOTION_MODELS}, got {self.motion_model!r}"
            )
        if not (np.isfinite(self.turn_resolution_rad) and 0 < self.turn_resolution_rad <= 0.5):
            raise InvalidInputError(
                f"turn_resolution_rad must be in (0, 0.5], got {self.turn_resolution_rad!r}"
            )
        if self.pibc_method not in PIBC_METHODS:
            raise InvalidInputError(
                f"pibc_method must be one of {PIBC_METHODS}, got {self.pibc_method!r}"
            )
        box = self.crop_box_m
        if box is not None:
            lo_hi = np.asarray(box, dtype=float) if _numeric_box(box) else None
            if lo_hi is None or lo_hi.shape != (2, 3) or not np.all(lo_hi[0] < lo_hi[1]):
                raise InvalidInputError(
                    "crop_box_m must be None or ((xmin, ymin, zmin), (xmax, ymax, zmax)) "
                    f"finite metres with min < max on every axis, got {box!r}"
                )
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name.startswith("passthrough_"):
                # a window (lo, hi) on that axis, or None: no window on it
                if v is not None and not (
                    isinstance(v, tuple)
                    and len(v) == 2
                    and all(isinstance(x, int | float) and np.isfinite(x) for x in v)
                    and v[0] < v[1]
                ):
                    raise InvalidInputError(
                        f"{f.name} must be None or (low, high) metres with low < high, got {v!r}"
                    )
                continue
            if (
                f.name.endswith("_m")
                and not isinstance(v, tuple)
                and f.name
                not in (
                    "crop_box_m",  # checked above
                    "footprint_center_x_m",
                    "footprint_center_y_m",
                    "footprint_margin_m",
                )
                and (not isinstance(v, int | float) or not np.isfinite(v) or v <= 0)
            ):
                raise InvalidInputError(f"{f.name} must be a positive number of metres, got {v!r}")
        if not (np.isfinite(self.footprint_margin_m) and self.footprint_margin_m >= 0):
            raise InvalidInputError(
                f"footprint_margin_m must be a non-negative number of metres, "
                f"got {self.footprint_margin_m!r}"
            )
        if self.thesis_clusters_min < 1 or self.thesis_clusters_max < self.thesis_clusters_min:
            raise InvalidInputError(
                "thesis_clusters_min/max must satisfy 1 <= min <= max, got "
                f"{self.thesis_clusters_min}, {self.thesis_clusters_max}"
            )
        return self

    def as_dict(self) -> dict[str, object]:
        return asdict(self)


@dataclass
class NavigationResult:
    """Everything :func:`plan_navigation` computed (DESIGN §5)."""

    points: np.ndarray  # (M, 3) processed points (on the fitted plane, input frame)
    points2d: np.ndarray  # (M, 2) the same in plane coordinates
    labels: np.ndarray  # (M,) cluster id per processed point, -1 = noise
    clusters: list[Cluster]
    graph: nx.Graph
    route: Route
    edge_paths: list[EdgePath]  # one per route edge, poses (x, y, yaw) in plane coordinates
    frame: PlaneFrame
    start: Hashable
    end: Hashable
    params: NavigationParams
    timings_s: dict[str, float] = field(default_factory=dict)
    counts: dict[str, int] = field(default_factory=dict)
    segmentation_info: dict[str, object] = field(default_factory=dict)

    def boundary_xyz(self, cluster: int) -> np.ndarray:
        """(K, 3) boundary polygon of a cluster in the input frame."""
        return self.frame.lift(self.clusters[cluster].boundary)

    def path_xyz(self, k: int) -> np.ndarray:
        """(K, 3) robot positions of route edge ``k``'s path in the input frame."""
        return self.frame.lift(self.edge_paths[k].poses[:, :2])

    def yaw_axis_xyz(self, yaw: np.ndarray) -> np.ndarray:
        """(K, 3) unit heading vectors in the input frame for plane-frame yaws."""
        yaw = np.asarray(yaw, dtype=float).reshape(-1, 1)
        return np.cos(yaw) * self.frame.e1 + np.sin(yaw) * self.frame.e2

    @property
    def paths_ok(self) -> bool:
        return all(p.ok for p in self.edge_paths)


def _numeric_box(box: object) -> bool:
    """Two sequences of three finite real numbers."""
    try:
        a = np.asarray(box, dtype=float)
    except (TypeError, ValueError):
        return False
    return a.shape == (2, 3) and bool(np.all(np.isfinite(a)))
