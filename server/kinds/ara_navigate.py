"""``ara.navigate``: inspection route of the ARA robot over a steel-bar structure
(seed 000, Ch. 4: segmentation Alg. 3, NCBE Alg. 1, graph Alg. 4, VOCPP
Alg. 5, PIBC Alg. 6 + RRT; see docs/navigation.md).

The cloud is a stored one (``cloud_id``) or a synthetic sample structure
(``sample``: cross, t, l, k, i, warren, pratt).

Which points must stay on steel (Alg. 6's projected robot points) is the
``footprint`` choice.  ``contact_patch`` (default): the magnetic-wheel
contact patch of the driving foot, 0.08 × 0.025 m (chosen; the trailing foot
follows the same track) — the part that must grip the flange, and one that
fits the samples' 60–150 mm flanges.  ``mobile_body``: the whole mobile-mode
body rectangle of robots/ara/params.toml ``[mobile_footprint]`` (0.68 ×
0.16 m), which no 60–150 mm flange can carry, so such plans are rejected by
their ``paths_found`` check — the honest answer for a robot that must not
overhang.  Explicit ``footprint_*_m`` values override both.
"""

from __future__ import annotations

import time
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, Field

from planners.errors import InvalidInputError
from planners.navigation import NavigationParams, NavigationResult, plan_navigation
from planners.navigation.pibc import footprint_points, point_in_polygon, project_footprint
from planners.navigation.synthetic import SAMPLES, SHAPES
from server.kinds.base import Check, JobContext, KindOutput, PlanKind, check_ge


class AraNavigateParams(BaseModel):
    """Cloud, route end points and method choices of an ARA navigation plan."""

    cloud_id: str | None = Field(
        None, description="id of a stored cloud (POST /clouds); robot frame, metres"
    )
    sample: str = Field(
        "cross", description=f"sample structure when no cloud_id: one of {', '.join(SHAPES)}"
    )
    sample_seed: int = Field(0, ge=0, description="generator seed of the sample structure")
    start: int | None = Field(None, ge=0, description="start vertex id (None: a leaf at one end)")
    end: int | None = Field(
        None, ge=0, description="end vertex id (None: the leaf farthest from the other)"
    )
    segmentation: Literal["default", "thesis"] = Field(
        "default",
        description="'default' strip-based segmentation or the seed's Alg. 3 (EM-GMM + Eq. 4.1)",
    )
    route_method: Literal["exact", "thesis"] = Field(
        "exact", description="'exact' minimum T-join postman route or the seed's Alg. 5 as printed"
    )
    pibc_method: Literal["angular", "thesis"] = Field(
        "angular",
        description="boundary check: exact ray-bracket test or the seed's Alg. 6 as printed",
    )
    plan_paths: bool = Field(True, description="plan the per-edge RRT-Connect robot paths")
    footprint: Literal["contact_patch", "mobile_body"] = Field(
        "contact_patch",
        description="points that must stay on steel: the driving foot's wheel contact patch "
        "or the whole mobile-mode body ([mobile_footprint])",
    )
    footprint_length_m: float | None = Field(
        None, gt=0, description="robot footprint length (None: from `footprint`)"
    )
    footprint_width_m: float | None = Field(
        None, gt=0, description="robot footprint width (None: ARA [mobile_footprint])"
    )
    footprint_center_x_m: float | None = Field(
        None, description="footprint centre ahead of the base frame (None: ARA [mobile_footprint])"
    )
    voxel_m: float = Field(0.01, gt=0, le=0.1, description="voxel grid edge of the down-sampling")
    seed: int = Field(0, ge=0, description="seed of RANSAC and the RRT samples")


def validate(p: AraNavigateParams) -> None:
    if p.cloud_id is None and p.sample not in SAMPLES:
        raise InvalidInputError(f"unknown sample {p.sample!r}; samples: {', '.join(SHAPES)}")


#: The driving foot's magnetic-wheel contact patch (chosen; see the module doc).
CONTACT_PATCH = {"length_m": 0.08, "width_m": 0.025, "center_x_m": 0.0, "center_y_m": 0.0}


def _footprint(p: AraNavigateParams) -> dict[str, float]:
    from robots import load_robot

    fp = (
        load_robot("ara").params["mobile_footprint"]
        if p.footprint == "mobile_body"
        else CONTACT_PATCH
    )
    return {
        "footprint_length_m": float(p.footprint_length_m or fp["length_m"]),
        "footprint_width_m": float(p.footprint_width_m or fp["width_m"]),
        "footprint_center_x_m": float(
            fp["center_x_m"] if p.footprint_center_x_m is None else p.footprint_center_x_m
        ),
        "footprint_center_y_m": float(fp.get("center_y_m", 0.0)),
    }


