"""Leftovers after a crash (issue #12 §6): temp files and unreferenced arrays go, referenced stay."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from server.store import Store
from server.store.cleanup import cleanup_leftovers


def _plant(data: Path) -> dict[str, Path]:
    planted = {
        "tmp_array": data / "arrays" / "clouds" / ".tmp-abc123.npy",
        "tmp_plan": data / "arrays" / "plans" / "pl_gone" / ".tmp-x.npy",
        "orphan_cloud": data / "arrays" / "clouds" / "cl_000000000000.npy",
        "orphan_plan": data / "arrays" / "plans" / "pl_000000000000" / "route.npy",
        "spool": data / "uploads" / ".tmp-upload-xyz.part",
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
    before = {p: p.read_bytes() for p in kept}
    planted = _plant(data)
    with caplog.at_level(logging.WARNING, logger="server.store.cleanup"):
        removed = cleanup_leftovers(store)
    assert removed == sorted(str(p.relative_to(data)) for p in planted.values())
    assert not any(p.exists() for p in planted.values())
    assert {p: p.read_bytes() for p in kept} == before  # referenced arrays untouched
    assert (data / "arrays" / "README.txt").read_text() == "keep me"
    assert not (data / "arrays" / "plans" / "pl_gone").exists()  # emptied plan dirs go
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
