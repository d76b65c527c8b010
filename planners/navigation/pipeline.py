"""ARA navigation chain (seed Ch. 4): point cloud → bars and cross areas →
structure graph → inspection route (VOCPP) → boundary-safe robot path.

Entry point :func:`plan_navigation` (DESIGN §5), re-exported by the package.  Stages, each in its module:

1. :mod:`.preprocess` — pass-through, voxel grid, RANSAC plane, projection (Ch. 4 intro);
2. :mod:`.segmentation` — bars / cross areas (Alg. 3 as ``"thesis"``, a
   deterministic strip-based ``"default"``), neighbour borders (§4.1);
3. :mod:`.boundaries` — NCBE boundary per cluster (Alg. 1);
4. :mod:`.graph` — structure graph (Alg. 4, fixed to follow every bar);
5. :func:`planners.vocpp.plan_route` — the route (Alg. 5, exact by default);
6. :mod:`.pibc` + :mod:`.rrt` — per-edge RRT-Connect in (x, y, yaw) whose
   samples are valid when every footprint point is on steel (Alg. 6):
   differential drive (hand-written) or holonomic (OMPL).

Synthetic structures with ground truth for tests and samples live in
:mod:`.synthetic` (``SAMPLES``, ``STRUCTURES``).
"""

from __future__ import annotations

import time
from collections.abc import Hashable
from typing import SupportsIndex, SupportsInt, TypedDict

import networkx as nx
import numpy as np

from planners.errors import EmptyInputError, InvalidInputError, UnknownVertexError
from planners.navigation.boundaries import Cluster, cluster_geometry
from planners.navigation.graph import build_graph, default_endpoints
from planners.navigation.params import (
    NavigationParams,
    NavigationResult,
    Progress,
)
from planners.navigation.pibc import (
    BoundarySet,
    footprint_points,
    poses_valid,
    rectangles_on_steel,
    steel_union,
)
from planners.navigation.preprocess import preprocess
from planners.navigation.rrt import (
    DiffDrivePlanner,
    EdgePath,
    EdgePlanner,
    corridor_sampler,
    settle_pose,
    wrap,
)
from planners.navigation.segmentation import borders, segment_default, segment_thesis
from planners.vocpp import Route, plan_route

__all__ = ["plan_navigation"]


def _validate_points(points: object) -> np.ndarray:
    try:
        pts = np.asarray(points, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"points must be a numeric (N, 3) array ({exc})") from exc
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InvalidInputError(f"points must have shape (N, 3) in metres, got {pts.shape}")
    if len(pts) == 0:
        raise EmptyInputError("points is empty: the navigation planner needs a point cloud")
    bad = ~np.all(np.isfinite(pts), axis=1)
    if np.any(bad):
        raise InvalidInputError(
            f"points has {int(bad.sum())} row(s) with NaN/inf (first at row {int(np.argmax(bad))}); "
            "drop them first (planners.pointcloud.drop_nonfinite)"
        )
    return pts


def vertex_id(v: Hashable) -> int:
    """A structure-graph vertex as the ``int`` it is: :func:`build_graph`
    numbers vertices ``0..V-1``; a :class:`Route` carries them as ``Hashable``."""
    assert isinstance(v, SupportsInt), f"structure-graph vertex {v!r} is not an integer"
    return int(v)


class _RrtSettings(TypedDict):
    """Keyword arguments shared by :class:`EdgePlanner` and :class:`DiffDrivePlanner`."""

    yaw_radius_m: float
    step_m: float
    resolution_m: float
    max_iterations: int
    shortcut_rounds: int