def _checks(res: NavigationResult, p: AraNavigateParams) -> tuple[list[Check], dict[str, float]]:
    g, route = res.graph, res.route
    bars = [c.id for c in res.clusters if c.kind == "bar"]
    driven = {g.edges[u, v]["clusters"][0] for u, v, _ in route.edges}
    covered = sum(b in driven for b in bars)
    checks = [
        check_ge("bars_covered", covered, len(bars), "bars on the route", ""),
    ]
    # Every planned pose on steel, verified by exact ray casting on the boundary
    # polygons (independent of the PIBC used while planning).
    params = res.params
    foot = footprint_points(
        params.footprint_length_m,
        params.footprint_width_m,
        center_x_m=params.footprint_center_x_m,
        center_y_m=params.footprint_center_y_m,
        spacing_m=params.footprint_spacing_m,
    )
    poses = [e.poses for e in res.edge_paths if len(e.poses)]
    if poses:
        pts = project_footprint(np.vstack(poses), foot).reshape(-1, 2)
        inside = np.zeros(len(pts), dtype=bool)
        for c in res.clusters:
            if len(c.boundary) >= 3:
                lo, hi = c.boundary.min(axis=0), c.boundary.max(axis=0)
                box = np.nonzero(~inside & np.all((pts >= lo) & (pts <= hi), axis=1))[0]
                inside[box] |= point_in_polygon(pts[box], c.boundary)
        frac = float(inside.reshape(-1, len(foot)).all(axis=1).mean())
    else:
        frac = 1.0
    checks.append(
        Check(
            name="poses_on_steel",
            passed=frac >= 1.0,
            value=frac,
            limit=1.0,
            message=f"{frac:.2%} of {sum(len(x) for x in poses)} planned poses keep every footprint point on steel",
        )
    )
    if p.plan_paths:
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
    want = (p.start if p.start is not None else res.start, p.end if p.end is not None else res.end)
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


