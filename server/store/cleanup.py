"""Remove what a crash left in the data directory (issue #12 §6).

A ``kill -9`` can leave, under ``arrays/`` and ``uploads/``:

* temporary files (``.tmp-*``): a half-written array or spooled upload —
  :class:`~server.store.arrays.ArrayStore` and the upload parser write under
  such names and rename only finished files into place;
* finished ``.npy`` arrays that no database row references: arrays are
  written *before* the row that refers to them is committed, so a crash in
  between leaves an orphan (never a row without its array).

:func:`cleanup_leftovers` runs at start, before any job or upload can be
writing, removes exactly those files (and plan directories left empty) and
logs each removal.  An array is kept when ``clouds.array_file`` or any value
of ``plans.arrays`` names it; nothing outside ``arrays/`` and ``uploads/`` is
touched, and nothing that is neither a temporary file nor an ``.npy``.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

#: Directories (relative to the data directory) that hold arrays and spools.
SCANNED = ("arrays", "uploads")


def referenced_arrays(store: Any) -> set[str]:
    """Relative names (under ``arrays/``) of every array a row refers to."""
    refs = {r["array_file"] for r in store.db.query("SELECT array_file FROM clouds")}
    for row in store.db.query("SELECT arrays FROM plans WHERE arrays IS NOT NULL"):
        try:
            names = json.loads(row["arrays"]) or {}
        except (TypeError, ValueError):
            continue  # an unreadable column references nothing we could keep by name
        if isinstance(names, dict):
            refs.update(str(v) for v in names.values())
    return {str(Path(r)) for r in refs if r}


def cleanup_leftovers(store: Any) -> list[str]:
    """Delete temporary files and unreferenced arrays; the removed paths, relative
    to the data directory, sorted."""
    data = Path(store.data_dir)
    arrays_root = Path(store.arrays.root)
    keep = referenced_arrays(store)
    removed: list[str] = []
    for top in SCANNED:
        root = data / top
        if not root.is_dir():
            continue
        for path in sorted(root.rglob("*")):
            if not path.is_file() or path.is_symlink():
                continue
            temp = path.name.startswith(".tmp-")
            orphan = (
                path.suffix == ".npy"
                and root == arrays_root
                and str(path.relative_to(arrays_root)) not in keep
            )
            if not (temp or orphan):
                continue
            rel = str(path.relative_to(data))
            try:
                size = path.stat().st_size
                path.unlink()
            except OSError as exc:
                log.warning("could not remove leftover %s: %s", rel, exc)
                continue
            log.warning(
                "removed %s left by an earlier crash: %s (%d bytes)",
                "temporary file" if temp else "unreferenced array",
                rel,
                size,
            )
            removed.append(rel)
    plans_dir = arrays_root / "plans"
    if plans_dir.is_dir():
        for d in sorted(plans_dir.iterdir()):
            if d.is_dir() and not d.is_symlink() and not any(d.iterdir()):
                d.rmdir()  # a deleted or never-finished plan's directory
    return sorted(removed)
