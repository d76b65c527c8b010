"""planners.structure.tiles: a scan modelled in overlapping tiles gives the
members of the whole-cloud model, a chord crossing tile borders comes out
whole, tiles are bounded and partition the extent, the mapper runs the
tiles (the builtin map, a recording one, a Dask cluster)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from planners.structure import StructureParams, model_structure, model_structure_tiled
from planners.structure.model import StructureModel
from planners.structure.synthetic import make_scan, match_members
from planners.structure.tiles import (
    TileJob,
    clip_polygon,
    clip_segment,
    horizontal_frame,
    model_tile,
    owning_tiles,
    plan_tiles,
)

#: three tiles over the 20 m Warren truss of seed 0 (two borders)
TILED = StructureParams(tile_above_points=10, tile_m=10.0, overlap_m=5.0)


class Recording:
    """A mapper like ``map`` that records what it was given."""

    def __init__(self) -> None:
        self.fns: list[Any] = []
        self.jobs: list[TileJob] = []

    def __call__(self, fn: Any, items: Any) -> Any:
        self.fns.append(fn)
        for job in items:
            self.jobs.append(job)
            yield fn(job)


@pytest.fixture(scope="module")
def scan() -> Any:
    return make_scan("warren", 0, spacing_m=0.02)


@pytest.fixture(scope="module")
def whole(scan: Any) -> StructureModel:
    return model_structure(scan.points)


@pytest.fixture(scope="module")
def recorded(scan: Any) -> tuple[StructureModel, Recording]:
    rec = Recording()
    return model_structure(scan.points, params=TILED, mapper=rec), rec


def _end_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Largest end point distance of two axes, either way round."""
    return min(
        float(np.linalg.norm(a - b, axis=1).max()), float(np.linalg.norm(a - b[::-1], axis=1).max())
    )


def test_tiled_gives_the_whole_clouds_members(whole: StructureModel, recorded: Any) -> None:
    tiled, _ = recorded
    assert tiled.params["n_tiles"] == 3
    assert len(tiled.members) == len(whole.members) == 18
    for m in whole.members:
        assert min(_end_distance(m.axis, n.axis) for n in tiled.members) <= 0.01
    # one label per point, the members' points counted from them
    assert len(tiled.labels) == len(whole.labels)
    counts = np.bincount(tiled.labels[tiled.labels >= 0], minlength=len(tiled.members))
    assert [m.n_points for m in tiled.members] == counts.tolist()
    assert len(tiled.joints) == len(whole.joints)
    agree = np.mean((tiled.labels >= 0) == (whole.labels >= 0))
    assert agree > 0.99


def test_a_chord_across_two_borders_is_one_member(scan: Any, recorded: Any) -> None:
    tiled, _ = recorded
    truth = np.array([t.axis for t in scan.members])
    depths = [t.section.h for t in scan.members]
    match = match_members(truth, depths, np.array([m.axis for m in tiled.members]))
    assert match.recall == 1.0 and match.precision == 1.0
    for t in (t for t in scan.members if t.role == "chord"):
        on = [
            m
            for m in tiled.members
            if abs(float(m.direction @ (t.axis[1] - t.axis[0]))) > 0.99 * t.length_m
            and _end_distance(m.axis, t.axis) < 1.0
        ]
        assert len(on) == 1
        assert abs(on[0].length_m - t.length_m) < 0.05
        assert on[0].faces  # its faces come from every tile it crosses


def test_the_mapper_runs_the_tiles(recorded: Any) -> None:
    tiled, rec = recorded
    assert rec.fns == [model_tile]
    assert [j.index for j in rec.jobs] == [0, 1, 2]
    # each point owned by exactly one tile's core
    assert sum(int(j.core.sum()) for j in rec.jobs) == len(tiled.labels)
    assert all(j.params.spacing_m == tiled.spacing_m for j in rec.jobs)


def test_deterministic(scan: Any, recorded: Any) -> None:
    tiled, _ = recorded
    again = model_structure_tiled(scan.points, params=TILED)  # the builtin map
    assert np.array_equal(again.labels, tiled.labels)
    for a, b in zip(again.members, tiled.members, strict=True):
        assert np.array_equal(a.axis, b.axis) and a.profile == b.profile


def test_small_clouds_are_not_tiled(scan: Any, whole: StructureModel) -> None:
    assert "n_tiles" not in whole.params

    def refuse(fn: Any, items: Any) -> Any:
        raise AssertionError("no tiles expected")

    pts = scan.points[:20_000]
    assert "n_tiles" not in model_structure(pts, mapper=refuse).params


