"""``ara.inspect`` through the REST API and the scene, on small box-section
structures built here (a few thousand points each, well under a second to
plan), and its planner entry point's checks."""

from __future__ import annotations

import io
import socket
import types
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

#: A survey frame (UTM-like easting / northing, 35 m up), as field scans come.
SURVEY = np.array([512_300.0, 5_401_200.0, 35.0])
SPACING = 0.03


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def box(p0: Any, p1: Any, seed: int, width: float = 0.3, depth: float = 0.2) -> np.ndarray:
    """The four faces of a rectangular hollow section from ``p0`` to ``p1``
    (``width`` across, horizontal for a horizontal member; ``depth`` up),
    sampled every ``SPACING`` with 1 mm noise."""
    a, b = np.asarray(p0, float), np.asarray(p1, float)
    length = float(np.linalg.norm(b - a))
    x = (b - a) / length
    up = np.array([0.0, 0.0, 1.0]) if abs(x[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    y = np.cross(up, x)
    y /= np.linalg.norm(y)
    z = np.cross(x, y)
    t = np.arange(0.0, length, SPACING)
    faces = []
    for sign in (-1.0, 1.0):
        for across, size, normal in ((y, width, z * depth / 2), (z, depth, y * width / 2)):
            u = np.arange(-size / 2, size / 2 + 1e-9, SPACING)
            tt, uu = (g.reshape(-1, 1) for g in np.meshgrid(t, u))
            faces.append(a + tt * x + uu * across + sign * normal)
    pts = np.vstack(faces)
    return pts + np.random.default_rng(seed).normal(0.0, 0.001, pts.shape)


def ell() -> np.ndarray:
    """Two 4 m boxes meeting at a right angle, top faces flush: one joint, one
    mobile transition."""
    return np.vstack([box([0, 0, 0], [4, 0, 0], 1), box([4, 0.15, 0], [4, 4, 0], 2)])


def upload(api: Any, pts: np.ndarray, units: str | None = None) -> str:
    buf = io.BytesIO()
    np.save(buf, pts)
    data = {"units": units} if units else None
    r = api.post("/api/v1/clouds", files={"file": ("scan.npy", buf.getvalue())}, data=data)
    assert r.status_code == 201, r.text
    return str(r.json()["id"])


def plan(api: Any, params: dict[str, Any]) -> dict[str, Any]:
    return api.wait(api.submit("ara.inspect", params)["id"], timeout=240)


def checks_of(p: dict[str, Any]) -> dict[str, dict[str, Any]]:
    return {c["name"]: c for c in p["checks"]}


CHECKS = {"members_found", "members_covered", "transitions_feasible", "gaps_explained"}


# ------------------------------------------------------------------ catalogue


def test_listed_with_its_params_schema_and_the_ara_numbers(api) -> None:
    from planners.inspection import ARA_JUMP_REACH_M, InspectionParams
    from planners.structure.synthetic import SCAN_SAMPLES
    from server.kinds.ara_inspect import AraInspectParams, ara_robot_numbers, inspection_params

    kinds = {k["name"]: k for k in api.get("/api/v1/kinds", "viewer").json()}
    k = kinds["ara.inspect"]
    assert k["robot"] == "ara" and k["compiles"] is True  # the robot program
    assert k["samples"] == sorted(SCAN_SAMPLES)
    props = k["params_schema"]["properties"]
    for name in (
        "cloud_id",
        "sample",
        "sample_seed",
        "crop_box_m",
        "units",
        "start",
        "end",
        "foot_length_m",
        "foot_width_m",
        "jump_reach_m",
        "coplanar_angle_deg",
        "jump_cost_m",
        "max_section_m",
        "max_gap_m",
        "linearity_min",
    ):
        assert name in props, name
    assert k["params_schema"]["additionalProperties"] is False
    assert k["defaults"]["units"] == "auto" and k["defaults"]["sample"] == "scan_warren"
    # The robot file and the planner's own defaults agree (foot, arm reach).
    assert ara_robot_numbers() == {
        "foot_length_m": 0.18,
        "foot_width_m": 0.12,
        "jump_reach_m": pytest.approx(ARA_JUMP_REACH_M),
        "arm_length_m": pytest.approx(0.5),
        "wrist_standing_m": pytest.approx(0.1),
        "wrist_landing_m": pytest.approx(0.1),
    }
    ara = ara_robot_numbers()
    assert inspection_params(AraInspectParams()) == InspectionParams(
        jump_reach_m=ara["jump_reach_m"],
        arm_length_m=ara["arm_length_m"],
        wrist_standing_m=ara["wrist_standing_m"],
        wrist_landing_m=ara["wrist_landing_m"],
    )


# ------------------------------------------------------------------ plans


def test_a_frame_in_a_survey_frame_plans_every_check_passing_and_draws(make_api) -> None:
    sapi = make_api(scene_port=free_port())
    cid = upload(sapi, ell() + SURVEY)
    p = plan(sapi, {"cloud_id": cid})
    assert p["state"] == "planned", [c["message"] for c in p["checks"] if not c["passed"]]
    checks = checks_of(p)
    assert set(checks) == CHECKS and all(c["passed"] for c in checks.values())
    m = p["metrics"]
    assert m["member_count"] == 2 and m["member_count_box"] == 2 and m["joint_count"] == 1
    assert m["route_length_ratio"] >= 1.0 and m["route_length_m"] == pytest.approx(
        m["route_lower_bound_m"] + m["deadhead_m"]
    )
    assert 7.0 < m["route_lower_bound_m"] < 8.5  # two 4 m members meeting at a corner
    assert m["jumps"] == 0 and m["gap_count"] == 0 and m["infeasible_transitions"] == 0
    for stage in ("spacing", "features", "lines", "assign", "faces", "graph"):
        assert f"structure_{stage}_time_s" in m, stage
    for stage in ("gaps", "route", "transitions"):
        assert f"inspection_{stage}_time_s" in m, stage

    res = p["result"]
    assert res["units"]["scale_to_m"] == 1.0 and "metres" in res["units"]["reason"]
    assert {mb["profile"] for mb in res["members"]} == {"box"}
    for mb in res["members"]:
        assert mb["faces"] and mb["driving_face"] in {f["id"] for f in mb["faces"]}
        assert all(np.asarray(f["outline"]).shape[1] == 3 for f in mb["faces"])
    (t,) = res["transitions"]
    assert (t["kind"], t["mode"], t["feasible"]) == ("member", "mobile", True)
    assert t["availability"]["plane"] and t["availability"]["area"] and t["availability"]["height"]
    route = res["route"]
    assert route["vertices"][0] == res["start"] and route["vertices"][-1] == res["end"]
    assert set(route["kinds"]) == {"span"} and res["uncovered_members"] == []
    pts = np.load(io.BytesIO(sapi.get(f"/api/v1/plans/{p['id']}/arrays/points").content))
    labels = np.load(io.BytesIO(sapi.get(f"/api/v1/plans/{p['id']}/arrays/labels").content))
    assert pts.shape == (len(labels), 3) and set(np.unique(labels)) <= {-1, 0, 1}
    # still in the survey frame (the L's centre is near (3, 1.5, 0) of it)
    assert np.all(np.abs(pts.mean(axis=0) - SURVEY - [3, 1.5, 0]) < 2.0)

    assert sapi.post("/api/v1/scene/show", json={"plan_id": p["id"]}).status_code == 200
    scene = sapi.services.scene.server.scene
    assert scene.get_handle_by_name("/plan/error") is None
    for name in (
        "/plan/local",
        "/plan/local/cloud/0",
        "/plan/local/members",
        "/plan/local/faces",
        "/plan/local/vertices",
        "/plan/local/routes/0",
        "/plan/local/transitions/feasible",
    ):
        assert scene.get_handle_by_name(name) is not None, name
    # Two vertex clicks propose a plan with that start and end; the
    # operator's Accept makes it.
    handle = scene.get_handle_by_name("/plan/local/vertices")
    nodes = [n for n in res["graph"]["nodes"] if n["kind"] != "split"]
    ids = [n["id"] for n in nodes]
    ends = [n["id"] for n in nodes if n["kind"] == "end"]
    for v in (ends[1], ends[0]):
        for entry in handle._impl.click_cb:
            entry.callback(types.SimpleNamespace(instance_index=ids.index(v)))
    (proposal,) = sapi.get("/api/v1/scene", "viewer").json()["proposals"]
    assert proposal["patch"] == {"start": ends[1], "end": ends[0]}
    r = sapi.post(f"/api/v1/scene/proposals/{proposal['id']}/accept")
    assert r.status_code == 202, r.text
    child = sapi.wait(r.json()["id"], timeout=240)
    assert child["result"]["route"]["vertices"][0] == ends[1]
    assert child["result"]["route"]["vertices"][-1] == ends[0]


def test_checks_fail_honestly(api) -> None:
    # Two beams 2 m apart: beyond the 0.70 m jump reach, so the main route
    # drives one and the other is named as needing the robot carried there;
    # the gap is open and explained by exactly that.
    apart = np.vstack([box([0, 0, 0], [4, 0, 0], 3), box([0, 2, 0], [4, 2, 0], 4)])
    p = plan(api, {"cloud_id": upload(api, apart + SURVEY)})
    checks = checks_of(p)
    assert p["state"] == "rejected"
    assert not checks["members_covered"]["passed"] and checks["members_covered"]["value"] == 1
    assert "only by another route" in checks["members_covered"]["message"]
    assert checks["gaps_explained"]["passed"] and checks["members_found"]["passed"]
    (gap,) = p["result"]["gaps"]
    assert not gap["joined"] and gap["width_m"] == pytest.approx(2.0, abs=0.05)
    assert gap["unreached_members"] == p["result"]["uncovered_members"] and gap["explained"]
    assert len(p["result"]["routes"]) == 2
    assert p["metrics"]["total_length_m"] > p["metrics"]["route_length_m"]

    # A 0.4 x 0.4 m foot fits on no 0.3 m wide face: the transition is infeasible.
    big = plan(
        api, {"cloud_id": upload(api, ell() + SURVEY), "foot_length_m": 0.4, "foot_width_m": 0.4}
    )
    checks = checks_of(big)
    assert big["state"] == "rejected" and not checks["transitions_feasible"]["passed"]
    assert "S_am false" in checks["transitions_feasible"]["message"]
    # The route drives both members, but the ARA cannot get onto the second one.
    assert big["result"]["uncovered_members"] == []
    cov = checks["members_covered"]
    assert not cov["passed"] and cov["value"] == 1 and "not inspected" in cov["message"]
    assert "(S_am)" in cov["message"] and len(big["result"]["unreachable_members"]) == 1

    # A flat plate (ground, a slab) holds no member: nothing to inspect.
    g = np.arange(0.0, 2.0, SPACING)
    xx, yy = np.meshgrid(g, g)
    plate = np.c_[xx.ravel(), yy.ravel(), np.zeros(xx.size)] + SURVEY
    none = plan(api, {"cloud_id": upload(api, plate)})
    assert none["state"] == "rejected", none.get("error")
    assert [c["name"] for c in none["checks"]] == ["members_found"]
    assert not none["checks"][0]["passed"] and "no member" in none["checks"][0]["message"]
    assert none["result"]["route"] is None and none["metrics"]["member_count"] == 0


def test_a_gap_within_reach_is_jumped(api) -> None:
    """Two parallel beams 0.6 m apart are two members when sections are
    known to be shallower (``max_section_m``): the route jumps the gap."""
    pair = np.vstack([box([0, 0, 0], [4, 0, 0], 5), box([0, 0.6, 0], [4, 0.6, 0], 6)])
    p = plan(api, {"cloud_id": upload(api, pair + SURVEY), "max_section_m": 0.4})
    assert p["state"] == "planned", [c["message"] for c in p["checks"] if not c["passed"]]
    assert p["result"]["structure_params"]["max_section_m"] == 0.4
    (gap,) = p["result"]["gaps"]
    assert gap["joined"] and gap["explained"] and gap["width_m"] == pytest.approx(0.6, abs=0.03)
    assert "jump" in p["result"]["route"]["kinds"]
    modes = [(t["kind"], t["mode"]) for t in p["result"]["transitions"]]
    assert ("gap", "inchworm") in modes
    assert p["metrics"]["gaps_joined"] == 1 and p["metrics"]["jumps"] >= 1
    # Without the override the two beams are read as faces of one member.
    one = plan(api, {"cloud_id": upload(api, pair + SURVEY)})
    assert one["metrics"]["member_count"] == 1


def test_the_gap_check_fails_when_a_gap_is_left_open_within_reach(monkeypatch) -> None:
    """``gaps_explained`` is a real check: a plan that left a gap open
    although it is within the jump reach (a planner fault, simulated here)
    fails it, naming the gap."""
    import planners.inspection.inspect_plan as inspect_plan
    from planners.structure import StructureParams

    real = inspect_plan.plan_inspection

    def leaves_gaps_open(*args: Any, **kw: Any) -> Any:
        out = real(*args, **kw)
        return replace(out, gaps=[replace(g, joined=False) for g in out.gaps])

    monkeypatch.setattr(inspect_plan, "plan_inspection", leaves_gaps_open)
    pair = np.vstack([box([0, 0, 0], [4, 0, 0], 5), box([0, 0.6, 0], [4, 0.6, 0], 6)])
    r = inspect_plan.plan_inspection_result(pair, structure=StructureParams(max_section_m=0.4))
    checks = {c.name: c for c in r.checks}
    assert not checks["gaps_explained"].passed and checks["gaps_explained"].value == 1
    assert "0.600 m between members" in checks["gaps_explained"].message
    assert r.summary["gaps"][0]["explained"] is False


def test_millimetre_clouds_are_scaled_to_metres(api) -> None:
    # Stored as millimetre numbers (the uploader said "m", so no rescale).
    cid = upload(api, (ell() + SURVEY) * 1000.0, units="m")
    p = plan(api, {"cloud_id": cid, "units": "mm"})
    assert p["state"] == "planned", [c["message"] for c in p["checks"] if not c["passed"]]
    assert p["result"]["units"] == {
        "unit": "mm",
        "scale_to_m": 0.001,
        "reason": "set by the request (mm)",
    }
    lengths = sorted(m["length_m"] for m in p["result"]["members"])
    assert lengths == [pytest.approx(4.0, abs=0.35), pytest.approx(4.0, abs=0.35)]
    pts = np.load(io.BytesIO(api.get(f"/api/v1/plans/{p['id']}/arrays/points").content))
    assert np.all(np.abs(pts.mean(axis=0) - SURVEY) < 5.0)  # metres again
    # "auto" tells millimetres from the spacing and extent, as an upload does.
    auto = plan(api, {"cloud_id": cid})
    assert auto["result"]["units"]["scale_to_m"] == 0.001
    assert "millimetres" in auto["result"]["units"]["reason"]
    assert auto["metrics"]["member_count"] == 2
    # A cloud the upload already converted from millimetres is not scaled twice.
    converted = upload(api, (ell() + SURVEY) * 1000.0, units="mm")
    r = api.post(
        "/api/v1/plans",
        json={"kind": "ara.inspect", "params": {"cloud_id": converted, "units": "mm"}},
    )
    assert r.status_code == 422 and "converted from millimetres" in r.json()["detail"]
    assert "params.units" in r.json()["detail"]


def test_bad_requests(api) -> None:
    def post(params: dict[str, Any]) -> Any:
        return api.post("/api/v1/plans", json={"kind": "ara.inspect", "params": params})

    r = post({"strat": 3})
    assert r.status_code == 422 and [e["loc"] for e in r.json()["detail"]] == [["strat"]]
    r = post({"crop_box_m": [[1, 0, 0], [0, 1, 1]]})
    assert r.status_code == 422 and "crop_box_m" in str(r.json()["detail"])
    assert "min < max" in str(r.json()["detail"])
    r = post({"crop_box_m": [[0, 0], [1, 1]]})
    assert r.status_code == 422 and "crop_box_m" in str(r.json()["detail"])
    r = post({"sample": "scan_bridge"})
    assert r.status_code == 422 and "unknown sample" in r.text
    for bad in ({"units": "feet"}, {"foot_width_m": 0}, {"coplanar_angle_deg": 90}):
        r = post(bad)
        assert r.status_code == 422 and next(iter(bad)) in str(r.json()["detail"]), bad
    assert api.get("/api/v1/plans", "viewer").json() == []  # nothing was queued

    # Vertex ids exist only once the cloud is modelled, in the job: an id
    # that is not a vertex fails the plan, saying so.
    cid = upload(api, ell() + SURVEY)
    p = plan(api, {"cloud_id": cid, "start": 999})
    assert p["state"] == "failed" and "start vertex 999 is not a vertex" in p["error"]
    p = plan(api, {"cloud_id": cid, "end": 999})
    assert p["state"] == "failed" and "end vertex 999 is not a vertex" in p["error"]
    # A crop box that keeps nothing says what the cloud spans.
    p = plan(api, {"cloud_id": cid, "crop_box_m": [[0, 0, 0], [1, 1, 1]]})
    assert p["state"] == "failed" and "crop box" in p["error"] and "spans" in p["error"]


def test_the_default_sample_plans_through_the_api(api) -> None:
    """Empty params: the synthetic TLS scan of a Warren truss.  Whether every
    transition is feasible depends on the sections drawn; the checks must
    all be there and the structure found."""
    p = plan(api, {})
    assert p["state"] in ("planned", "rejected"), p.get("error")
    checks = checks_of(p)
    assert set(checks) == CHECKS and checks["members_found"]["passed"]
    assert p["state"] == ("planned" if all(c["passed"] for c in checks.values()) else "rejected")
    m = p["metrics"]
    assert m["member_count"] >= 5 and m["route_length_ratio"] >= 1.0
    assert m["transitions"] == len(p["result"]["transitions"])


def test_a_sample_scan_is_generated_once_per_process_and_read_only() -> None:
    """Plans of the same sample share one generated scan, which no plan can alter."""
    from planners.structure.synthetic import SCAN_SAMPLES
    from server.kinds.ara_inspect import sample_points

    sample_points.cache_clear()
    first = sample_points("scan_pratt", 1)
    assert sample_points("scan_pratt", 1) is first
    assert sample_points.cache_info().hits == 1
    np.testing.assert_array_equal(first, SCAN_SAMPLES["scan_pratt"](1))
    assert not first.flags.writeable
    with pytest.raises(ValueError, match="read-only"):
        first[0, 0] = 0.0
    assert sample_points("scan_pratt", 2) is not first
