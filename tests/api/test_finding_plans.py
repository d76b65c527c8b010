"""From a finding to a maintenance plan, through REST: a
corrosion finding on a face of a sample structure becomes a blast plan of
that region with the base searched near it; every check passes; it is
approved, run on the emulator, and the run's coverage comes back onto the
finding, which then asks for a new condition state."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from fastapi.testclient import TestClient
from shapely.geometry import Polygon

from server.app import create_app
from server.auth import create_token
from tests.api.test_dispatch import wait_execution
from tests.api.test_findings import inspect_plan
from tests.api.test_findings import on_face as a_face_of
from tests.conftest import Api, make_settings
from tests.support.waiting import wait_for


def _patch(face: dict, centre: np.ndarray, half: float) -> list[list[float]]:
    """A square of side 2·half on the face's plane around ``centre``."""
    outline = np.asarray(face["outline"], float)
    n = np.asarray(face["normal"], float) / np.linalg.norm(face["normal"])
    e = outline[1] - outline[0]
    x = e - (e @ n) * n
    x /= np.linalg.norm(x)
    y = np.cross(n, x)
    return [list(centre + half * (a * x + b * y)) for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]


def _finding(api, plan: dict, type_: str = "corrosion", **extra) -> dict:
    member, face, point, _ = a_face_of(plan)
    region = _patch(face, np.asarray(point), 0.15)
    body = {
        "plan_id": plan["id"],
        "member_id": member,
        "face_id": face["id"],
        "point_m": point,
        "region_m": region,
        "type": type_,
        "condition_state": 3,
        **extra,
    }
    r = api.post("/api/v1/findings", json=body)
    assert r.status_code == 201, r.text
    return r.json()


def _plane_uv(surface: dict, pts: np.ndarray) -> np.ndarray:
    d = np.asarray(pts, float) - np.asarray(surface["origin"])
    return np.column_stack([d @ np.asarray(surface["x_axis"]), d @ np.asarray(surface["y_axis"])])


@pytest.fixture(scope="module")
def inspected(tmp_path_factory):
    """One sample inspection and its corrosion finding, shared (a model takes ~10 s)."""
    settings = make_settings(
        tmp_path_factory.mktemp("fp") / "var", emulators=True, emulator_time_scale=20.0
    )
    app = create_app(settings)
    client = TestClient(app)
    client.__enter__()
    store = app.state.services.store
    tokens = {
        role: create_token(store, f"test-{role}", role, "test")[1]
        for role in ("viewer", "operator", "admin")
    }
    api = Api(client, tokens, app)
    plan = inspect_plan(api)
    yield api, plan
    client.__exit__(None, None, None)


