"""A plan's history exported as a zip and imported on another server:
round trip of a real emulator run with findings and photos, the ``archived``
state rule, and every refused archive leaving the store as it was."""

from __future__ import annotations

import hashlib
import io
import json
import time
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader

from server.store.findings import FindingStore
from tests.api.test_dispatch import approved_demo, wait_execution

PNG = b"\x89PNG\r\n\x1a\n" + bytes(range(64))
JPEG = b"\xff\xd8\xff\xe0" + bytes(range(64, 0, -1))
TABLES = (
    "plans",
    "clouds",
    "executions",
    "execution_acks",
    "execution_states",
    "findings",
    "finding_photos",
    "finding_plans",
    "audit_events",
)


def export(api, plan_id: str) -> bytes:
    r = api.get(f"/api/v1/plans/{plan_id}/export", "viewer")
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == "application/zip"
    assert f"steelpath-plan-{plan_id}.zip" in r.headers["content-disposition"]
    return r.content


def upload(api, data: bytes, role: str = "admin") -> Any:
    return api.post("/api/v1/imports", role, files={"file": ("plan.zip", data, "application/zip")})


def snapshot(api) -> tuple[dict[str, int], list[str]]:
    """Row counts of every archived table, and every file under the data directory."""
    store = api.services.store
    counts = {t: store.db.query_one(f"SELECT COUNT(*) FROM {t}")[0] for t in TABLES}
    data = Path(store.data_dir)
    files = sorted(
        str(p.relative_to(data))
        for p in data.rglob("*")
        if p.is_file() and not p.name.startswith("steelpath.sqlite3")
    )
    return counts, files


def add_findings(api, plan_id: str) -> list[str]:
    """Two findings with photos on ``plan_id`` (one soft-deleted), straight in the store:
    the REST route places findings on inspection plans only."""
    fs = FindingStore(api.services.store.db, api.services.store.data_dir / "photos")
    a = fs.add(
        {"plan_id": plan_id, "member_id": 1, "point_m": [1.0, 2.0, 3.0], "type": "corrosion",
         "condition_state": 3, "notes": "rust at the bearing"},
        "inspector (tk_x)",
    )  # fmt: skip
    b = fs.add(
        {"plan_id": plan_id, "cluster_id": 2, "region_m": [[0, 0, 0], [1, 0, 0], [1, 1, 0]],
         "type": "crack", "condition_state": 2},
        "inspector (tk_x)",
    )  # fmt: skip
    fs.add_photo(a.id, PNG, "bearing.png", "image/png", "inspector (tk_x)")
    fs.add_photo(a.id, JPEG, "close.jpg", "image/jpeg", "inspector (tk_x)")
    fs.add_photo(b.id, PNG, "crack.png", "image/png", "inspector (tk_x)")
    fs.update(b.id, {"notes": "hairline"}, "inspector (tk_x)")
    fs.delete(b.id, "inspector (tk_x)", "paint crack, not steel")
    with api.services.store.db.transaction() as conn:  # a maintenance plan made from `a`
        conn.execute(
            "INSERT INTO finding_plans (plan_id, finding_id, kind, created_by, created_at)"
            " VALUES ('pl_blast0001', ?, 'blast', 'inspector (tk_x)', '2026-01-01T00:00:00')",
            (a.id,),
        )
    return [a.id, b.id]


def rezip(data: bytes, change: dict[str, bytes | None], extra: dict[str, bytes] | None = None):
    """``data`` with entries replaced (bytes) or removed (``None``), plus ``extra``."""
    out = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(data)) as src, zipfile.ZipFile(out, "w") as dst:
        for info in src.infolist():
            if info.filename in change:
                if change[info.filename] is not None:
                    dst.writestr(info.filename, change[info.filename])
            else:
                dst.writestr(info.filename, src.read(info))
        for name, body in (extra or {}).items():
            dst.writestr(name, body)
    return out.getvalue()


