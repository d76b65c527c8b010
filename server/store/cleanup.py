"""Remove what a crash left behind.

A ``kill -9`` can leave, in the data directory:

* temporary files, which the server writes under a temporary name and
  renames into place only once finished: ``.tmp-*`` under ``arrays/`` (a
  half-written array, :class:`~server.store.arrays.ArrayStore` and the cloud
  parser), ``captures/`` (a robot's capture being stored) and ``uploads/``
  (a spooled upload), ``photos/*.part`` (a finding's
  photo) and ``robots/.*.tmp`` (a robot's link secret being replaced);
* ``uploads/import-*/``: a plan archive being unpacked (``POST /imports``);
* files written *before* the row that refers to them is committed, so that a
  crash in between leaves an orphan (never a row without its file): ``.npy``
  arrays under ``arrays/`` that no ``clouds.array_file`` or ``plans.arrays``
  names, capture arrays under ``captures/`` that no ``execution_captures``
  row names, and photos under ``photos/`` that no ``finding_photos`` row names;
* ``emulators/.*.tmp``: a built-in emulator's world or saved state being
  replaced (only once untouched for :data:`EMULATOR_TMP_MIN_AGE_S`: an
  emulator outlives a crashed server and may be writing it still);

and in the system's temporary directory (``tempfile.gettempdir()``): a plan
export being zipped (``steelpath-export-*.zip``), a rosbag2 being written
(``steelpath-bag-*/``) and an E57 upload copied for its reader
(``.tmp-e57-*.e57``).

Several servers may share one data directory, and a server must
not delete what another one is still writing.  So each server holds a shared
``flock`` on ``<data>/.steelpath-server.lock`` for as long as it runs (the
kernel drops it when the process dies, ``kill -9`` included); at start,
:func:`clean_at_start` first tries to take it exclusively.  Alone, it removes
every leftover, however new.  Beside a running server it removes only those
untouched for :data:`STALE_S` (an upload being spooled or a file being
written changes all the time; six hours is far beyond any single write).  The
system temporary directory is shared by every server of this user on the
machine, whatever its data directory: the same rule applies there with a lock
of its own (``<tmp>/steelpath-<uid>.lock``), and only this user's entries are
looked at.

Every removal is logged.  Nothing else is touched: not a file that is neither
a temporary nor an orphan, not a symlink, nothing outside the places above.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import logging
import os
import shutil
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

log = logging.getLogger(__name__)

#: A leftover is this old (seconds since its last change) before it is removed
#: while another server uses the same directory.
STALE_S = 6 * 3600.0
#: The lock every running server holds (shared) on its data directory.
LOCK_NAME = ".steelpath-server.lock"

#: Directories (relative to the data directory) that hold arrays and spools.
SCANNED = ("arrays", "captures", "uploads")
#: Directories (relative to the data directory) whose ``.*.tmp`` files are temporaries.
HIDDEN_TMP_DIRS = ("robots", "emulators")
#: Built-in emulators outlive a crashed server (they are reused by the next
#: one), so a temporary of theirs is removed only once untouched this long
#: (seconds), even by a server alone: each of their writes takes milliseconds.
EMULATOR_TMP_MIN_AGE_S = 60.0
#: Name patterns of the server's own entries in the system temporary directory.
SYSTEM_TEMP_PATTERNS = ("steelpath-export-*.zip", "steelpath-bag-*", ".tmp-e57-*.e57")


def referenced_arrays(store: Any) -> set[str]:
    """Relative names (under ``arrays/``) of every array a row refers to."""
    refs: set[str] = set()
    for row in store.db.query("SELECT array_file, attributes FROM clouds"):
        refs.add(row["array_file"])
        try:  # the cloud's per-point attribute arrays, beside its points
            attrs = json.loads(row["attributes"] or "{}") or {}
        except (TypeError, ValueError):
            attrs = {}
        if isinstance(attrs, dict):
            refs.update(str(v) for v in attrs.values())
    for row in store.db.query("SELECT arrays FROM plans WHERE arrays IS NOT NULL"):
        try:
            names = json.loads(row["arrays"]) or {}
        except (TypeError, ValueError):
            continue  # an unreadable column references nothing we could keep by name
        if isinstance(names, dict):
            refs.update(str(v) for v in names.values())
    return {str(Path(r)) for r in refs if r}


def referenced_captures(store: Any) -> set[str]:
    """Relative names (under ``captures/``) of every capture array a row refers to."""
    refs: set[str] = set()
    for row in store.db.query("SELECT points_file, intensity_file FROM execution_captures"):
        refs.update(str(Path(v)) for v in (row["points_file"], row["intensity_file"]) if v)
    return refs


def referenced_photos(store: Any) -> set[str]:
    """Ids (file names under ``photos/``) of every photo a row refers to."""
    return {str(r["id"]) for r in store.db.query("SELECT id FROM finding_photos")}


def _newest_change(path: Path) -> float:
    """The latest modification time of ``path`` and, for a directory, of anything in it."""
    newest = path.lstat().st_mtime
    if path.is_dir() and not path.is_symlink():
        for root, dirs, files in os.walk(path):
            for name in dirs + files:
                with contextlib.suppress(OSError):
                    newest = max(newest, os.lstat(os.path.join(root, name)).st_mtime)
    return newest


def _data_leftovers(store: Any) -> Iterator[tuple[Path, str]]:
    """Every leftover in the data directory, with what it is."""
    data = Path(store.data_dir)
    arrays_root = Path(store.arrays.root)
    # What rows name, and how an unnamed array is described, per directory.
    named: dict[Path, tuple[set[str], str]] = {
        arrays_root: (referenced_arrays(store), "unreferenced array"),
        data / "captures": (referenced_captures(store), "unreferenced capture"),
    }
    for top in SCANNED:
        root = data / top
        if not root.is_dir():
            continue
        if top == "uploads":
            for d in sorted(root.glob("import-*")):
                if d.is_dir() and not d.is_symlink():
                    yield d, "unfinished import"
        keep, orphan = named.get(root, (None, ""))
        for path in sorted(root.rglob("*")):
            if not path.is_file() or path.is_symlink():
                continue
            if top == "uploads" and path.relative_to(root).parts[0].startswith("import-"):
                continue  # goes with its import directory
            if path.name.startswith(".tmp-"):
                yield path, "temporary file"
            elif (
                path.suffix == ".npy"
                and keep is not None
                and (str(path.relative_to(root)) not in keep)
            ):
                yield path, orphan
    photos = data / "photos"
    if photos.is_dir():
        photo_ids = referenced_photos(store)
        for path in sorted(photos.iterdir()):
            if not path.is_file() or path.is_symlink():
                continue
            if path.suffix == ".part":
                yield path, "temporary file"
            elif path.name.startswith("ph_") and not path.suffix and path.name not in photo_ids:
                yield path, "unreferenced photo"
    for top in HIDDEN_TMP_DIRS:
        d = data / top
        if d.is_dir():
            for path in sorted(d.glob(".*.tmp")):
                if path.is_file() and not path.is_symlink():
                    yield path, "temporary file"


def _system_temp_leftovers(temp_dir: Path) -> Iterator[tuple[Path, str]]:
    """This user's SteelPath entries in the system temporary directory."""
    uid = os.getuid()
    for pattern in SYSTEM_TEMP_PATTERNS:
        for path in sorted(temp_dir.glob(pattern)):
            with contextlib.suppress(OSError):
                st = path.lstat()
                if st.st_uid == uid and not path.is_symlink():
                    yield path, "temporary file"