def _check_vertex(g: nx.Graph, v: Hashable, role: str) -> Hashable:
    if v in g:
        return v
    # Accept numeric strings ("3") from REST callers.
    iv: int | None = None
    # int() accepts exactly these; any other vertex cannot name an int id
    if isinstance(v, (str, bytes, SupportsInt, SupportsIndex)):
        try:
            iv = int(v)
        except (TypeError, ValueError):
            iv = None
    if iv is not None and iv in g:
        return iv
    leaves = sorted(n for n in g.nodes if g.degree(n) == 1)
    raise UnknownVertexError(
        f"{role} vertex {v!r} is not in the structure graph; vertices are 0..{max(g.nodes)} "
        f"(leaf vertices: {leaves[:20]})"
    )


def _edge_paths(
    g: nx.Graph,
    route: Route,
    clusters: list[Cluster],
    p: NavigationParams,
    progress: Progress | None,
) -> list[EdgePath]:
    """One on-steel robot path per route edge (seed §4.3: "the motion path for
    one edge each time"), continuous from edge to edge."""
    m = p.footprint_margin_m
    foot = footprint_points(
        p.footprint_length_m + 2 * m,
        p.footprint_width_m + 2 * m,
        center_x_m=p.footprint_center_x_m,
        center_y_m=p.footprint_center_y_m,
        spacing_m=p.footprint_spacing_m,
    )
    reach = float(np.max(np.hypot(foot[:, 0], foot[:, 1])))
    boxes = np.array(
        [
            [*c.boundary.min(axis=0), *c.boundary.max(axis=0)]
            if len(c.boundary)
            else [0, 0, -1, -1]
            for c in clusters
        ]
    )
    full = BoundarySet([c.centre for c in clusters], [c.boundary for c in clusters])
    steel = steel_union([c.boundary for c in clusters])
    rect = (p.footprint_length_m + 2 * m, p.footprint_width_m + 2 * m)
    cx, cy = p.footprint_center_x_m, p.footprint_center_y_m
    rng = np.random.default_rng(p.seed)
    out: list[EdgePath] = []
    prev: np.ndarray | None = None
    n_edges = len(route.edges)
    size = f"{p.footprint_length_m:g} × {p.footprint_width_m:g} m footprint"
    for k, (u, v, _key) in enumerate(route.edges):
        a = np.asarray(g.nodes[u]["pos2d"], dtype=float)
        b = np.asarray(g.nodes[v]["pos2d"], dtype=float)
        lo = np.minimum(a, b) - reach - 0.05
        hi = np.maximum(a, b) + reach + 0.05
        near = np.nonzero(
            (boxes[:, 0] <= hi[0])
            & (boxes[:, 2] >= lo[0])
            & (boxes[:, 1] <= hi[1])
            & (boxes[:, 3] >= lo[1])
        )[0]
        bset = full.subset(near.tolist())
        n_c = p.pibc_n_centres if p.pibc_n_centres > 0 else len(bset)

        def valid(poses: np.ndarray, bset: BoundarySet = bset, n_c: int = n_c) -> np.ndarray:
            # Alg. 6 on the footprint's points, then, for the poses it passes,
            # the whole (margin-grown) rectangle inside the union of the
            # boundaries, so no pose straddles a gap between two of them.
            ok = poses_valid(
                poses, foot, bset, method=p.pibc_method, n_centres=n_c, m_closest=p.pibc_m_closest
            )
            if ok.any():
                ok[ok] = rectangles_on_steel(poses[ok], steel, *rect, center_x_m=cx, center_y_m=cy)
            return ok

        yaw = float(np.arctan2(*(b - a)[::-1])) if np.hypot(*(b - a)) > 1e-9 else 0.0
        start = prev if prev is not None else settle_pose(a, b, yaw, valid)
        # Drive backwards rather than turn round on a bar: the goal heading is
        # the edge direction or its reverse, whichever is nearer the start's.
        goal_yaw = yaw
        if start is not None and abs(float(wrap(start[2] - yaw))) > np.pi / 2:
            goal_yaw = float(wrap(yaw + np.pi))
        goal = settle_pose(b, a, goal_yaw, valid)
        if start is None or goal is None:
            which = "start" if start is None else "end"
            out.append(
                EdgePath(
                    vertex_id(u),
                    vertex_id(v),
                    np.zeros((0, 3)),
                    False,
                    f"no pose near the {which} of edge ({u}, {v}) keeps the {size} on steel",
                )
            )
            prev = None
        else:
            common: _RrtSettings = {
                "yaw_radius_m": 0.5 * p.footprint_length_m,
                "step_m": p.rrt_step_m,
                "resolution_m": p.rrt_resolution_m,
                "max_iterations": p.rrt_max_iterations,
                "shortcut_rounds": p.shortcut_rounds,
            }
            planner: EdgePlanner | DiffDrivePlanner = (
                DiffDrivePlanner(valid, turn_resolution_rad=p.turn_resolution_rad, **common)
                if p.motion_model == "differential"
                else EdgePlanner(valid, **common)
            )
            if isinstance(planner, DiffDrivePlanner):
                sampler = corridor_sampler(
                    a, b, rng, lateral_sigma_m=0.03, margin_m=0.5 * p.footprint_length_m
                )
                # Turns happen at the vertex the edge leaves (the route
                # changes bars there): search turning points around it.
                path, iters = planner.plan(
                    start,
                    goal,
                    sampler,
                    turn_centre=a,
                    turn_radius_m=0.5 * p.footprint_length_m + 0.02,
                )
                path = None if path is None else planner.shortcut(path, rng)
            else:  # OMPL, sampling the box whose clusters ``valid`` checks
                seed = int(rng.integers(2**31 - 1))
                path, iters = planner.plan(start, goal, lower=lo, upper=hi, seed=seed)
            dense = None if path is None else planner.densify(path)
            if dense is None or not np.all(valid(dense)):
                what = (
                    "differential-drive path (turns in place, straight drives)"
                    if p.motion_model == "differential"
                    else "path"
                )
                out.append(
                    EdgePath(
                        vertex_id(u),
                        vertex_id(v),
                        np.zeros((0, 3)),
                        False,
                        f"RRT-Connect found no on-steel {what} for edge ({u}, {v}) in "
                        f"{iters} iterations: the {size} does not fit the steel between its "
                        "ends (a turn, or a boundary narrower than the footprint)",
                        iters,
                    )
                )
                prev = None
            else:
                out.append(EdgePath(vertex_id(u), vertex_id(v), dense, True, "", iters))
                prev = dense[-1]
        if progress is not None:
            progress(0.75 + 0.24 * (k + 1) / max(n_edges, 1), f"path {k + 1}/{n_edges}")
    return out