def audit_keys(events: list[dict]) -> set[tuple]:
    return {
        (e["ts"], e["actor"], e["entity"], e["entity_id"], e["action"], e["from_state"],
         e["to_state"], e["reason"])
        for e in events
    }  # fmt: skip


def test_a_real_run_with_findings_exports_and_imports_on_another_server(make_api, tmp_path):
    src = make_api(tmp_path / "a", emulators=True, emulator_time_scale=10.0)
    assert src.services.dispatch.wait_connected("ara", 20)
    plan = approved_demo(src, end="c2")
    pid = plan["id"]
    fids = add_findings(src, pid)
    eid = src.post(f"/api/v1/plans/{pid}/dispatch", json={"robot": "ara"}).json()["id"]
    wait_execution(src, eid, ("running",), timeout=30)
    time.sleep(1.0)
    assert src.post(f"/api/v1/executions/{eid}/pause").status_code == 200
    wait_execution(src, eid, ("paused",), timeout=30)
    while_paused = export(src, pid)  # an execution still active at export
    assert src.post(f"/api/v1/executions/{eid}/resume").status_code == 200
    ex = wait_execution(src, eid, ("completed",), timeout=120)
    data = export(src, pid)

    # The zip: manifest with every file's sha256, the MCAP readable.
    zf = zipfile.ZipFile(io.BytesIO(data))
    manifest = json.loads(zf.read("manifest.json"))
    assert manifest["format"] == "steelpath.plan-archive" and manifest["format_version"] == 1
    assert manifest["schema_version"] == src.get("/api/v1/health").json()["schema_version"]
    assert manifest["plan_id"] == pid and manifest["plan_state"] == "completed"
    for f in manifest["files"]:
        assert hashlib.sha256(zf.read(f["name"])).hexdigest() == f["sha256"], f["name"]
    assert set(zf.namelist()) == {"manifest.json"} | {f["name"] for f in manifest["files"]}
    assert manifest["counts"]["executions"] == 1 and manifest["counts"]["findings"] == 2
    assert manifest["counts"]["photos"] == 3
    assert f"executions/{eid}.mcap" in zf.namelist()
    summary = make_reader(io.BytesIO(zf.read(f"executions/{eid}.mcap"))).get_summary()
    assert summary is not None
    topics = {c.topic for c in summary.channels.values()}
    assert {"/plan/program", "/commands/acknowledged", "/robot/state", "/operator"} <= topics
    assert any(n.startswith("photos/") and n.endswith(".jpg") for n in zf.namelist())

    # A second server: its own data directory.
    dst = make_api(tmp_path / "b")
    assert dst.services.store.data_dir != src.services.store.data_dir
    assert dst.get(f"/api/v1/plans/{pid}").status_code == 404
    assert upload(dst, data, "operator").status_code == 403
    assert upload(dst, data, "viewer").status_code == 403
    r = upload(dst, data)
    assert r.status_code == 201, r.text
    got = r.json()
    assert got["plan_id"] == pid and got["state"] == "archived"
    assert got["original_state"] == "completed"
    assert got["executions"] == [eid] and got["interrupted"] == []
    assert sorted(got["findings"]) == sorted(fids) and len(got["photos"]) == 3

    # The plan as the API shows it: equal but for the state rule.
    a = src.get(f"/api/v1/plans/{pid}", "viewer").json()
    b = dst.get(f"/api/v1/plans/{pid}", "viewer").json()
    assert b["state"] == "archived" and b["allowed_actions"] == ["delete", "revise"]
    for k in ("state", "allowed_actions", "audit", "revisions"):
        a.pop(k), b.pop(k)
    assert a == b
    for name in a["arrays"]:
        url = f"/api/v1/plans/{pid}/arrays/{name}"
        assert src.get(url).content == dst.get(url).content
        assert np.load(io.BytesIO(dst.get(url).content)).size > 0

    # Executions, acks, recorded states.
    assert dst.get(f"/api/v1/executions/{eid}").json()["state"] == "completed"
    ea = {k: v for k, v in ex.items() if k not in ("audit", "current_command")}
    eb = dst.get(f"/api/v1/executions/{eid}").json()
    assert ea == {k: v for k, v in eb.items() if k not in ("audit", "current_command")}
    for method in ("ack_times", "execution_states"):
        assert getattr(src.services.store, method)(eid) == getattr(dst.services.store, method)(eid)
    assert len(dst.services.store.execution_states(eid)) >= 2
    rec = dst.get(f"/api/v1/executions/{eid}/recording.mcap", "viewer")
    assert rec.status_code == 200 and make_reader(io.BytesIO(rec.content)).get_summary()

    # Findings (the deleted one too) and photos, byte for byte.
    for fid in fids:
        fa = src.get(f"/api/v1/findings/{fid}", "viewer").json()
        fb = dst.get(f"/api/v1/findings/{fid}", "viewer").json()
        assert fa == fb
        for photo in fa["photos"]:
            pa, pb = src.get(photo["url"], "viewer"), dst.get(photo["url"], "viewer")
            assert pb.status_code == 200 and pa.content == pb.content
    assert dst.get(f"/api/v1/findings/{fids[1]}", "viewer").json()["deleted"]

    # Audit: every event there is here, plus the admin's import.
    store_a, store_b = src.services.store, dst.services.store
    events_a: list[dict] = []
    events_b: list[dict] = []
    for entity, ids in (("plan", [pid]), ("execution", [eid]), ("finding", fids)):
        for i in ids:
            events_a += [e.public() for e in store_a.list_audit(entity, i, limit=10_000)]
            events_b += [e.public() for e in store_b.list_audit(entity, i, limit=10_000)]
    assert audit_keys(events_a) <= audit_keys(events_b)
    (imp,) = [e for e in events_b if e["action"] == "import"]
    assert imp["entity"] == "plan" and imp["actor"].startswith("test-admin")
    assert (imp["from_state"], imp["to_state"]) == ("completed", "archived")

    # Never dispatchable or approvable here; its robot is not busy with it.
    before = snapshot(dst)
    r = dst.post(f"/api/v1/plans/{pid}/dispatch", json={"robot": "ara"})
    assert r.status_code == 409 and "archived" in r.json()["detail"], r.text
    assert dst.post(f"/api/v1/plans/{pid}/approve").status_code == 409

    # Re-import: 409, nothing changed.
    r = upload(dst, data)
    assert r.status_code == 409 and "already exists" in r.json()["detail"]
    assert snapshot(dst) == before

    # Exported while its run was paused: the run comes in interrupted, not resumable.
    third = make_api(tmp_path / "c")
    r = upload(third, while_paused)
    assert r.status_code == 201, r.text
    assert r.json()["original_state"] == "paused" and r.json()["interrupted"] == [eid]
    exc = third.get(f"/api/v1/executions/{eid}").json()
    assert exc["state"] == "interrupted" and "imported while paused" in exc["error"]
    assert third.services.store.newest_execution_of("ara", {"interrupted", "paused"}) is None
    assert third.post(f"/api/v1/executions/{eid}/resume").status_code == 409
    assert third.get(f"/api/v1/executions/{eid}").json()["state"] == "interrupted"


