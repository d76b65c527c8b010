"""Leftovers after a crash: temporaries and unreferenced files go,
referenced data stays, and a server starting beside a running one leaves its
writes in progress alone."""

from __future__ import annotations

import contextlib
import io
import logging
import os
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest
from PIL import Image

from server.captures.service import record_capture
from server.store import Store
from server.store.cleanup import (
    EMULATOR_TMP_MIN_AGE_S,
    LOCK_NAME,
    STALE_S,
    RunLock,
    cleanup_leftovers,
)
from tests.api.test_captures import make_capture, make_execution
from tests.conftest import Api
from tests.support.serve import ServeProcess
from tests.support.waiting import wait_for


def _plant(data: Path) -> dict[str, Path]:
    planted = {
        "tmp_array": data / "arrays" / "clouds" / ".tmp-abc123.npy",
        "tmp_plan": data / "arrays" / "plans" / "pl_gone" / ".tmp-x.npy",
        "orphan_cloud": data / "arrays" / "clouds" / "cl_000000000000.npy",
        "orphan_plan": data / "arrays" / "plans" / "pl_000000000000" / "route.npy",
        "spool": data / "uploads" / ".tmp-upload-xyz.part",
        "tmp_capture": data / "captures" / "ex_gone" / ".tmp-c.npy",
        "orphan_capture": data / "captures" / "ex_000000000000" / "7.points.npy",
    }
    for p in planted.values():
        p.parent.mkdir(parents=True, exist_ok=True)
        with open(p, "wb") as fh:  # a real array (np.save would rename the .part)
            np.save(fh, np.zeros((2, 3)))
    other = data / "arrays" / "README.txt"  # neither temp nor .npy: never touched
    other.write_text("keep me")
    return planted


def test_cleanup_removes_leftovers_and_keeps_referenced_arrays(api, tmp_path, caplog) -> None:
    cloud = api.post("/api/v1/clouds", json={"sample": "demo_plane"}).json()
    plan = api.wait(api.submit("demo.route")["id"])
    assert plan["state"] == "planned" and plan["arrays"], plan
    store = api.services.store
    data = store.data_dir
    kept = [store.arrays.path(store.get_cloud(cloud["id"]).array_file)]
    kept += [store.arrays.path(rel) for rel in store.get_plan(plan["id"]).arrays.values()]
    # A capture a robot sent during an execution: its points and intensities stay.
    _plan, ex = make_execution(api)
    cap = record_capture(store, ex.id, make_capture(7, 50))
    assert cap is not None and cap.intensity_file is not None
    kept += [data / "captures" / cap.points_file, data / "captures" / cap.intensity_file]
    before = {p: p.read_bytes() for p in kept}
    planted = _plant(data)
    with caplog.at_level(logging.WARNING, logger="server.store.cleanup"):
        removed = cleanup_leftovers(store)
    assert removed == sorted(str(p.relative_to(data)) for p in planted.values())
    assert not any(p.exists() for p in planted.values())
    assert {p: p.read_bytes() for p in kept} == before  # referenced arrays untouched
    assert (data / "arrays" / "README.txt").read_text() == "keep me"
    assert not (data / "arrays" / "plans" / "pl_gone").exists()  # emptied plan dirs go
    assert not (data / "captures" / "ex_gone").exists()  # and emptied execution dirs
    got = api.get(f"/api/v1/executions/{ex.id}/captures/7", "viewer")
    assert got.status_code == 200 and got.json()["returned_points"] == 50
    for rel in removed:
        assert rel in caplog.text
    # The stored cloud and plan still read back through the API.
    pts = api.get(f"/api/v1/clouds/{cloud['id']}/points.npy", "viewer")
    assert pts.status_code == 200
    arr = next(iter(plan["arrays"]))
    assert api.get(f"/api/v1/plans/{plan['id']}/arrays/{arr}", "viewer").status_code == 200
    assert cleanup_leftovers(store) == []  # idempotent


def test_app_start_cleans_the_data_directory(make_api, tmp_path) -> None:
    data = tmp_path / "var"
    Store(data).close()
    planted = _plant(data)
    make_api(data=data)
    assert not any(p.exists() for p in planted.values())


# ------------------------------------------------- every kind of temporary
def _image() -> bytes:
    buf = io.BytesIO()
    Image.new("RGB", (4, 3), (180, 90, 40)).save(buf, format="PNG")
    return buf.getvalue()


def _write(path: Path, size: int = 1024) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(os.urandom(size))
    return path