def test_a_corrosion_finding_becomes_a_blast_plan_run_and_its_coverage_comes_back(
    inspected,
) -> None:
    api, plan = inspected
    f = _finding(api, plan)
    face = next(
        g
        for m in plan["result"]["members"]
        if m["id"] == f["member_id"]
        for g in m["faces"]
        if g["id"] == f["face_id"]
    )
    assert (
        api.post(f"/api/v1/findings/{f['id']}/plan", "viewer", json={"kind": "blast"}).status_code
        == 403
    )
    r = api.post(f"/api/v1/findings/{f['id']}/plan", json={"kind": "blast"})
    assert r.status_code == 202, r.text
    assert r.headers["location"] == f"/api/v1/plans/{r.json()['id']}"
    blast = api.wait(r.json()["id"], timeout=300)
    assert blast["state"] == "planned", blast.get("error")
    failed = [c for c in blast["checks"] if not c["passed"]]
    assert not failed, failed

    # The surface is the finding's region on the face's plane.
    surf = blast["result"]["surface"]
    n = np.asarray(face["normal"]) / np.linalg.norm(face["normal"])
    assert abs(abs(np.asarray(surf["normal"]) @ n) - 1.0) < 1e-9
    # The surface is the finding's region clipped to the face's outline.
    region = Polygon(_plane_uv(surf, np.asarray(f["region_m"])))
    on_face = region.intersection(Polygon(_plane_uv(surf, np.asarray(face["outline"]))))
    blasted = Polygon(_plane_uv(surf, np.asarray(surf["outline_world"])))
    assert 0 < on_face.area <= region.area
    assert blasted.symmetric_difference(on_face).area < 1e-6
    # The base was searched, stands on the face's outer side, and the plan uses it.
    placed = blast["result"]["base_placement"]
    base = np.asarray(blast["result"]["robot_base"])[:3, 3]
    assert np.allclose(placed["base_m"], base)
    assert (base - np.asarray(surf["origin"])) @ n > 0
    assert placed["reaching"] >= 1 and placed["reach_margin_m"] >= 0
    # The structure's scan (a sample here: stored again as a cloud) gives the obstacles.
    cloud = api.get(f"/api/v1/clouds/{blast['params']['obstacle_cloud_id']}").json()
    assert cloud["n_points"] > 1000 and "sample" in cloud["name"]

    # The plan links back to its finding.
    assert api.get(f"/api/v1/plans/{blast['id']}", "viewer").json()["finding_id"] == f["id"]
    assert api.get(f"/api/v1/plans/{plan['id']}", "viewer").json()["finding_id"] is None
    linked = api.get(f"/api/v1/findings/{f['id']}", "viewer").json()
    assert [p["plan_id"] for p in linked["maintenance_plans"]] == [blast["id"]]
    assert linked["maintenance_plans"][0]["state"] == "planned"
    assert not linked["awaiting_review"]
    assert any(e["action"] == "plan" for e in linked["audit"])

    # Approve, run on the emulator, and the coverage comes back.
    assert (
        api.post(f"/api/v1/plans/{blast['id']}/approve", json={"comment": "ok"}).status_code == 200
    )
    assert api.services.dispatch.wait_connected("denso_vm6083", 20)
    ex = api.post(f"/api/v1/plans/{blast['id']}/dispatch", json={"robot": "denso_vm6083"})
    assert ex.status_code in (200, 201, 202), ex.text
    wait_execution(api, ex.json()["id"], ("completed",), timeout=240)

    def recorded() -> dict | None:
        got = api.get(f"/api/v1/findings/{f['id']}", "viewer").json()
        return got if got["maintenance_plans"][0]["outcome"] == "completed" else None

    got = wait_for(recorded, 20)
    assert got is not None
    link = got["maintenance_plans"][0]
    assert link["execution_id"] == ex.json()["id"] and link["state"] == "completed"
    assert link["spots_done"] == link["spots_planned"] > 0
    assert link["coverage_pct"] == pytest.approx(blast["metrics"]["coverage_pct"], abs=1e-3)
    assert got["awaiting_review"] and link["review_requested_at"]
    # The inspection's report lists the blast plan under the finding, with what it achieved.
    report = api.get(f"/api/v1/reports/{plan['id']}", "viewer").text
    assert f"{blast['id']} blast completed — run completed" in report
    assert f"coverage {link['coverage_pct']:.2f} %" in report
    assert "(new condition state awaited)" in report
    # The operator's new condition state answers the request.
    r = api.patch(f"/api/v1/findings/{f['id']}", json={"condition_state": 1})
    assert r.status_code == 200 and not r.json()["awaiting_review"]
    assert r.json()["maintenance_plans"][0]["reviewed_at"]