@pytest.fixture
def small_archive(make_api, tmp_path) -> tuple[Any, str, bytes]:
    """A plan referencing a stored cloud, exported from a first server."""
    src = make_api(tmp_path / "src")
    store = src.services.store
    pts = np.random.default_rng(3).normal(size=(500, 3))
    cloud = store.add_cloud("girder", "test.xyz", pts, 0, "surveyor (tk_s)")
    plan = store.create_plan("demo.route", {"cloud_id": cloud.id}, "planner (tk_p)")
    add_findings(src, plan.id)
    return src, plan.id, export(src, plan.id)


def test_the_source_cloud_travels_with_its_plan(small_archive, make_api, tmp_path):
    src, pid, data = small_archive
    cid = src.services.store.get_plan(pid).params["cloud_id"]
    dst = make_api(tmp_path / "dst")
    r = upload(dst, data)
    assert r.status_code == 201, r.text
    assert r.json()["cloud_id"] == cid and r.json()["cloud"] == "imported"
    a, b = src.services.store, dst.services.store
    assert np.array_equal(a.cloud_points(cid), b.cloud_points(cid))
    assert a.get_cloud(cid).public() == b.get_cloud(cid).public()
    # The link from a finding to the maintenance plan made from it travels too.
    link = "SELECT * FROM finding_plans WHERE plan_id = 'pl_blast0001'"
    assert dict(a.db.query_one(link)) == dict(b.db.query_one(link))


