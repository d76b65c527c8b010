"""Archive imports against zip bombs: a few hundred KB of
zip whose entry inflates to 200 MB of zeros under a wrong SHA-256 or a
smaller declared size is refused with 422 without that entry reaching the
disk; an archive declaring more in all than the limit is refused before any
entry is read; nothing is left behind; a good archive still imports."""

from __future__ import annotations

import hashlib
import io
import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.api.test_archive import add_findings, export, snapshot, upload

BIG = 200 * 1024 * 1024  # zeros: about 200 KB deflated
MiB = 1024 * 1024


def written() -> int:
    """Bytes this process (all its threads) has passed to write() so far."""
    for line in Path("/proc/self/io").read_text().splitlines():
        if line.startswith("wchar:"):
            return int(line.split()[1])
    raise AssertionError("no wchar in /proc/self/io")


needs_proc_io = pytest.mark.skipif(
    not Path("/proc/self/io").exists(), reason="counts writes through Linux's /proc/self/io"
)


@pytest.fixture
def archive(make_api: Any, tmp_path: Path) -> bytes:
    """A plan with its source cloud and findings, exported from a first server."""
    src = make_api(tmp_path / "src")
    store = src.services.store
    pts = np.random.default_rng(3).normal(size=(500, 3))
    cloud = store.add_cloud("girder", "test.xyz", pts, 0, "surveyor (tk_s)")
    plan = store.create_plan("demo.route", {"cloud_id": cloud.id}, "planner (tk_p)")
    add_findings(src, plan.id)
    return export(src, plan.id)


def rebuilt(
    data: bytes,
    *,
    zeros: tuple[str, int] | None = None,
    listed: dict[str, Any] | None = None,
    replace: dict[str, bytes] | None = None,
) -> bytes:
    """``data`` with entries ``replace``d (their manifest lines updated), plus an
    entry of ``zeros[1]`` zero bytes written 1 MiB at a time (nothing large in
    memory), listed first in the manifest as ``listed`` says (default: its
    true size, a wrong SHA-256)."""
    replace = replace or {}
    out = io.BytesIO()
    with (
        zipfile.ZipFile(io.BytesIO(data)) as src,
        zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as dst,
    ):
        manifest = json.loads(src.read("manifest.json"))
        for f in manifest["files"]:
            if f["name"] in replace:
                body = replace[f["name"]]
                f.update(size=len(body), sha256=hashlib.sha256(body).hexdigest())
        if zeros is not None:
            name, size = zeros
            line = {"name": name, "size": size, "sha256": "0" * 64, **(listed or {})}
            manifest["files"].insert(0, line)  # first: unpacked before anything else
        dst.writestr("manifest.json", json.dumps(manifest))
        for info in src.infolist():
            if info.filename != "manifest.json":
                dst.writestr(info.filename, replace.get(info.filename) or src.read(info))
        if zeros is not None:
            chunk = bytes(MiB)
            with dst.open(zeros[0], "w") as fh:
                for _ in range(zeros[1] // MiB):
                    fh.write(chunk)
    return out.getvalue()


def test_the_bomb_is_small(archive: bytes) -> None:
    bomb = rebuilt(archive, zeros=("arrays/zeros.npy", BIG))
    assert len(bomb) < len(archive) + 400 * 1024
    with zipfile.ZipFile(io.BytesIO(bomb)) as zf:
        assert zf.getinfo("arrays/zeros.npy").file_size == BIG


@needs_proc_io
def test_a_wrong_sha256_is_found_before_the_entry_is_written(
    archive: bytes, make_api: Any, tmp_path: Path
) -> None:
    dst = make_api(tmp_path / "dst")
    before = snapshot(dst)
    bomb = rebuilt(archive, zeros=("arrays/zeros.npy", BIG))
    start = written()
    r = upload(dst, bomb)
    grew = written() - start
    assert r.status_code == 422, r.text
    detail = r.json()["detail"]
    assert "arrays/zeros.npy" in detail and "sha256 mismatch" in detail, detail
    assert str(tmp_path) not in detail and "/tmp" not in detail
    assert grew < 16 * MiB, f"{grew} bytes written for a refused archive"
    assert snapshot(dst) == before  # no temporary file left behind


@needs_proc_io
def test_an_entry_larger_than_its_manifest_says_is_refused_unread(
    archive: bytes, make_api: Any, tmp_path: Path
) -> None:
    dst = make_api(tmp_path / "dst")
    before = snapshot(dst)
    bomb = rebuilt(archive, zeros=("arrays/zeros.npy", BIG), listed={"size": 1000})
    start = written()
    r = upload(dst, bomb)
    grew = written() - start
    assert r.status_code == 422, r.text
    detail = r.json()["detail"]
    assert detail.startswith("arrays/zeros.npy unpacks to") and "1000" in detail, detail
    assert grew < 16 * MiB, f"{grew} bytes written for a refused archive"
    assert snapshot(dst) == before


def test_an_archive_declaring_more_than_the_limit_is_refused_before_reading(
    archive: bytes, make_api: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Upload limit 1 MiB: an archive may unpack to 4 MiB in all; this one declares 8."""
    dst = make_api(tmp_path / "dst", max_upload_mb=1)
    before = snapshot(dst)
    bomb = rebuilt(archive, zeros=("arrays/zeros.npy", 8 * MiB))
    opened: list[str] = []
    original = zipfile.ZipFile.open

    def spy(self: zipfile.ZipFile, name: Any, *args: Any, **kw: Any) -> Any:
        opened.append(getattr(name, "filename", name))
        return original(self, name, *args, **kw)

    monkeypatch.setattr(zipfile.ZipFile, "open", spy)
    r = upload(dst, bomb)
    assert r.status_code == 413 and "unpacks to" in r.json()["detail"], r.text
    assert opened == []  # not even the manifest
    assert snapshot(dst) == before


def test_messages_hold_no_path_or_library_text(
    archive: bytes, make_api: Any, tmp_path: Path
) -> None:
    """A cloud .npy that is not one (its manifest line right): 422 in our words."""
    dst = make_api(tmp_path / "dst")
    with zipfile.ZipFile(io.BytesIO(archive)) as zf:
        (npy,) = [n for n in zf.namelist() if n.startswith("cloud/") and n.endswith(".npy")]
    r = upload(dst, rebuilt(archive, replace={npy: b"not an array at all" * 10}))
    assert r.status_code == 422, r.text
    assert r.json()["detail"] == f"{npy} is not a readable .npy array"


def test_a_good_archive_still_imports(archive: bytes, make_api: Any, tmp_path: Path) -> None:
    dst = make_api(tmp_path / "dst")
    r = upload(dst, archive)
    assert r.status_code == 201, r.text
    counts, files = snapshot(dst)
    assert counts["findings"] == 2 and counts["finding_photos"] == 3
    assert not [f for f in files if f.startswith("uploads/")]
