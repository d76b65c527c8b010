"""The world a built-in emulator's camera sees: the plan's scan, as a file.

The ARA emulator takes ``--world PATH``: an ``.npz`` with ``points`` (N,3)
float32 in the plan's ``world`` frame (and optionally ``intensity`` (N,)
uint8), reloaded when the file changes; its ``capture`` command answers with
the points its simulated camera sees.  When the server dispatches a plan to a
built-in emulator that takes a world (:data:`WORLD_ROBOTS`), it writes that
file from the plan's scan first (:func:`write_plan_world`): the plan's
stored ``points`` array, else the stored cloud its params name
(``cloud_id``), else no points at all — never the previous plan's scan.
Above :data:`MAX_WORLD_POINTS` every ``stride``-th point is kept.

The file is ``<data>/emulators/<robot>.world.npz`` (:func:`world_path`),
written under a temporary name and renamed into place, so the emulator never
reads half a file.
"""

from __future__ import annotations

import logging
import math
import os
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from server.store import PlanRecord, Store

log = logging.getLogger(__name__)

#: Robots whose emulator simulates a camera over a world file.
WORLD_ROBOTS = ("ara",)
#: At most this many points are written (stride-thinned above it).
MAX_WORLD_POINTS = 2_000_000


def world_path(data: Path | str, robot: str) -> Path:
    """Where the built-in emulator of ``robot`` reads its world."""
    return Path(data) / "emulators" / f"{robot}.world.npz"


def plan_scan(store: Store, plan: PlanRecord) -> tuple[np.ndarray, np.ndarray | None, str]:
    """The plan's scan in its world frame: points (N,3) float32, intensity
    (N,) uint8 or ``None``, and where they came from."""
    from server.store import NotFoundError

    pts: np.ndarray | None = None
    inten: np.ndarray | None = None
    source = "no scan (the plan stores no points array and names no stored cloud)"
    if "points" in plan.arrays:
        raw = np.asarray(plan.array("points"))
        if raw.ndim == 2 and raw.shape[1] >= 3:
            pts = raw[:, :3]
            source = f"stored array 'points' of plan {plan.id}"
            if "intensity" in plan.arrays:
                inten = np.asarray(plan.array("intensity")).reshape(-1)
    if pts is None:
        cid = plan.params.get("cloud_id")
        if isinstance(cid, str) and cid:
            try:
                pts = np.asarray(store.cloud_points(cid))[:, :3]
                source = f"stored cloud {cid} of plan {plan.id}"
            except (NotFoundError, OSError):
                source = f"the plan's cloud {cid} is no longer stored: no scan"
    if pts is None:
        return np.zeros((0, 3), np.float32), None, source
    keep = np.isfinite(pts).all(axis=1)
    if inten is not None and len(inten) != len(pts):
        inten = None
    pts = pts[keep]
    inten = None if inten is None else inten[keep]
    stride = max(1, math.ceil(len(pts) / MAX_WORLD_POINTS))
    if stride > 1:
        source += f", every {stride}. point"
        pts = pts[::stride]
        inten = None if inten is None else inten[::stride]
    out_i = None if inten is None else np.clip(inten, 0, 255).astype(np.uint8)
    return np.ascontiguousarray(pts, dtype=np.float32), out_i, source


def write_world(path: Path, points: np.ndarray, intensity: np.ndarray | None = None) -> Path:
    """Write a world file atomically (temporary name, fsync, rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, Any] = {"points": np.ascontiguousarray(points, dtype=np.float32)}
    if intensity is not None:
        arrays["intensity"] = np.ascontiguousarray(intensity, dtype=np.uint8)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, **arrays)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def write_plan_world(store: Store, plan: PlanRecord, robot: str, data: Path | str) -> Path | None:
    """Write ``robot``'s emulator world from ``plan``'s scan (``None``: its
    emulator takes no world).  Errors are logged, never raised: a dispatch
    does not fail for the emulator's scenery."""
    if robot not in WORLD_ROBOTS:
        return None
    path = world_path(data, robot)
    try:
        pts, inten, source = plan_scan(store, plan)
        write_world(path, pts, inten)
    except Exception:
        log.exception("could not write the emulator world of %s for plan %s", robot, plan.id)
        return None
    log.info("emulator world of %s: %d points, %s", robot, len(pts), source)
    return path
