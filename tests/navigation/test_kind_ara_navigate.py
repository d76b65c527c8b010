"""``ara.navigate`` through the REST API and the scene."""

from __future__ import annotations

import socket
import types

CRAWLER = {"footprint_length_m": 0.08, "footprint_width_m": 0.025, "footprint_center_x_m": 0.0}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_defaults_plan_and_compile_a_wheel_program_on_the_cross_sample(api) -> None:
    """Defaults: the Cross sample, the driving foot's contact patch, and
    differential-drive paths (turns in place, straight drives): every check
    passes, including the compiled wheel program replayed against the steel."""
    plan = api.wait(api.submit("ara.navigate")["id"], timeout=240)
    checks = {c["name"]: c for c in plan["checks"]}
    assert plan["state"] == "planned", [c["message"] for c in plan["checks"] if not c["passed"]]
    for name in (
        "bars_covered",
        "route_endpoints",
        "poses_on_steel",
        "wheel_motion",
        "paths_found",
        "command_program",
    ):
        assert checks[name]["passed"], (name, checks[name]["message"])
    m = plan["metrics"]
    assert m["cluster_count"] == 5 and m["bar_count"] == 4 and m["cross_count"] == 1
    assert m["route_length_m"] >= m["route_lower_bound_m"] > 0
    assert abs(m["deadhead_m"] - (m["route_length_m"] - m["route_lower_bound_m"])) < 1e-9
    for stage in ("preprocess", "segmentation", "boundaries", "graph", "route", "paths"):
        assert f"{stage}_time_s" in m
    res = plan["result"]
    assert res["footprint"]["length_m"] == 0.08 and res["motion_model"] == "differential"
    assert {c["kind"] for c in res["clusters"]} == {"bar", "cross"}
    wheels = [c for c in plan["program"] if c["op"] == "wheels"]
    assert wheels and all(
        c["speeds_m_s"][0] in (c["speeds_m_s"][1], -c["speeds_m_s"][1]) for c in wheels
    )  # straight drive or turn in place, never an arc


def test_whole_mobile_body_does_not_fit_the_flanges(api) -> None:
    """The ARA's whole 0.68 x 0.16 m mobile body is wider than the 60-150 mm
    flanges: the route is planned but the path check says why it cannot be
    driven, and the plan is rejected."""
    plan = api.wait(api.submit("ara.navigate", {"footprint": "mobile_body"})["id"], timeout=240)
    assert plan["state"] == "rejected", plan.get("error")
    checks = {c["name"]: c for c in plan["checks"]}
    assert checks["bars_covered"]["passed"] and checks["route_endpoints"]["passed"]
    assert not checks["paths_found"]["passed"]
    assert "0.68 × 0.16 m footprint" in checks["paths_found"]["message"]
    assert plan["result"]["footprint"]["center_x_m"] == -0.25


def test_holonomic_paths_cannot_be_compiled_for_the_wheels(api) -> None:
    """The seed's RRT in (x, y, yaw) slides sideways: the plan says so and is
    rejected instead of sending wheel commands that would not follow it."""
    plan = api.wait(api.submit("ara.navigate", {"motion_model": "holonomic"})["id"], timeout=240)
    checks = {c["name"]: c for c in plan["checks"]}
    assert plan["state"] == "rejected"
    assert not checks["wheel_motion"]["passed"]
    assert "cannot be driven" in checks["wheel_motion"]["message"]


def test_small_robot_plan_passes_every_check_and_draws(make_api) -> None:
    sapi = make_api(scene_port=free_port())
    cid = sapi.post("/api/v1/clouds", json={"sample": "t"}).json()["id"]
    plan = sapi.wait(sapi.submit("ara.navigate", {"cloud_id": cid, **CRAWLER})["id"], timeout=240)
    assert plan["state"] == "planned", [c["message"] for c in plan["checks"] if not c["passed"]]
    assert all(c["passed"] for c in plan["checks"])
    res = plan["result"]
    route = res["route"]
    assert route["vertices"][0] == res["start"] and route["vertices"][-1] == res["end"]
    assert len(res["paths"]) == len(route["edges"]) and all(p["ok"] for p in res["paths"])
    r = sapi.get(f"/api/v1/plans/{plan['id']}/arrays/path_xyz")
    assert r.status_code == 200

    assert sapi.post("/api/v1/scene/show", json={"plan_id": plan["id"]}).status_code == 200
    scene = sapi.services.scene.server.scene
    for name in (
        "/plan/vertices",
        "/plan/route",
        "/plan/robot",
        "/plan/graph",
        "/plan/boundaries/0",
        "/plan/cloud/0",
    ):
        assert scene.get_handle_by_name(name) is not None, name
    # Two vertex clicks propose a child plan with that start and end; only
    # the operator's Accept (REST) makes it.
    handle = scene.get_handle_by_name("/plan/vertices")
    ids = [n["id"] for n in res["graph"]["nodes"]]
    leaves = [n["id"] for n in res["graph"]["nodes"] if n["degree"] == 1]
    for v in (leaves[1], leaves[0]):
        for entry in handle._impl.click_cb:
            entry.callback(types.SimpleNamespace(instance_index=ids.index(v)))
    assert sapi.get(f"/api/v1/plans?parent_id={plan['id']}").json() == []
    (proposal,) = sapi.get("/api/v1/scene", "viewer").json()["proposals"]
    assert proposal["patch"] == {"start": leaves[1], "end": leaves[0]}
    r = sapi.post(f"/api/v1/scene/proposals/{proposal['id']}/accept")
    assert r.status_code == 202, r.text
    children = sapi.get(f"/api/v1/plans?parent_id={plan['id']}").json()
    assert [c["id"] for c in children] == [r.json()["id"]]
    child = sapi.wait(children[0]["id"], timeout=240)
    assert child["params"]["start"] == leaves[1] and child["params"]["end"] == leaves[0]
    assert child["result"]["route"]["vertices"][0] == leaves[1]