def _remove(path: Path, what: str, shown: str, min_age_s: float, now: float) -> bool:
    """Remove one leftover unless it changed in the last ``min_age_s``; logged."""
    try:
        if min_age_s > 0 and now - _newest_change(path) < min_age_s:
            return False  # perhaps another server's write in progress
        if path.is_dir():
            size = sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
            shutil.rmtree(path)
        else:
            size = path.stat().st_size
            path.unlink()
    except OSError as exc:
        log.warning("could not remove leftover %s: %s", shown, exc)
        return False
    log.warning("removed %s left by an earlier crash: %s (%d bytes)", what, shown, size)
    return True


def cleanup_leftovers(
    store: Any,
    *,
    min_age_s: float = 0.0,
    temp_dir: Path | None = None,
    temp_min_age_s: float = STALE_S,
) -> list[str]:
    """Delete the leftovers listed in this module's docstring; the removed paths, sorted.

    Data-directory paths are relative to it; system-temporary ones (looked at
    only when ``temp_dir`` is given) absolute.  An entry changed less than
    ``min_age_s`` (``temp_min_age_s`` in ``temp_dir``) seconds ago is kept.
    """
    data = Path(store.data_dir)
    now = time.time()
    removed: list[str] = []
    for path, what in list(_data_leftovers(store)):
        rel = str(path.relative_to(data))
        age = min_age_s
        if path.parent == data / "emulators":
            age = max(age, EMULATOR_TMP_MIN_AGE_S)
        if _remove(path, what, rel, age, now):
            removed.append(rel)
    if temp_dir is not None and temp_dir.is_dir():
        for path, what in list(_system_temp_leftovers(temp_dir)):
            if _remove(path, what, str(path), temp_min_age_s, now):
                removed.append(str(path))
    for holder in (Path(store.arrays.root) / "plans", data / "captures"):
        if not holder.is_dir():
            continue
        for d in sorted(holder.iterdir()):
            if d.is_dir() and not d.is_symlink() and not any(d.iterdir()):
                with contextlib.suppress(OSError):  # another server may be filling it now
                    d.rmdir()  # a deleted or never-finished plan's (execution's) directory
    return sorted(removed)


