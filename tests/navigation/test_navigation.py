"""plan_navigation end to end: paths on steel, determinism, progress, bad input."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import shapely

from planners.errors import (
    CancelledError,
    EmptyInputError,
    InfeasibleError,
    InvalidInputError,
    UnknownVertexError,
)
from planners.navigation import NavigationParams, plan_navigation
from planners.navigation.pibc import footprint_points, project_footprint

from ._shared import SMALL_ROBOT, structure, with_paths


def _steel(res) -> shapely.Geometry:
    """Union of the cluster boundary polygons: the exact reference for 'on steel'."""
    return shapely.union_all(
        [shapely.Polygon(c.boundary).buffer(0) for c in res.clusters if len(c.boundary) >= 3]
    )


@pytest.mark.parametrize(("shape", "seed"), [("l", 0), ("k", 1), ("i", 2)])
def test_paths_stay_on_steel(shape: str, seed: int) -> None:
    res = with_paths(shape, seed)
    assert len(res.edge_paths) == len(res.route.edges)
    assert res.paths_ok, [p.message for p in res.edge_paths if not p.ok]
    p = res.params
    foot = footprint_points(
        p.footprint_length_m,
        p.footprint_width_m,
        center_x_m=p.footprint_center_x_m,
        spacing_m=p.footprint_spacing_m,
    )
    steel = _steel(res)
    res_m = p.rrt_resolution_m
    prev = None
    for ep, (u, v, _) in zip(res.edge_paths, res.route.edges, strict=True):
        assert (ep.u, ep.v) == (u, v)
        pts = project_footprint(ep.poses, foot).reshape(-1, 2)
        inside = shapely.contains_xy(steel, pts[:, 0], pts[:, 1])
        assert inside.mean() > 0.999, inside.mean()  # exact test, independent of PIBC
        step = np.hypot(*np.diff(ep.poses[:, :2], axis=0).T)
        assert step.max() <= res_m + 1e-9
        if prev is not None:
            assert np.allclose(ep.poses[0], prev)  # continuous from edge to edge
        prev = ep.poses[-1]
        # Each path ends near its edge's end vertex (leaves: within a footprint).
        end = np.array(res.graph.nodes[v]["pos2d"])
        assert np.linalg.norm(ep.poses[-1, :2] - end) <= 0.5 * p.footprint_length_m + 0.02
    lifted = res.path_xyz(0)
    assert lifted.shape == (len(res.edge_paths[0].poses), 3)


def test_same_input_same_output() -> None:
    pts = structure("t", 0).points
    params = NavigationParams(**SMALL_ROBOT)
    a = plan_navigation(pts, params=params)
    b = plan_navigation(pts.copy(), params=params)
    assert np.array_equal(a.points, b.points) and np.array_equal(a.labels, b.labels)
    assert a.route.edges == b.route.edges and a.route.length == b.route.length
    assert len(a.edge_paths) == len(b.edge_paths)
    for x, y in zip(a.edge_paths, b.edge_paths, strict=True):
        assert np.array_equal(x.poses, y.poses)


def test_start_end_progress_and_timings() -> None:
    pts = structure("i", 0).points
    base = NavigationParams(plan_paths=False)
    first = plan_navigation(pts, params=base)
    g = first.graph
    a, b = sorted(g.nodes)[0], sorted(g.nodes)[-1]
    calls: list[tuple[float, str]] = []
    res = plan_navigation(
        pts, start=a, end=b, params=base, progress=lambda f, s: calls.append((f, s))
    )
    assert res.route.vertices[0] == a and res.route.vertices[-1] == b
    fr = [f for f, _ in calls]
    assert fr == sorted(fr) and fr[0] == 0.0 and fr[-1] == 1.0
    stages = [s for _, s in calls]
    for name in ("preprocess", "segmentation", "boundaries", "graph", "route", "done"):
        assert name in stages
    assert set(res.timings_s) == {
        "preprocess_s",
        "segmentation_s",
        "boundaries_s",
        "graph_s",
        "route_s",
        "paths_s",
    }
    assert all(t >= 0 for t in res.timings_s.values())
    # Closed route: start == end; string ids from REST are accepted.
    closed = plan_navigation(pts, start=str(a), end=str(a), params=base)
    assert closed.route.vertices[0] == closed.route.vertices[-1] == a


def test_cancel_propagates() -> None:
    def cancel(fraction: float, stage: str) -> None:
        if stage == "graph":
            raise CancelledError("operator cancelled")

    with pytest.raises(CancelledError, match="operator"):
        plan_navigation(
            structure("l", 0).points, params=NavigationParams(plan_paths=False), progress=cancel
        )


def test_bad_input() -> None:
    pts = structure("l", 0).points
    with pytest.raises(EmptyInputError, match="empty"):
        plan_navigation(np.zeros((0, 3)))
    with pytest.raises(InvalidInputError, match=r"\(N, 3\)"):
        plan_navigation(pts[:, :2])
    bad = pts.copy()
    bad[5, 1] = np.nan
    with pytest.raises(InvalidInputError, match="NaN"):
        plan_navigation(bad)
    rng = np.random.default_rng(0)
    with pytest.raises(InfeasibleError, match="no structure plane"):
        plan_navigation(
            rng.uniform(-0.4, 0.4, (3000, 3)), params=NavigationParams(min_plane_points=2000)
        )
    with pytest.raises(UnknownVertexError, match="start vertex 999"):
        plan_navigation(pts, start=999, params=NavigationParams(plan_paths=False))
    with pytest.raises(UnknownVertexError, match="end vertex 'x'"):
        plan_navigation(pts, end="x", params=NavigationParams(plan_paths=False))
    with pytest.raises(InvalidInputError, match="segmentation"):
        plan_navigation(pts, params=NavigationParams(segmentation="gmm"))
    with pytest.raises(InvalidInputError, match="voxel_m"):
        plan_navigation(pts, params=NavigationParams(voxel_m=-0.01))
    with pytest.raises(InvalidInputError, match="route_method"):
        plan_navigation(pts, params=NavigationParams(route_method="fast"))


def test_ara_footprint_does_not_fit_narrow_bars() -> None:
    """The ARA's 0.68 × 0.16 m mobile footprint is wider than every synthetic
    flange (60–150 mm): no pose is on steel, and each edge says so."""
    res = plan_navigation(structure("l", 0).points)
    assert res.params.footprint_width_m == 0.16
    assert not res.paths_ok
    assert all("footprint" in p.message for p in res.edge_paths)
    assert res.route.length > 0  # the route itself is still planned


def test_thesis_segmentation_through_the_entry_point() -> None:
    pts = structure("l", 1).points
    res = plan_navigation(pts, params=NavigationParams(segmentation="thesis", plan_paths=False))
    assert res.segmentation_info["n_clusters"] >= 2
    assert {c.kind for c in res.clusters} <= {"bar", "cross"}
    res2 = plan_navigation(pts, params=dataclasses.replace(res.params))
    assert np.array_equal(res.labels, res2.labels)


def test_passthrough_window_may_be_none() -> None:
    """``passthrough_*_m`` is typed ``tuple | None`` (None was refused
    as "must be a positive number"); None means no window on that axis, so a
    cloud shifted far outside the default window plans as the original does."""
    pts = structure("l", 0).points
    shifted = pts + [0.0, 18.0, 0.0]  # y ≈ 18 m, as the pc2beam crop sits
    with pytest.raises(EmptyInputError, match="pass-through"):
        plan_navigation(shifted, params=NavigationParams(plan_paths=False))
    base = plan_navigation(pts, params=NavigationParams(plan_paths=False))
    res = plan_navigation(shifted, params=NavigationParams(plan_paths=False, passthrough_y_m=None))
    assert res.graph.number_of_nodes() == base.graph.number_of_nodes()
    assert res.graph.number_of_edges() == base.graph.number_of_edges()
    for bad in ((1.0, -1.0), (0.0, float("nan")), (0.0,), "wide"):
        with pytest.raises(InvalidInputError, match="passthrough_x_m"):
            NavigationParams(passthrough_x_m=bad).validated()  # type: ignore[arg-type]