def _plant_every_kind(data: Path, temp: Path, tag: str) -> dict[str, Path]:
    """One leftover of each kind the server writes, named with ``tag``: what a
    crash in the middle of each write leaves (names as the server makes them)."""
    hexes = tag.encode().hex().ljust(12, "0")[:12]
    imp_empty = data / "uploads" / f"import-{hexes}"
    imp_empty.mkdir(parents=True)  # the archive's unpacking had not begun
    imp_half = data / "uploads" / f"import-{hexes[::-1]}"
    _write(imp_half / ".tmp-0")
    _write(imp_half / ".tmp-1", 4096)
    bag = temp / f"steelpath-bag-{tag}"
    _write(bag / "ex_1" / "ex_1_0.db3")
    # An emulator (it outlives a crashed server) writes its temporaries in
    # milliseconds: a leftover of one is at least a minute old.
    emulator = {
        "world_tmp": _write(data / "emulators" / f".ara.world.{tag}.tmp", 4096),
        "emulator_state_tmp": _write(data / "emulators" / f".ara.state.json.{tag}.tmp", 64),
    }
    _age(emulator, EMULATOR_TMP_MIN_AGE_S + 60)
    return emulator | {
        "photo_part": _write(data / "photos" / f"ph_{hexes}.part", 2 * 1024 * 1024),
        "orphan_photo": _write(data / "photos" / f"ph_{hexes[::-1]}"),
        "import_empty": imp_empty,
        "import_half": imp_half,
        "array_tmp": _write(data / "arrays" / "clouds" / f".tmp-{tag}.npy"),
        "spool": _write(data / "uploads" / f".tmp-upload-{tag}.part"),
        "secret_tmp": _write(data / "robots" / f".ara.key.{len(tag)}4242.tmp", 65),
        "capture_tmp": _write(data / "captures" / f"ex_{hexes}" / f".tmp-{tag}.npy"),
        "orphan_capture": _write(data / "captures" / f"ex_{hexes}" / "3.points.npy"),
        "export": _write(temp / f"steelpath-export-{tag}.zip"),
        "bag": bag,
        "e57": _write(temp / f".tmp-e57-{tag}.e57"),
    }


def _age(paths: dict[str, Path], seconds: float) -> None:
    """Make ``paths`` (and what directories hold) look last changed ``seconds`` ago."""
    then = time.time() - seconds
    for p in paths.values():
        for q in [p, *(p.rglob("*") if p.is_dir() else [])]:
            os.utime(q, (then, then))


def _real_data(api: Api) -> dict[str, Any]:
    """A cloud, a planned plan with arrays, a finding with a photo: what must survive."""
    cloud = api.post("/api/v1/clouds", json={"sample": "demo_plane"}).json()
    plan = api.wait(api.submit("ara.inspect", {"sample_seed": 2})["id"], timeout=120)
    assert plan["state"] == "planned" and plan["arrays"], plan.get("error")
    member = plan["result"]["members"][0]
    finding = api.post(
        "/api/v1/findings",
        json={
            "plan_id": plan["id"],
            "member_id": member["id"],
            "point_m": list(np.asarray(member["faces"][0]["outline"]).mean(axis=0)),
            "type": "corrosion",
            "condition_state": 2,
        },
    ).json()
    png = _image()
    photo = api.post(
        f"/api/v1/findings/{finding['id']}/photos", files={"file": ("a.png", png, "image/png")}
    ).json()
    store = api.services.store
    files = [store.arrays.path(store.get_cloud(cloud["id"]).array_file)]
    files += [store.arrays.path(rel) for rel in store.get_plan(plan["id"]).arrays.values()]
    files += [store.data_dir / "photos" / photo["id"], store.data_dir / "robots" / "ara.key"]
    return {
        "cloud": cloud,
        "plan": plan,
        "photo": photo,
        "png": png,
        "bytes": {p: p.read_bytes() for p in files},
    }


def _check_real_data(api: Api, real: dict[str, Any]) -> None:
    assert {p: p.read_bytes() for p in real["bytes"]} == real["bytes"]
    assert api.get(f"/api/v1/clouds/{real['cloud']['id']}/points.npy", "viewer").status_code == 200
    plan = real["plan"]
    for name in plan["arrays"]:
        r = api.get(f"/api/v1/plans/{plan['id']}/arrays/{name}", "viewer")
        assert r.status_code == 200, name
    got = api.get(real["photo"]["url"], "viewer")
    assert got.status_code == 200 and got.content == real["png"]