def run(p: AraNavigateParams, ctx: JobContext) -> KindOutput:
    t0 = time.perf_counter()
    validate(p)
    ctx.progress(0.0, "loading cloud")
    points = ctx.load_cloud(p.cloud_id) if p.cloud_id else SAMPLES[p.sample](p.sample_seed)
    params = NavigationParams(
        segmentation=p.segmentation,
        route_method=p.route_method,
        pibc_method=p.pibc_method,
        plan_paths=p.plan_paths,
        voxel_m=p.voxel_m,
        seed=p.seed,
        **_footprint(p),
    )
    res = plan_navigation(points, start=p.start, end=p.end, params=params, progress=ctx.progress)
    checks, extra = _checks(res, p)
    g, route, frame = res.graph, res.route, res.frame
    nodes = sorted(g.nodes)
    paths = [e for e in res.edge_paths if len(e.poses)]
    path_xyz = (
        np.vstack([res.frame.lift(e.poses[:, :2]) for e in paths]) if paths else np.zeros((0, 3))
    )
    path_yaw = np.concatenate([e.poses[:, 2] for e in paths]) if paths else np.zeros(0)
    path_edge = (
        np.concatenate(
            [np.full(len(e.poses), k) for k, e in enumerate(res.edge_paths) if len(e.poses)]
        )
        if paths
        else np.zeros(0)
    )
    result: dict[str, Any] = {
        "start": res.start,
        "end": res.end,
        "frame": {
            "origin": frame.origin.tolist(),
            "e1": frame.e1.tolist(),
            "e2": frame.e2.tolist(),
            "normal": frame.normal.tolist(),
        },
        "footprint": {k.removeprefix("footprint_"): v for k, v in _footprint(p).items()},
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
                for v in nodes
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
            "vertices": [int(v) for v in route.vertices],
            "edges": [[int(u), int(v)] for u, v, _ in route.edges],
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
    kinds = [c.kind for c in res.clusters]
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
    return KindOutput(
        result=result,
        arrays={
            "points": res.points.astype(np.float32),
            "labels": res.labels.astype(np.int32),
            "path_xyz": path_xyz.astype(np.float64),
            "path_yaw": path_yaw.astype(np.float64),
            "path_edge": path_edge.astype(np.int32),
        },
        checks=checks,
        metrics=metrics,
    )


#: Wheel-command constants (chosen: slow inspection speed, servo-class turn rate).
DRIVE_SPEED_M_S = 0.05
TURN_RATE_RAD_S = 0.5


def compile_program(plan: Any) -> list[dict[str, Any]]:
    """Differential-drive wheel commands along the route.

    The ARA's wheels cannot slide sideways as the (x, y, yaw) per-edge paths
    may, so the program drives the route's graph edges — which follow each
    bar's centre line (Alg. 4) — straight, turns in place only at vertices
    and by at most 90° (a U-turn at a bar end is driven as a reversal).  The
    motion the wheels will really make is replayed here, and every sampled
    pose — including each in-place turn — must keep the footprint on steel
    (exact ray casting on the cluster boundaries); if not, compilation fails
    and the plan's ``command_program`` check says where.
    """
    from robots import load_robot
    from server.kinds.programs import as_dicts, differential_drive

    frame = plan.result["frame"]
    origin, e1, e2 = (np.asarray(frame[k], dtype=float) for k in ("origin", "e1", "e2"))
    pos = {n["id"]: np.asarray(n["pos"], dtype=float) for n in plan.result["graph"]["nodes"]}
    walk = plan.result["route"]["vertices"]
    if len(walk) < 2:
        raise ValueError("the route has no edges, so there is nothing to drive")
    xyz = np.array([pos[v] for v in walk])
    xy = np.stack([(xyz - origin) @ e1, (xyz - origin) @ e2], axis=1)
    first = xy[1] - xy[0]
    heading0 = float(np.arctan2(first[1], first[0]))  # start facing along the first bar
    track = float(load_robot("ara").params["foot"]["wheel_track_m"])
    cmds = differential_drive(
        xy,
        track_m=track,
        speed_m_s=DRIVE_SPEED_M_S,
        turn_rate_rad_s=TURN_RATE_RAD_S,
        heading_rad=heading0,
        allow_reverse=True,
    )
    fp = plan.result["footprint"]
    foot = footprint_points(
        fp["length_m"],
        fp["width_m"],
        center_x_m=fp["center_x_m"],
        center_y_m=fp["center_y_m"],
        spacing_m=0.01,
    )
    polys = [
        np.stack([(b - origin) @ e1, (b - origin) @ e2], axis=1)
        for b in (np.asarray(c["boundary"], dtype=float) for c in plan.result["clusters"])
    ]
    poses = replay_differential_drive(xy[0], heading0, cmds, track)
    pts = project_footprint(poses, foot)
    flat = pts.reshape(-1, 2)
    on = np.zeros(len(flat), dtype=bool)
    for poly in polys:
        on |= point_in_polygon(flat, poly)
    ok = on.reshape(pts.shape[:2]).all(axis=1)
    if not ok.all():
        bad = poses[int(np.argmin(ok))]
        raise ValueError(
            f"{int((~ok).sum())} of {len(ok)} poses the wheels will drive put the footprint "
            f"off the steel (first at x={bad[0]:.3f} m, y={bad[1]:.3f} m, "
            f"yaw={np.degrees(bad[2]):.0f}°): an in-place turn or a straight run that the "
            "holonomic path avoided"
        )
    return as_dicts(cmds)


def replay_differential_drive(
    xy0: np.ndarray, heading: float, cmds: list[Any], track_m: float, step_m: float = 0.01
) -> np.ndarray:
    """(P,3) poses sampled along what the wheel commands make the robot do."""
    from robots.protocol.commands import WheelSpeeds

    x, y, th = float(xy0[0]), float(xy0[1]), heading
    out = [(x, y, th)]
    for c in cmds:
        if not isinstance(c, WheelSpeeds):
            continue
        vl, vr = c.speeds_m_s[0], c.speeds_m_s[1]
        v, w = (vl + vr) / 2.0, (vr - vl) / track_m
        n = max(1, int(np.ceil(max(abs(v) * c.duration_s / step_m, abs(w) * c.duration_s / 0.05))))
        dt = c.duration_s / n
        for _ in range(n):
            th += w * dt
            x += v * np.cos(th) * dt
            y += v * np.sin(th) * dt
            out.append((x, y, th))
    return np.array(out)


def _draw(ctx: Any, plan: Any) -> None:
    from server.scene.ara_navigate import draw

    draw(ctx, plan)


KIND = PlanKind(
    name="ara.navigate",
    title="ARA: inspection route over a steel-bar structure",
    description=__doc__ or "",
    params_model=AraNavigateParams,
    run=run,
    validate=validate,
    robot="ara",
    samples=dict(SAMPLES),
    draw=_draw,
    compile=compile_program,
)
