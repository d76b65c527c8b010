"""The ``ara.navigate`` kind's entry point in the one result contract (issue
#13 §2): :func:`plan_navigation_result` runs
:func:`planners.navigation.pipeline.plan_navigation` (seed 000 Ch. 4:
segmentation Alg. 3, NCBE Alg. 1, graph Alg. 4, VOCPP Alg. 5, PIBC Alg. 6 +
RRT) and shapes its result into the stored :class:`planners.result.PlanResult`:
the summary the scene drawer and the wheel compiler read, the arrays, the
checks and the metrics.

The checks are made independently of the planner's own bookkeeping: the
whole footprint at every driven pose and the area swept between poses
(:mod:`planners.navigation.footprint_checks`, exact, not Alg. 6's sampled
points), each step's wheel motion (:mod:`planners.navigation.wheel_steps`),
the bars the route drives on and its end vertices.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from planners.navigation.footprint_checks import Footprint, bars_covered, poses_on_steel
from planners.navigation.params import NavigationParams, NavigationResult
from planners.navigation.pipeline import plan_navigation, vertex_id
from planners.navigation.wheel_steps import wheel_steps
from planners.result import Check, PlanResult, check_ge
from planners.summary import json_safe


def plan_navigation_result(
    points: np.ndarray,
    *,
    start: int | None = None,
    end: int | None = None,
    params: NavigationParams,
    progress: Callable[[float, str], None] | None = None,
) -> PlanResult:
    """Plan the inspection route over ``points`` (N,3, robot frame) from vertex
    ``start`` to ``end`` (``None``: leaves at the ends of the structure) and
    return the stored form.

    The metric ``planning_time_s`` is the wall time of this call; every
    stage's time is ``<stage>_time_s``.  Bad input raises
    :mod:`planners.errors` types (from ``plan_navigation``); a route whose
    paths leave the steel or cannot be driven is failed checks, not an
    exception.
    """
    t0 = time.perf_counter()
    res = plan_navigation(points, start=start, end=end, params=params, progress=progress)
    checks, extra = _checks(res, start, end)
    kinds = [c.kind for c in res.clusters]
    g, route = res.graph, res.route
    metrics = {
        "route_length_m": route.length,
        "route_lower_bound_m": route.lower_bound,
        "deadhead_m": route.deadhead,
        "cluster_count": float(len(res.clusters)),
        "bar_count": float(kinds.count("bar")),
        "cross_count": float(kinds.count("cross")),
        "graph_vertices": float(g.number_of_nodes()),
        "graph_edges": float(g.number_of_edges()),
        "points_input": float(res.counts.get("input", len(points))),
        "points_processed": float(len(res.points)),
        "paths_ok": float(sum(e.ok for e in res.edge_paths)),
        "route_edges": float(len(route.edges)),
        **extra,
        **{k.removesuffix("_s") + "_time_s": v for k, v in res.timings_s.items()},
        "planning_time_s": time.perf_counter() - t0,
    }
    return PlanResult(
        summary=json_safe(_summary(res)), arrays=_arrays(res), checks=checks, metrics=metrics
    )


def _footprint(params: NavigationParams) -> Footprint:
    return Footprint(
        params.footprint_length_m,
        params.footprint_width_m,
        params.footprint_center_x_m,
        params.footprint_center_y_m,
    )


def _checks(
    res: NavigationResult, start: int | None, end: int | None
) -> tuple[list[Check], dict[str, float]]:
    """The plan's checks and the metrics they measure (``bars_covered``,
    ``poses_on_steel_fraction``)."""
    g, route, params = res.graph, res.route, res.params
    bars = [c.id for c in res.clusters if c.kind == "bar"]
    covered = bars_covered(bars, [g.edges[u, v]["clusters"][0] for u, v, _ in route.edges])
    checks = [check_ge("bars_covered", covered, len(bars), "bars on the route", "")]
    # the exact footprint test, not Alg. 6's sampled points used while planning
    poses = [e.poses for e in res.edge_paths if len(e.poses)]
    report = poses_on_steel(poses, [c.boundary for c in res.clusters], _footprint(params))
    frac, first, n_poses = report.fraction, report.first_off, report.n_poses
    checks.append(
        Check(
            name="poses_on_steel",
            passed=frac >= 1.0,
            value=frac,
            limit=1.0,
            message=f"{frac:.2%} of {n_poses} driven poses (and the area swept between them) "
            "keep the footprint on steel"
            + (
                ""
                if first is None
                else f"; first off at x={first[0]:.3f} m, y={first[1]:.3f} m, "
                f"yaw={np.degrees(first[2]):.0f}°"
            ),
        )
    )
    if poses and params.plan_paths:
        slide = sum(int(wheel_steps(x).sideways.sum()) for x in poses)
        checks.append(
            Check(
                name="wheel_motion",
                passed=slide == 0,
                value=float(slide),
                limit=0.0,
                message=(
                    "every step is a turn in place or a straight drive along the heading"
                    if slide == 0
                    else f"{slide} steps slide sideways or turn while driving: the "
                    f"'{params.motion_model}' paths cannot be driven by the ARA's "
                    "differential wheels"
                ),
            )
        )
    if params.plan_paths:
        n_ok = sum(e.ok for e in res.edge_paths)
        first_bad = next((e.message for e in res.edge_paths if not e.ok), "")
        checks.append(
            Check(
                name="paths_found",
                passed=n_ok == len(res.edge_paths),
                value=float(n_ok),
                limit=float(len(res.edge_paths)),
                message=f"{n_ok}/{len(res.edge_paths)} route edges have an on-steel path"
                + (f"; first failure: {first_bad}" if first_bad else ""),
            )
        )
    want = (start if start is not None else res.start, end if end is not None else res.end)
    got = (route.vertices[0], route.vertices[-1])
    checks.append(
        Check(
            name="route_endpoints",
            passed=got == want,
            value=f"{got[0]}→{got[1]}",
            limit=f"{want[0]}→{want[1]}",
            message=f"route runs from vertex {got[0]} to vertex {got[1]}",
        )
    )
    return checks, {"bars_covered": float(covered), "poses_on_steel_fraction": frac}


def _summary(res: NavigationResult) -> dict[str, Any]:
    """The plane frame, footprint, clusters, graph, route and per-edge paths
    as the scene drawer and the wheel compiler read them."""
    g, route, frame, params = res.graph, res.route, res.frame, res.params
    return {
        "start": res.start,
        "end": res.end,
        "frame": {
            "origin": frame.origin.tolist(),
            "e1": frame.e1.tolist(),
            "e2": frame.e2.tolist(),
            "normal": frame.normal.tolist(),
        },
        "footprint": {
            "length_m": params.footprint_length_m,
            "width_m": params.footprint_width_m,
            "center_x_m": params.footprint_center_x_m,
            "center_y_m": params.footprint_center_y_m,
        },
        "start_pose": (
            [float(x) for x in res.edge_paths[0].poses[0]]
            if res.edge_paths and len(res.edge_paths[0].poses)
            else None
        ),
        "motion_model": params.motion_model,
        "preprocess": {
            "crop_box_m": params.crop_box_m,
            "passthrough_m": {
                axis: getattr(params, f"passthrough_{axis}_m") for axis in ("x", "y", "z")
            },
            "counts": dict(res.counts),
        },
        "clusters": [
            {
                "id": c.id,
                "kind": c.kind,
                "n_points": c.n_points,
                "centre": frame.lift(c.centre)[0].tolist(),
                "length_m": c.length_m,
                "width_m": c.width_m,
                "boundary": np.round(frame.lift(c.boundary), 5).tolist(),
            }
            for c in res.clusters
        ],
        "graph": {
            "nodes": [
                {
                    "id": int(v),
                    "pos": list(g.nodes[v]["pos"]),
                    "kind": g.nodes[v]["kind"],
                    "degree": g.degree(v),
                }
                for v in sorted(g.nodes)
            ],
            "edges": [
                {
                    "u": int(u),
                    "v": int(v),
                    "weight_m": d["weight"],
                    "clusters": list(d["clusters"]),
                    "kind": d["kind"],
                }
                for u, v, d in g.edges(data=True)
            ],
        },
        "route": {
            "vertices": [vertex_id(v) for v in route.vertices],
            "edges": [[vertex_id(u), vertex_id(v)] for u, v, _ in route.edges],
            "length_m": route.length,
            "lower_bound_m": route.lower_bound,
            "deadhead_m": route.deadhead,
            "method": route.method,
        },
        "paths": [
            {"u": e.u, "v": e.v, "ok": e.ok, "poses": len(e.poses), "message": e.message}
            for e in res.edge_paths
        ],
        "segmentation": {k: v for k, v in res.segmentation_info.items() if not isinstance(v, list)},
    }


def _arrays(res: NavigationResult) -> dict[str, np.ndarray]:
    """The processed cloud and its labels, and the driven poses of every
    route edge stacked (``path_edge``: the route edge of each pose)."""
    paths = [e for e in res.edge_paths if len(e.poses)]
    path_xyz = np.vstack([res.frame.lift(e.poses[:, :2]) for e in paths]) if paths else None
    return {
        "points": res.points.astype(np.float32),
        "labels": res.labels.astype(np.int32),
        "path_xyz": (np.zeros((0, 3)) if path_xyz is None else path_xyz).astype(np.float64),
        "path_yaw": (
            np.concatenate([e.poses[:, 2] for e in paths]) if paths else np.zeros(0)
        ).astype(np.float64),
        "path_edge": (
            np.concatenate(
                [np.full(len(e.poses), k) for k, e in enumerate(res.edge_paths) if len(e.poses)]
            )
            if paths
            else np.zeros(0)
        ).astype(np.int32),
        "path_poses": (np.vstack([e.poses for e in paths]) if paths else np.zeros((0, 3))).astype(
            np.float64
        ),
    }