@dataclass
class RunLock:
    """A ``flock`` held on a lock file: exclusive while cleaning alone, then shared."""

    path: Path
    handle: IO[bytes]
    alone: bool

    @classmethod
    def take(cls, path: Path) -> RunLock:
        """Open ``path`` and lock it: exclusively when no other server holds it
        (``alone``), else shared (waiting out another server's cleaning)."""
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)
        handle = os.fdopen(fd, "r+b")
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            alone = True
        except BlockingIOError:
            fcntl.flock(fd, fcntl.LOCK_SH)
            alone = False
        return cls(path, handle, alone)

    def share(self) -> None:
        """Let other servers start beside this one (they will see it running)."""
        fcntl.flock(self.handle.fileno(), fcntl.LOCK_SH)

    def release(self) -> None:
        self.handle.close()  # closing drops the lock


@dataclass
class RunLocks:
    """What a running server holds (:func:`clean_at_start`); release at shutdown."""

    locks: list[RunLock]
    removed: list[str]

    def release(self) -> None:
        for lock in self.locks:
            lock.release()


def clean_at_start(store: Any, *, temp_dir: Path | None = None) -> RunLocks:
    """Take this server's locks and remove leftovers, all of them where no other
    server runs on the same directory, else only stale ones (module docstring).

    Call it before any job or upload can write; keep the result for the
    server's life and :meth:`RunLocks.release` it at shutdown.
    """
    temp = Path(temp_dir or tempfile.gettempdir())
    data_lock = RunLock.take(Path(store.data_dir) / LOCK_NAME)
    locks = [data_lock]
    temp_lock: RunLock | None = None
    try:
        temp_lock = RunLock.take(temp / f"steelpath-{os.getuid()}.lock")
        locks.append(temp_lock)
    except OSError as exc:  # an unwritable temporary directory: leave it alone
        log.warning("not cleaning %s: cannot lock it (%s)", temp, exc)
    try:
        removed = cleanup_leftovers(
            store,
            min_age_s=0.0 if data_lock.alone else STALE_S,
            temp_dir=temp if temp_lock is not None else None,
            temp_min_age_s=0.0 if temp_lock is not None and temp_lock.alone else STALE_S,
        )
    finally:
        for lock in locks:
            lock.share()
    return RunLocks(locks, removed)
