"""Large arrays (clouds, trajectories) as ``.npy`` files beside the database.

Files are written to a temporary name, flushed to disk and renamed into
place (``os.replace`` is atomic on POSIX), so a crash mid-write never leaves a
truncated array under a name a database row refers to.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np


class ArrayStore:
    """Write and read arrays under ``root`` by relative name."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)

    def path(self, relname: str) -> Path:
        p = (self.root / relname).resolve()
        if self.root.resolve() not in p.parents:
            raise ValueError(f"array name {relname!r} escapes the data directory")
        return p

    def save(self, relname: str, array: np.ndarray) -> str:
        target = self.path(relname)
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=".tmp-", suffix=".npy")
        try:
            with os.fdopen(fd, "wb") as fh:
                np.save(fh, np.asarray(array), allow_pickle=False)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, target)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return relname

    def load(self, relname: str, mmap: bool = False) -> np.ndarray:
        return np.load(self.path(relname), mmap_mode="r" if mmap else None, allow_pickle=False)

    def delete(self, relname: str) -> None:
        self.path(relname).unlink(missing_ok=True)

    def delete_tree(self, relname: str) -> None:
        d = self.path(relname)
        if d.is_dir():
            for f in d.iterdir():
                f.unlink(missing_ok=True)
            d.rmdir()