def test_tiles_are_bounded() -> None:
    rng = np.random.default_rng(3)
    pts = np.column_stack(
        [rng.uniform(0, 100, 60_000), rng.uniform(0, 8, 60_000), np.zeros(60_000)]
    )
    pts[:30_000, 0] *= 0.2  # a dense first fifth
    frame = horizontal_frame(pts)
    ab = frame.ab(pts)
    tiles = plan_tiles(ab, tile_m=30.0, overlap_m=2.0, max_points=8_000)
    assert len(tiles) > 4
    for t in tiles:
        assert int(t.in_outer(ab).sum()) <= 8_000
    owner = owning_tiles(ab, tiles)
    assert (owner >= 0).all()


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(1, 400),
    length=st.floats(0.0, 300.0),
    width=st.floats(0.0, 60.0),
    yaw=st.floats(0.0, 2 * math.pi),
    tile_m=st.floats(1.0, 80.0),
    overlap_m=st.floats(0.0, 10.0),
    max_points=st.integers(20, 500),
    seed=st.integers(0, 1000),
)
def test_tile_geometry(
    n: int,
    length: float,
    width: float,
    yaw: float,
    tile_m: float,
    overlap_m: float,
    max_points: int,
    seed: int,
) -> None:
    rng = np.random.default_rng(seed)
    local = np.column_stack([rng.uniform(0, length, n), rng.uniform(0, width, n)])
    rot = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
    xy = local @ rot.T + [5e5, 5.4e6]
    pts = np.column_stack([xy, rng.uniform(0, 5, n)])
    frame = horizontal_frame(pts)
    ab = frame.ab(pts)
    tiles = plan_tiles(ab, tile_m, overlap_m, max_points)
    in_core = np.array([t.in_core(ab) for t in tiles])
    in_outer = np.array([t.in_outer(ab) for t in tiles])
    # the cores partition the points; every point is in its core's tile
    assert (in_core.sum(axis=0) == 1).all()
    assert (in_outer | ~in_core).all()
    owner = owning_tiles(ab, tiles)
    assert np.array_equal(owner, np.argmax(in_core, axis=0))
    # a tile over the bound has a core no wider than the overlap (it cannot be split)
    for t, on in zip(tiles, in_outer, strict=True):
        if on.sum() > max_points:
            a0, a1, b0, b1 = t.core
            wa = min(a1, ab[:, 0].max()) - max(a0, ab[:, 0].min())
            wb = min(b1, ab[:, 1].max()) - max(b0, ab[:, 1].min())
            assert max(wa, wb) <= max(overlap_m, tile_m / 64) + 1e-9


def test_clipping() -> None:
    planes = [(np.array([1.0, 0.0]), 0.0), (np.array([-1.0, 0.0]), 1.0)]  # 0 ≤ x ≤ 1
    seg = clip_segment(np.array([[-1.0, 0.0], [3.0, 4.0]]), planes)
    assert seg is not None and np.allclose(seg, [[0.0, 1.0], [1.0, 2.0]])
    assert clip_segment(np.array([[2.0, 0.0], [3.0, 0.0]]), planes) is None
    square = np.array([[-1.0, -1.0], [2.0, -1.0], [2.0, 1.0], [-1.0, 1.0]])
    out = clip_polygon(square, planes)
    assert np.allclose(np.sort(out[:, 0]), [0, 0, 1, 1])


def _tiled_on_a_worker(points: np.ndarray) -> StructureModel:
    """A plan's structure step as it runs on a Dask worker."""
    from server.structure_tiles import dask_mapper

    return model_structure(points, params=TILED, mapper=dask_mapper())


def test_tiles_on_a_dask_cluster(scan: Any, recorded: Any) -> None:
    distributed = pytest.importorskip("distributed")
    tiled, _ = recorded
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        on_worker = client.submit(_tiled_on_a_worker, scan.points, pure=False).result()
        from server.structure_tiles import dask_mapper

        via_client = model_structure(scan.points, params=TILED, mapper=dask_mapper(client))
    for got in (on_worker, via_client):
        assert np.array_equal(got.labels, tiled.labels)
        assert [m.axis.tolist() for m in got.members] == [m.axis.tolist() for m in tiled.members]


def test_the_inspection_plan_runs_its_tiles_through_the_given_mapper(scan: Any) -> None:
    """``plan_inspection_result(mapper=…)`` reaches the structure model: a
    cloud past the tiling threshold runs its tiles through that mapper (the
    ``ara.inspect`` kind passes the server's pool / Dask mapper)."""
    from planners.inspection.inspect_plan import plan_inspection_result

    rec = Recording()
    res = plan_inspection_result(scan.points, structure=TILED, mapper=rec)
    assert rec.fns == [model_tile] and len(rec.jobs) == 3
    assert res.summary["members"], res.summary.keys()