def test_bad_requests(api) -> None:
    r = api.post("/api/v1/plans", json={"kind": "ara.navigate", "params": {"sample": "zz"}})
    assert r.status_code == 422 and "unknown sample" in r.text
    r = api.post("/api/v1/plans", json={"kind": "ara.navigate", "params": {"segmentation": "gmm"}})
    assert r.status_code == 422
    r = api.post("/api/v1/plans", json={"kind": "ara.navigate", "params": {"cloud_id": "cl_nope"}})
    assert r.status_code == 422
    plan = api.wait(api.submit("ara.navigate", {"start": 999, "plan_paths": False})["id"])
    assert plan["state"] == "failed" and "start vertex 999" in (plan.get("error") or "")
    # Every synthetic structure is a sample cloud.
    r = api.post("/api/v1/clouds", json={"sample": "warren"})
    assert r.status_code in (200, 201), r.text
    assert r.json()["n_points"] > 10_000


def test_a_stored_cloud_in_a_survey_frame_plans_without_the_robot_window(api) -> None:
    """The Cross sample moved into a survey frame (UTM-like
    easting / northing, 35 m up) and uploaded as LAS plans with the defaults:
    ``auto`` leaves the robot-frame pass-through off for a stored cloud and the
    summary says so; the robot window, asked for, empties it with a clear
    error; a crop box keeps a region, and an empty one says what the cloud spans."""
    import io

    import laspy
    import numpy as np

    from planners.navigation.synthetic import SAMPLES

    offset = np.array([512_300.0, 5_401_200.0, 35.0])
    pts = SAMPLES["cross"](0) + offset
    header = laspy.LasHeader(point_format=3, version="1.4")
    header.scales, header.offsets = np.full(3, 1e-4), np.floor(pts.min(axis=0))
    las = laspy.LasData(header)
    las.x, las.y, las.z = pts.T
    buf = io.BytesIO()
    las.write(buf)
    r = api.post("/api/v1/clouds", files={"file": ("cross_utm.las", buf.getvalue())})
    assert r.status_code == 201, r.text
    cid = r.json()["id"]

    plan = api.wait(api.submit("ara.navigate", {"cloud_id": cid})["id"], timeout=240)
    assert plan["state"] == "planned", plan.get("error")
    pre = plan["result"]["preprocess"]
    assert pre["passthrough_m"] == {"x": None, "y": None, "z": None} and pre["crop_box_m"] is None
    assert plan["metrics"]["bar_count"] == 4 and plan["metrics"]["cross_count"] == 1

    robot = api.wait(
        api.submit("ara.navigate", {"cloud_id": cid, "passthrough": "robot_frame"})["id"], 240
    )
    assert robot["state"] == "failed" and "pass-through" in robot["error"]

    lo, hi = pts.min(axis=0), pts.max(axis=0)
    trimmed = [(lo + [0.05, 0.0, 0.0]).tolist(), hi.tolist()]  # 5 cm off one bar's end
    half = api.wait(
        api.submit(
            "ara.navigate",
            {
                "cloud_id": cid,
                "crop_box_m": trimmed,
                "plan_paths": False,
            },
        )["id"],
        240,
    )
    assert half["state"] in ("planned", "rejected"), half.get("error")
    counts = half["result"]["preprocess"]["counts"]
    assert 0 < counts["crop_box"] < counts["input"]
    empty = api.wait(
        api.submit(
            "ara.navigate",
            {"cloud_id": cid, "crop_box_m": [[0, 0, 0], [1, 1, 1]]},
        )["id"],
        240,
    )
    assert empty["state"] == "failed" and "crop box" in empty["error"] and "spans" in empty["error"]


def test_crop_box_must_be_an_ordered_box(api) -> None:
    r = api.post(
        "/api/v1/plans",
        json={"kind": "ara.navigate", "params": {"crop_box_m": [[1, 0, 0], [0, 1, 1]]}},
    )
    assert r.status_code == 422 and "crop_box_m" in str(r.json()["detail"])