def _manifest(data: bytes) -> dict:
    return json.loads(zipfile.ZipFile(io.BytesIO(data)).read("manifest.json"))


def _bad_cases(data: bytes) -> dict[str, tuple[bytes, int, str]]:
    man = _manifest(data)
    plan = json.loads(zipfile.ZipFile(io.BytesIO(data)).read("plan.json"))
    v2 = {**man, "format_version": 2}
    tampered = json.dumps({**plan, "approved_by": "someone else"}).encode()
    listed_missing = {n["name"]: None for n in man["files"] if n["name"].startswith("photos/")}
    bomb = io.BytesIO()
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("manifest.json", json.dumps(man))
        zf.writestr("plan.json", b"\0" * (2 * 1024 * 1024))  # 2 MiB of zeros, ~2 KiB zipped
    return {
        "not a zip": (b"this is not a zip archive at all", 400, "not a zip"),
        "missing manifest": (rezip(data, {"manifest.json": None}), 422, "no manifest.json"),
        "unknown version": (
            rezip(data, {"manifest.json": json.dumps(v2).encode()}),
            422,
            "unknown format version 2",
        ),
        "tampered file": (rezip(data, {"plan.json": tampered}), 422, "sha256 mismatch"),
        "listed but missing": (rezip(data, listed_missing), 422, "not in the archive"),
        "not listed": (rezip(data, {}, {"executions/ex_extra.json": b"{}"}), 422, "manifest"),
        "traversal": (rezip(data, {}, {"../x": b"boo"}), 400, "unsafe file name"),
        "absolute": (rezip(data, {}, {"/etc/x": b"boo"}), 400, "unsafe file name"),
        "nested traversal": (rezip(data, {}, {"photos/../../x.png": b"b"}), 400, "unsafe"),
        "zip bomb": (bomb.getvalue(), 413, "unpacks to"),
    }


def test_every_bad_archive_is_refused_and_leaves_nothing(small_archive, make_api, tmp_path):
    _, _, data = small_archive
    # Upload limit 0.25 MiB: the archive fits, 4× that bounds what it unpacks to.
    dst = make_api(tmp_path / "dst", max_upload_mb=0.25)
    assert len(data) < 0.25 * 1024 * 1024
    before = snapshot(dst)
    for name, (body, status, words) in _bad_cases(data).items():
        r = upload(dst, body)
        assert r.status_code == status, (name, r.status_code, r.text)
        assert words in r.json()["detail"], (name, r.text)
        assert snapshot(dst) == before, name
    big = upload(dst, np.random.default_rng(1).bytes(300 * 1024))
    assert big.status_code == 413 and "upload limit" in big.json()["detail"]
    assert snapshot(dst) == before
    # The untouched archive still imports, all of it.
    r = upload(dst, data)
    assert r.status_code == 201, r.text
    counts, files = snapshot(dst)
    assert counts["plans"] == before[0]["plans"] + 1 and counts["clouds"] == 1
    assert counts["findings"] == 2 and counts["finding_photos"] == 3
    assert sum(f.startswith("photos/") for f in files) == 3
    assert not [f for f in files if f.startswith("uploads/")]