def test_a_finding_that_cannot_be_blasted_is_refused_with_why(inspected) -> None:
    api, plan = inspected
    crack = _finding(api, plan, "crack")
    r = api.post(f"/api/v1/findings/{crack['id']}/plan", json={"kind": "blast"})
    assert r.status_code == 422 and "not blasted" in r.text
    f = _finding(api, plan)
    for body, words in (
        ({"kind": "weld"}, "kind"),
        ({"kind": "blast", "patch_m": -1}, "patch_m"),
        ({"kind": "blast", "params": {"nozzle": "huge"}}, "nozzle"),
        ({"kind": "blast", "colour": 1}, "colour"),
    ):
        r = api.post(f"/api/v1/findings/{f['id']}/plan", json=body)
        assert r.status_code == 422 and words in r.text, (body, r.text)
    assert api.post("/api/v1/findings/fd_nope/plan", json={"kind": "blast"}).status_code == 404
    # A base region nothing reaches from: the plan fails saying so.
    far = {"lo_m": [50.0, 50.0, 50.0], "hi_m": [51.0, 51.0, 51.0]}
    r = api.post(
        f"/api/v1/findings/{f['id']}/plan",
        json={"kind": "blast", "params": {"base_search": far}},
    )
    assert r.status_code == 202, r.text
    failed = api.wait(r.json()["id"], timeout=120)
    assert failed["state"] == "failed" and "no base position reaches" in failed["error"]
    # A withdrawn finding makes no plan.
    api.delete(f"/api/v1/findings/{f['id']}?reason=duplicate")
    r = api.post(f"/api/v1/findings/{f['id']}/plan", json={"kind": "blast"})
    assert r.status_code == 409 and "deleted" in r.text
    # Nothing was linked by the refusals.
    assert api.get(f"/api/v1/findings/{crack['id']}").json()["maintenance_plans"] == []


def test_a_crack_finding_asks_for_a_close_inspection_of_its_member(inspected) -> None:
    api, plan = inspected
    f = _finding(api, plan, "crack")
    graph = plan["result"]["graph"]
    start = plan["result"]["route"]["vertices"][0]
    r = api.post(f"/api/v1/findings/{f['id']}/plan", json={"kind": "ara.inspect", "start": start})
    assert r.status_code == 202, r.text
    close = api.wait(r.json()["id"], timeout=300)
    assert close["state"] == "planned", close.get("error")
    assert close["params"]["close_member"] == f["member_id"]
    assert close["params"]["start"] == start
    assert all(c["passed"] for c in close["checks"]), close["checks"]
    route = close["result"]["route"]
    assert route["vertices"][0] == start
    # It ends at an end of the member, having driven every span of it.
    spans = {
        frozenset((e["u"], e["v"]))
        for e in graph["edges"]
        if e.get("kind") == "span" and e.get("member") == f["member_id"]
    }
    driven = {frozenset(p) for p in itertools.pairwise(route["vertices"])}
    assert spans and spans <= driven
    assert route["length_m"] <= plan["result"]["route"]["length_m"]
    got = api.get(f"/api/v1/findings/{f['id']}").json()
    assert got["maintenance_plans"][0]["kind"] == "ara.inspect"


def test_spots_count_only_acknowledged_way_points() -> None:
    from server.maintenance import spots_acknowledged

    # way-points 0..4 (joints commands), nozzle commands between; spots per way-point
    program = [
        {"op": "joints"},  # 0: wp0, approach
        {"op": "joints"},  # 1: wp1, spot 0
        {"op": "nozzle"},  # 2
        {"op": "joints"},  # 3: wp2, spot 0 again
        {"op": "joints"},  # 4: wp3, spot 1
        {"op": "joints"},  # 5: wp4, spot 2
        {"op": "stop"},
    ]
    spot = np.array([-1, 0, 0, 1, 2])
    assert spots_acknowledged(program, [], spot) == (0, 3)
    assert spots_acknowledged(program, [0, 1, 2], spot) == (1, 3)
    assert spots_acknowledged(program, [0, 1, 2, 3, 4], spot) == (2, 3)
    assert spots_acknowledged(program, list(range(7)), spot) == (3, 3)


def test_a_sample_plan_without_its_seed_names_what_is_missing() -> None:
    """The scan behind a sample inspection is generated again from its name
    and seed; params without the seed are refused with why, rather than
    rebuilt from a guessed seed (another structure than the one inspected)."""
    from types import SimpleNamespace

    from server.maintenance import MaintenanceError, scan_cloud_id

    source = SimpleNamespace(id="p1", params={"sample": "scan_warren"}, result={})
    with pytest.raises(MaintenanceError) as err:
        scan_cloud_id(None, source, "alice")  # type: ignore[arg-type]
    assert "sample_seed" in str(err.value)
