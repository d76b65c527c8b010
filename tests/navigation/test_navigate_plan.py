"""planners.navigation.navigate_plan: the ``ara.navigate`` entry point's stored
form.  Every check value is recomputed here from the returned
summary and arrays alone (shapely for the footprint, a plain loop for the
wheel steps), the way a reader of the stored plan would."""

from __future__ import annotations

import json
import math
from functools import lru_cache
from typing import Any

import numpy as np
import pytest
import shapely
from shapely.ops import unary_union

from planners.errors import UnknownVertexError
from planners.navigation import NavigationParams
from planners.navigation.navigate_plan import plan_navigation_result
from planners.navigation.synthetic import SAMPLES
from planners.result import PlanResult

#: The driving foot's contact patch (ara.navigate's default footprint).
PATCH = {
    "footprint_length_m": 0.08,
    "footprint_width_m": 0.025,
    "footprint_center_x_m": 0.0,
    "footprint_center_y_m": 0.0,
    "footprint_spacing_m": 0.01,
}
ARRAYS = {
    "points": np.float32,
    "labels": np.int32,
    "path_xyz": np.float64,
    "path_yaw": np.float64,
    "path_edge": np.int32,
    "path_poses": np.float64,
}


@lru_cache(maxsize=8)
def _plan(
    sample: str, motion_model: str = "differential", plan_paths: bool = True, **ends: int
) -> PlanResult:
    params = NavigationParams(motion_model=motion_model, plan_paths=plan_paths, **PATCH)
    return plan_navigation_result(SAMPLES[sample](0), params=params, **ends)


def _strict_json(summary: dict[str, Any]) -> dict[str, Any]:
    back = json.loads(json.dumps(summary, allow_nan=False))
    assert back == summary
    return back


def _to_plane(s: dict[str, Any], xyz: Any) -> np.ndarray:
    f = s["frame"]
    d = np.asarray(xyz, dtype=float).reshape(-1, 3) - f["origin"]
    return np.column_stack([d @ f["e1"], d @ f["e2"]])


def _rectangle(pose: np.ndarray, fp: dict[str, float]) -> shapely.Polygon:
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    hl, hw = fp["length_m"] / 2, fp["width_m"] / 2
    cx, cy = fp["center_x_m"], fp["center_y_m"]
    local = [(cx + a, cy + b) for a, b in ((hl, hw), (-hl, hw), (-hl, -hw), (hl, -hw))]
    return shapely.Polygon([(x + c * u - s * v, y + s * u + c * v) for u, v in local])


def _sideways_steps(poses: np.ndarray, edge: np.ndarray) -> int:
    """Steps within one route edge that are neither a turn in place (≤ 1 µm
    moved) nor a straight drive (≤ 1e-6 rad turned, ≤ 10 µm off the heading)."""
    n = 0
    for k in range(len(poses) - 1):
        if edge[k] != edge[k + 1]:
            continue
        (x0, y0, a0), (x1, y1, a1) = poses[k], poses[k + 1]
        dx, dy = x1 - x0, y1 - y0
        turn = math.hypot(dx, dy) <= 1e-6
        dyaw = abs(math.remainder(a1 - a0, 2 * math.pi))
        lateral = abs(dx * math.sin(a0) - dy * math.cos(a0))
        n += not turn and not (dyaw <= 1e-6 and lateral <= 1e-5)
    return n


def _assert_form(r: PlanResult) -> dict[str, Any]:
    """The summary is strict JSON; arrays, metrics and the checks every plan
    has agree with the summary."""
    s = _strict_json(r.summary)
    a, m = r.arrays, r.metrics
    assert list(a) == list(ARRAYS)
    for name, dtype in ARRAYS.items():
        assert a[name].dtype == dtype, name
    assert a["labels"].shape == (len(a["points"]),)
    fp = {k.removeprefix("footprint_"): v for k, v in PATCH.items() if k != "footprint_spacing_m"}
    assert s["footprint"] == fp
    route, nodes = s["route"], s["graph"]["nodes"]
    assert route["vertices"][0] == s["start"] and route["vertices"][-1] == s["end"]
    assert m["route_length_m"] == route["length_m"] >= route["lower_bound_m"] > 0
    assert m["deadhead_m"] == pytest.approx(route["length_m"] - route["lower_bound_m"])
    assert m["graph_vertices"] == len(nodes) and m["graph_edges"] == len(s["graph"]["edges"])
    assert m["route_edges"] == len(route["edges"]) and m["points_processed"] == len(a["points"])
    kinds = [c["kind"] for c in s["clusters"]]
    assert (m["bar_count"], m["cross_count"]) == (kinds.count("bar"), kinds.count("cross"))
    stages = [v for k, v in m.items() if k.endswith("_time_s") and k != "planning_time_s"]
    assert stages and m["planning_time_s"] >= max(stages)
    checks = {c.name: c for c in r.checks}
    # bars_covered: the bars whose cluster an edge of the route drives on first.
    edge_cluster = {}
    for e in s["graph"]["edges"]:
        edge_cluster[(e["u"], e["v"])] = edge_cluster[(e["v"], e["u"])] = e["clusters"][0]
    driven = {edge_cluster[(u, v)] for u, v in route["edges"]}
    bars = [c["id"] for c in s["clusters"] if c["kind"] == "bar"]
    covered = sum(b in driven for b in bars)
    assert checks["bars_covered"].value == covered == m["bars_covered"]
    assert checks["bars_covered"].limit == len(bars)
    got = f"{route['vertices'][0]}→{route['vertices'][-1]}"
    assert checks["route_endpoints"].value == got
    return s