def plan_navigation(
    points: np.ndarray,
    *,
    start: Hashable | None = None,
    end: Hashable | None = None,
    params: NavigationParams | None = None,
    progress: Progress | None = None,
) -> NavigationResult:
    """Plan the ARA's inspection of a steel structure seen as ``points`` (seed Ch. 4).

    ``points`` (N, 3) in the robot frame, metres, all finite.  ``start``/``end``
    are vertex ids of the structure graph; ``None`` picks two leaf vertices at
    the ends of the structure (:func:`.graph.default_endpoints`).  ``progress``
    (fraction, stage) is called between stages and may raise
    :class:`planners.errors.CancelledError`, which propagates.

    Raises :class:`EmptyInputError` (empty cloud, nothing left after
    filtering), :class:`InvalidInputError` (bad shape, NaN/inf, bad params),
    :class:`planners.errors.InfeasibleError` (no structure plane),
    :class:`UnknownVertexError` (start/end not in the graph) and the route's
    errors (:func:`planners.vocpp.plan_route`).  Same input → same output.
    """
    p = (params or NavigationParams()).validated()
    pts = _validate_points(points)
    timings: dict[str, float] = {}

    def stage(fraction: float, name: str) -> None:
        if progress is not None:
            progress(fraction, name)

    t = time.perf_counter()
    stage(0.0, "preprocess")
    pre = preprocess(
        pts,
        crop_box_m=p.crop_box_m,
        passthrough_x_m=p.passthrough_x_m,
        passthrough_y_m=p.passthrough_y_m,
        passthrough_z_m=p.passthrough_z_m,
        voxel_m=p.voxel_m,
        ransac_threshold_m=p.ransac_threshold_m,
        ransac_iterations=p.ransac_iterations,
        min_plane_points=p.min_plane_points,
        speckle_radius_m=p.speckle_radius_m,
        speckle_min_neighbours=p.speckle_min_neighbours,
        seed=p.seed,
    )
    timings["preprocess_s"] = time.perf_counter() - t

    t = time.perf_counter()
    stage(0.15, "segmentation")
    uv = pre.points2d
    if p.segmentation == "default":
        seg = segment_default(
            uv,
            grid_m=p.grid_m,
            n_directions=p.n_directions,
            long_factor=p.long_factor,
            min_bar_length_m=p.min_bar_length_m,
        )
    else:
        seg = segment_thesis(
            uv,
            n_clusters_min=p.thesis_clusters_min,
            n_clusters_max=p.thesis_clusters_max,
            lb_m=p.border_lb_m,
            eps_m=p.border_eps_m,
            max_points=p.thesis_max_points,
            seed=p.seed,
        )
    brs = borders(uv, seg.labels, eps_m=p.border_eps_m, lb_m=p.border_lb_m)
    if p.segmentation == "default":
        # "Their two ends connect two cross areas" (§4.1): with every crossing
        # found, two bars that touch beside a narrow-angle crossing are not
        # neighbours, so the route turns in the crossing, not on a corner.
        brs = [b for b in brs if seg.kinds[b.a] != seg.kinds[b.b]]
    timings["segmentation_s"] = time.perf_counter() - t

    t = time.perf_counter()
    stage(0.4, "boundaries")
    clusters = cluster_geometry(
        uv,
        seg.labels,
        seg.kinds,
        brs,
        sliding_factor_m=p.sliding_factor_m,
        polygons="strips" if p.segmentation == "default" else "stars",
    )
    timings["boundaries_s"] = time.perf_counter() - t

    t = time.perf_counter()
    stage(0.5, "graph")
    g = build_graph(clusters, brs, pre.frame.lift, dmin_m=p.dmin_m)
    if g.number_of_edges() == 0:
        raise EmptyInputError(
            f"the structure graph has no edges ({len(clusters)} cluster(s), none with a "
            "neighbour or a free end); is the cloud a steel-bar structure?"
        )
    if start is None or end is None:
        s0, e0 = default_endpoints(g)
        start = s0 if start is None else start
        end = e0 if end is None else end
    start = _check_vertex(g, start, "start")
    end = _check_vertex(g, end, "end")
    timings["graph_s"] = time.perf_counter() - t

    t = time.perf_counter()
    stage(0.6, "route")
    route = plan_route(g, start, end, weight="weight", method=p.route_method)
    timings["route_s"] = time.perf_counter() - t

    t = time.perf_counter()
    stage(0.75, "paths")
    paths = _edge_paths(g, route, clusters, p, progress) if p.plan_paths else []
    timings["paths_s"] = time.perf_counter() - t
    stage(1.0, "done")
    counts = dict(pre.counts)
    counts["clusters"] = len(clusters)
    counts["vertices"] = g.number_of_nodes()
    counts["edges"] = g.number_of_edges()
    return NavigationResult(
        points=pre.points3d,
        points2d=uv,
        labels=seg.labels,
        clusters=clusters,
        graph=g,
        route=route,
        edge_paths=paths,
        frame=pre.frame,
        start=start,
        end=end,
        params=p,
        timings_s=timings,
        counts=counts,
        segmentation_info=dict(seg.info),
    )