def test_an_archive_of_too_many_entries_is_refused_before_unpacking(make_api, tmp_path):
    dst = make_api(tmp_path / "dst")
    many = io.BytesIO()
    with zipfile.ZipFile(many, "w") as zf:
        for i in range(10_001):
            zf.writestr(f"photos/fd_x/ph_{i}.png", b"")
    before = snapshot(dst)
    r = upload(dst, many.getvalue())
    assert r.status_code == 413 and "10001 entries" in r.json()["detail"], r.text
    assert snapshot(dst) == before


def test_a_failure_while_writing_rolls_back_rows_and_files(small_archive, make_api, tmp_path):
    """A finding id already here (another import's) → 409, and the files it had
    moved into place are gone again."""
    _, _, data = small_archive
    dst = make_api(tmp_path / "dst")
    fid = json.loads(zipfile.ZipFile(io.BytesIO(data)).read("findings.json"))["findings"][0]["id"]
    with dst.services.store.db.transaction() as conn:
        conn.execute(
            "INSERT INTO findings (id, plan_id, type, condition_state, created_by, created_at)"
            " VALUES (?, 'pl_other', 'other', 1, 't', 't')",
            (fid,),
        )
    before = snapshot(dst)
    r = upload(dst, data)
    assert r.status_code == 409 and fid in r.json()["detail"], r.text
    assert snapshot(dst) == before

    # A stray file where the last photo goes: the cloud and the first photos
    # were already moved into place when it is found; they are removed again.
    other = make_api(tmp_path / "other")
    photos = json.loads(zipfile.ZipFile(io.BytesIO(data)).read("findings.json"))["photos"]
    stray = Path(other.services.store.data_dir) / "photos" / photos[-1]["row"]["id"]
    stray.parent.mkdir(parents=True, exist_ok=True)
    stray.write_bytes(b"not mine")
    before = snapshot(other)
    r = upload(other, data)
    assert r.status_code == 409 and "not overwritten" in r.json()["detail"], r.text
    assert snapshot(other) == before and stray.read_bytes() == b"not mine"


def test_export_needs_a_token_and_a_plan(small_archive) -> None:
    src, pid, _ = small_archive
    assert src.client.get(f"/api/v1/plans/{pid}/export").status_code == 401
    assert src.get("/api/v1/plans/pl_nope/export", "viewer").status_code == 404


def test_a_clouds_colour_and_intensity_travel_with_it(make_api, tmp_path):
    """The per-point attributes an upload kept (rgb, intensity, classification)
    are exported beside the points and imported under the new server's names."""
    src = make_api(tmp_path / "src")
    store = src.services.store
    rng = np.random.default_rng(5)
    cid = "cl_attrs0001"
    pts = rng.normal(size=(300, 3))
    attrs = {
        "rgb": rng.integers(0, 65535, size=(300, 3), dtype=np.uint16),
        "intensity": rng.integers(0, 65535, size=300, dtype=np.uint16),
        "classification": rng.integers(0, 20, size=300, dtype=np.uint8),
    }
    store.arrays.save(f"clouds/{cid}.npy", pts)
    for name, arr in attrs.items():
        store.arrays.save(f"clouds/{cid}.{name}.npy", arr)
    bounds = {"min": pts.min(axis=0).tolist(), "max": pts.max(axis=0).tolist()}
    store.register_cloud(
        cid, "coloured", "upload:c.las", 300, bounds, 0, "surveyor (tk_s)", attributes=list(attrs)
    )
    plan = store.create_plan("demo.route", {"cloud_id": cid}, "planner (tk_p)")
    data = export(src, plan.id)
    assert {f"cloud/{cid}.{n}.npy" for n in attrs} <= set(
        zipfile.ZipFile(io.BytesIO(data)).namelist()
    )
    dst = make_api(tmp_path / "dst")
    r = upload(dst, data)
    assert r.status_code == 201, r.text
    got = dst.services.store
    assert sorted(got.get_cloud(cid).attributes) == sorted(attrs)
    for name, arr in attrs.items():
        assert np.array_equal(got.cloud_attribute(cid, name, mmap=False), arr)
