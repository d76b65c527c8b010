"""``demo.route``: the shortest route between two vertices of a small graph.

A deliberately small kind that exercises the whole product path — params,
job with progress, checks, stored arrays, scene, approval — without a heavy
planner.  The graph is given in JSON (vertex positions in metres and edges);
edge weights are the Euclidean lengths; the route is Dijkstra's shortest path
(networkx).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from pydantic import Field, model_validator

from planners.postman.shortest_route import (
    build_graph,
    check_endpoints,
    plan_demo_route,
    unit_grid_edges,
)
from server.kinds.base import Coordinate, JobContext, KindOutput, PlanKind, PlanView, StrictParams

#: Longest route limit, metres: a route over every member of a bridge under
#: 2 km, members driven more than once, stays well inside 100 km.
MAX_ROUTE_M = 100_000.0


def _default_nodes() -> dict[str, list[float]]:
    # A 3 × 3 grid of bar crossings, 1 m apart, as a tiny truss.
    return {f"{'abc'[i]}{j}": [float(i), float(j), 0.0] for i in range(3) for j in range(3)}


def _default_edges() -> list[tuple[str, str]]:
    return [(str(u), str(v)) for u, v in unit_grid_edges(_default_nodes())]


class DemoRouteParams(StrictParams):
    """Graph, endpoints and limits of a demo route."""

    nodes: dict[str, list[Coordinate]] = Field(
        default_factory=_default_nodes, description="vertex id → [x, y, z] position in metres"
    )
    edges: list[tuple[str, str]] = Field(
        default_factory=_default_edges, description="undirected edges as [u, v] vertex ids"
    )
    start: str = Field("a0", description="start vertex id")
    end: str = Field("c2", description="end vertex id")
    max_length_m: float = Field(
        10.0, gt=0, le=MAX_ROUTE_M, description="longest acceptable route (check)"
    )
    step_delay_s: float = Field(
        0.0,
        ge=0,
        le=2.0,
        description="pause between route steps, to make progress and cancel visible in demos",
    )

    @model_validator(mode="after")
    def _positions_are_xyz(self) -> DemoRouteParams:
        for node, pos in self.nodes.items():
            if len(pos) != 3 or not all(np.isfinite(pos)):
                raise ValueError(f"node {node!r} position must be 3 finite numbers, got {pos}")
        return self


def validate(p: DemoRouteParams) -> None:
    check_endpoints(build_graph(p.nodes, p.edges), p.start, p.end)


def run(p: DemoRouteParams, ctx: JobContext) -> KindOutput:
    r = plan_demo_route(
        p.nodes,
        p.edges,
        p.start,
        p.end,
        max_length_m=p.max_length_m,
        step_delay_s=p.step_delay_s,
        progress=ctx.progress,
    )
    return KindOutput.from_result(r)


#: Differential-drive constants used to turn the route into wheel commands
#: (the ARA robot's mobile mode; values chosen for the demo).
TRACK_M = 0.14
DRIVE_SPEED_M_S = 0.1
TURN_RATE_RAD_S = 0.5


def compile_wheels(plan: PlanView) -> list[dict[str, Any]]:
    """The route as ARA wheel commands: turn in place to each segment's heading,
    drive it straight, stop at the end (robot starts at the first vertex facing +x)."""
    from server.kinds.programs import as_dicts, differential_drive

    xy = plan.array("path_xyz")[:, :2]
    return as_dicts(
        differential_drive(
            xy, track_m=TRACK_M, speed_m_s=DRIVE_SPEED_M_S, turn_rate_rad_s=TURN_RATE_RAD_S
        )
    )


def sample_plane(seed: int) -> np.ndarray:
    """A 2 m × 1 m steel plate seen with 2 mm noise: a quick cloud for demos."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform([0.0, 0.0], [2.0, 1.0], size=(5000, 2))
    z = rng.normal(0.0, 0.002, size=(5000, 1))
    return np.hstack([xy, z])


KIND = PlanKind(
    name="demo.route",
    title="Demo: shortest route on a small graph",
    description=__doc__ or "",
    params_model=DemoRouteParams,
    run=run,
    validate=validate,
    samples={"demo_plane": sample_plane},
    robot="ara",
    compile=compile_wheels,
)