@pytest.fixture
def system_temp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A system temporary directory of this test's own (the server's ``tempfile``)."""
    temp = tmp_path / "systmp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    return temp


def test_a_restart_removes_every_kind_of_temporary(
    make_api: Any, tmp_path: Path, system_temp: Path, caplog: pytest.LogCaptureFixture
) -> None:
    data = tmp_path / "var"
    first = make_api(data=data)
    real = _real_data(first)
    first.client.__exit__(None, None, None)
    planted = _plant_every_kind(data, system_temp, "crash")
    unrelated = [
        _write(system_temp / "other-program.zip"),
        _write(data / "uploads" / "notes.txt"),
        _write(data / "photos" / "README"),
    ]
    with caplog.at_level(logging.WARNING, logger="server.store.cleanup"):
        second = make_api(data=data)
    left = {k: p for k, p in planted.items() if p.exists()}
    assert not left, left
    for p in planted.values():
        assert p.name in caplog.text
    assert all(p.exists() for p in unrelated)
    _check_real_data(second, real)


def test_beside_a_running_server_only_stale_leftovers_go(
    make_api: Any, tmp_path: Path, system_temp: Path
) -> None:
    """A second server sharing the data directory must not delete what the
    first is writing: fresh temporaries stay, ones untouched for longer than
    STALE_S go; once the first has stopped, a start removes the rest."""
    data = tmp_path / "var"
    first = make_api(data=data)
    writing = _plant_every_kind(data, system_temp, "inflight")
    stale = _plant_every_kind(data, system_temp, "stale")
    _age(stale, STALE_S + 60)
    second = make_api(data=data)
    assert all(p.exists() for p in writing.values())
    left = {k: p for k, p in stale.items() if p.exists()}
    assert not left, left
    second.client.__exit__(None, None, None)
    first.client.__exit__(None, None, None)
    make_api(data=data)  # alone now
    left = {k: p for k, p in writing.items() if p.exists()}
    assert not left, left


def test_an_emulators_fresh_temporary_survives_a_lone_start(make_api: Any, tmp_path: Path) -> None:
    """A built-in emulator outlives a crashed server and is reused by the next:
    the state file it is replacing right now is not a leftover."""
    data = tmp_path / "var"
    Store(data).close()
    fresh = _write(data / "emulators" / ".ara.state.json.abc123.tmp", 64)
    old = _write(data / "emulators" / ".ara.state.json.def456.tmp", 64)
    _age({"old": old}, EMULATOR_TMP_MIN_AGE_S + 1)
    state = _write(data / "emulators" / "ara.state.json", 64)
    make_api(data=data)
    assert fresh.exists() and state.exists()
    assert not old.exists()


def test_the_lock_says_whether_another_server_runs(tmp_path: Path) -> None:
    path = tmp_path / LOCK_NAME
    a = RunLock.take(path)
    assert a.alone
    a.share()
    b = RunLock.take(path)
    assert not b.alone  # a still runs
    a.release()
    b.release()
    c = RunLock.take(path)
    assert c.alone  # a killed process holds nothing: the kernel dropped its lock
    c.release()


def test_kill_9_during_an_upload_then_restart(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A real ``steelpath serve`` killed (SIGKILL) while it spools an upload, with
    a photo, an import and an export half-written beside it: the next start
    removes them all and keeps what was stored."""
    temp = tmp_path / "systmp"
    temp.mkdir()
    monkeypatch.setenv("TMPDIR", str(temp))  # the servers' tempfile.gettempdir()
    data = tmp_path / "var"
    data.mkdir()
    a = ServeProcess(data, "a")
    try:
        _kill_during_an_upload(a, data, temp)
    finally:
        a.stop()


def _kill_during_an_upload(a: ServeProcess, data: Path, temp: Path) -> None:
    cloud = a.post("/clouds", {"sample": "demo_plane"}, status=201)
    started = threading.Event()
    stop = threading.Event()

    def body() -> Iterator[bytes]:
        yield b"--b\r\nContent-Disposition: form-data; name=file; filename=big.xyz\r\n\r\n"
        while not stop.is_set():
            yield b"0.0 0.0 0.0\n" * 20000
            started.set()
            time.sleep(0.05)

    def upload() -> None:
        with contextlib.suppress(httpx.HTTPError):
            a.http.post(
                "/clouds",
                content=body(),
                headers={"Content-Type": "multipart/form-data; boundary=b"},
            )

    uploader = threading.Thread(target=upload, daemon=True)
    uploader.start()
    spools = wait_for(
        lambda: [p for p in (data / "uploads").glob(".tmp-upload-*.part") if p.stat().st_size],
        60,
        "the upload's first chunk in its spool file",
    )
    assert started.is_set()
    # The other writes, caught in the middle by the same crash.
    planted = _plant_every_kind(data, temp, "killed")
    a.kill9()
    stop.set()
    uploader.join(10)
    assert all(p.exists() for p in spools) and spools[0].stat().st_size > 0
    b = ServeProcess(data, "b", token=a.token)
    try:
        left = [p for p in [*spools, *planted.values()] if p.exists()]
        assert not left, (left, b.tail())
        got = b.http.get(f"/clouds/{cloud['id']}/points.npy")
        assert got.status_code == 200
        assert np.load(io.BytesIO(got.content)).shape == (5000, 3)
    finally:
        b.stop()