def _steel(s: dict[str, Any]) -> Any:
    return unary_union([shapely.Polygon(_to_plane(s, c["boundary"])) for c in s["clusters"]])


def test_contact_patch_plan_on_the_t_sample() -> None:
    r = _plan("t")
    s = _assert_form(r)
    a, m = r.arrays, r.metrics
    checks = {c.name: c for c in r.checks}
    assert list(checks) == [
        "bars_covered",
        "poses_on_steel",
        "wheel_motion",
        "paths_found",
        "route_endpoints",
    ]
    assert r.passed, [c.message for c in r.checks if not c.passed]
    poses, edge = a["path_poses"], a["path_edge"]
    assert len(poses) > 10
    # The stacked arrays are the per-edge paths of the summary, in order.
    counts = [p["poses"] for p in s["paths"]]
    assert np.bincount(edge, minlength=len(counts)).tolist() == counts
    assert s["start_pose"] == poses[0].tolist()
    np.testing.assert_array_equal(a["path_yaw"], poses[:, 2])
    np.testing.assert_allclose(_to_plane(s, a["path_xyz"]), poses[:, :2], atol=1e-9)
    f = s["frame"]
    np.testing.assert_allclose((a["path_xyz"] - f["origin"]) @ f["normal"], 0.0, atol=1e-9)
    # poses_on_steel: every pose's footprint rectangle lies on the union of
    # the stored boundaries (rounded to 10 µm in the summary).
    steel = _steel(s).buffer(2e-5)
    assert all(steel.covers(_rectangle(q, s["footprint"])) for q in poses)
    assert checks["poses_on_steel"].value == 1.0 == m["poses_on_steel_fraction"]
    assert f"of {len(poses)} driven poses" in checks["poses_on_steel"].message
    # wheel_motion and paths_found from the arrays and the summary.
    assert checks["wheel_motion"].value == _sideways_steps(poses, edge) == 0.0
    n_ok = sum(p["ok"] for p in s["paths"])
    assert checks["paths_found"].value == n_ok == m["paths_ok"] == len(s["route"]["edges"])
    assert checks["paths_found"].limit == len(s["paths"])
    assert s["motion_model"] == "differential"


def test_holonomic_paths_fail_the_wheel_check_by_the_right_count() -> None:
    r = _plan("t", motion_model="holonomic")
    s = _assert_form(r)
    wheel = next(c for c in r.checks if c.name == "wheel_motion")
    slide = _sideways_steps(r.arrays["path_poses"], r.arrays["path_edge"])
    assert slide > 0 and wheel.value == slide and not wheel.passed and not r.passed
    assert f"{slide} steps slide sideways" in wheel.message
    assert "'holonomic' paths cannot be driven" in wheel.message
    assert s["motion_model"] == "holonomic"


def test_without_paths_only_the_route_and_chosen_end_points() -> None:
    first = _plan("cross", plan_paths=False)
    s = _assert_form(first)
    assert [c.name for c in first.checks] == ["bars_covered", "poses_on_steel", "route_endpoints"]
    assert s["start_pose"] is None and s["paths"] == []
    for name in ("path_xyz", "path_poses"):
        assert first.arrays[name].shape == (0, 3)
    assert first.arrays["path_yaw"].shape == first.arrays["path_edge"].shape == (0,)
    # poses_on_steel over no poses: nothing is driven, so nothing leaves the steel.
    assert first.checks[1].value == 1.0 and "of 0 driven poses" in first.checks[1].message
    leaves = [n["id"] for n in s["graph"]["nodes"] if n["degree"] == 1]
    start, end = leaves[1], leaves[0]
    r = _plan("cross", plan_paths=False, start=start, end=end)
    s2 = _assert_form(r)
    endpoints = r.checks[-1]
    assert endpoints.passed and endpoints.limit == f"{start}→{end}" == endpoints.value
    assert (s2["start"], s2["end"]) == (start, end)


def test_an_unknown_start_vertex_is_a_planner_error() -> None:
    with pytest.raises(UnknownVertexError, match="999"):
        _plan("cross", plan_paths=False, start=999)
