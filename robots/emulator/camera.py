"""The emulator's depth camera: what a ``capture`` command sees of a world point cloud.

``--world PATH`` (:class:`World`) is an ``.npz`` with ``points`` (N, 3)
float32 in the program's world frame and optionally ``intensity`` (N,)
uint8; it is reloaded whenever its modification time (or size) changes —
the server rewrites it at each dispatch.  At most :data:`MAX_WORLD_POINTS`
points; a file that breaks a rule is refused with a :class:`WorldError`
naming it.

:func:`render` takes the world points inside the camera's frustum
(``hfov``/``vfov``, ``min_range``…``max_range`` along the view axis, all
from ``[camera]`` of the robot's ``params.toml``), keeps the nearest point
per pixel of a ``width_px`` × ``height_px`` grid (occlusion), adds axial
range noise ``σ(z) = s0 + s2 (z − 0.4)²`` along each point's ray with a
seeded generator, and thins to ``max_points`` deterministically (evenly
over the pixels, in pixel order).  Vectorised and chunked: the world is
walked in blocks of :data:`BLOCK` points, each reduced to the few points in
front of the camera before anything else is computed.  The world is indexed
once per load (:class:`Cloud`: sorted by 1 m grid cell), so a capture only
looks at the cells its frustum's bounding box meets: its cost depends on the
points near the camera, not on the size of the world.

A world (re)load happens in the emulator's loop at the first capture after
the file changed (≈ 0.1 s per million points); the robot's watchdog does not
count that time against the host (:meth:`SimRobot._capture
<robots.emulator.robot.SimRobot>`).
"""

from __future__ import annotations

import logging
import math
import os
import time
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from robots.protocol.capture import MAX_POINT_M
from robots.protocol.commands import MAX_WORLD_M
from robots.protocol.messages import MAX_CAPTURE_POINTS

log = logging.getLogger(__name__)

#: A world larger than this is refused (≈ 240 MB of float32 points).
MAX_WORLD_POINTS = 20_000_000
#: World points transformed per block (bounds the temporary arrays to a few MB).
BLOCK = 1 << 18


class WorldError(ValueError):
    """A world file that cannot be used (names the file and the rule it breaks)."""


@dataclass(frozen=True)
class CameraSpec:
    """A depth camera fixed to the base: pose, field of view, range, noise, output size."""

    camera_to_base: np.ndarray  # (4, 4): camera (optical: z view, x right, y down) → base
    hfov_rad: float
    vfov_rad: float
    width_px: int
    height_px: int
    min_range_m: float
    max_range_m: float
    noise_sigma0_m: float = 0.0
    noise_sigma2_per_m: float = 0.0
    max_points: int = MAX_CAPTURE_POINTS

    def __post_init__(self) -> None:
        if not (0 < self.hfov_rad < math.pi and 0 < self.vfov_rad < math.pi):
            raise ValueError("camera field of view must be within (0, 180°)")
        if not 0 < self.min_range_m < self.max_range_m <= MAX_POINT_M:
            raise ValueError(
                f"camera range {self.min_range_m}…{self.max_range_m} m: must be "
                f"0 < min < max ≤ {MAX_POINT_M} m (i16 millimetres on the wire)"
            )
        if self.width_px < 1 or self.height_px < 1:
            raise ValueError("camera grid must be at least 1 × 1 pixels")
        if not 0 <= self.max_points <= MAX_CAPTURE_POINTS:
            raise ValueError(f"camera max_points must be 0…{MAX_CAPTURE_POINTS}")

    @classmethod
    def from_params(cls, camera: dict[str, Any], camera_to_base: np.ndarray) -> CameraSpec:
        """From a ``[camera]`` table of params.toml and the URDF's camera joint."""
        return cls(
            camera_to_base=np.asarray(camera_to_base, dtype=float),
            hfov_rad=math.radians(float(camera["hfov_deg"])),
            vfov_rad=math.radians(float(camera["vfov_deg"])),
            width_px=int(camera["width_px"]),
            height_px=int(camera["height_px"]),
            min_range_m=float(camera["min_range_m"]),
            max_range_m=float(camera["max_range_m"]),
            noise_sigma0_m=float(camera.get("noise_sigma0_m", 0.0)),
            noise_sigma2_per_m=float(camera.get("noise_sigma2_per_m", 0.0)),
            max_points=min(int(camera.get("max_points", MAX_CAPTURE_POINTS)), MAX_CAPTURE_POINTS),
        )


def load_world(path: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray | None]:
    """``points`` (N, 3) float32 and ``intensity`` (N,) uint8 or None of a world file."""
    p = Path(path)
    try:
        with np.load(p, allow_pickle=False) as data:
            if "points" not in data.files:
                raise WorldError(f"world {p}: no 'points' array (has {sorted(data.files)})")
            raw = data["points"]
            inten = data["intensity"] if "intensity" in data.files else None
    except WorldError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise WorldError(f"world {p}: cannot read an .npz ({exc})") from exc
    if raw.ndim != 2 or raw.shape[1] != 3:
        raise WorldError(f"world {p}: points of shape {raw.shape}, expected (N, 3)")
    if len(raw) > MAX_WORLD_POINTS:
        raise WorldError(f"world {p}: {len(raw):,} points > {MAX_WORLD_POINTS:,} allowed")
    if raw.dtype.kind not in "fiu":
        raise WorldError(f"world {p}: points of dtype {raw.dtype}, expected float32")
    pts = np.ascontiguousarray(raw, dtype=np.float32)
    if len(pts) and (not np.isfinite(pts).all() or float(np.abs(pts).max()) > MAX_WORLD_M):
        raise WorldError(
            f"world {p}: points must be finite and within ±{MAX_WORLD_M:g} m "
            "(a local frame: subtract the plan's world origin)"
        )
    if inten is not None:
        if inten.shape != (len(pts),):
            raise WorldError(f"world {p}: intensity of shape {inten.shape}, expected ({len(pts)},)")
        if inten.dtype != np.uint8:
            raise WorldError(f"world {p}: intensity of dtype {inten.dtype}, expected uint8")
        inten = np.ascontiguousarray(inten)
    return pts, inten


class World:
    """A world file, reloaded when it changes; :meth:`current` is what the camera sees."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.cloud: Cloud | None = None
        self._stamp: tuple[int, int] | None = None
        self.loads = 0
        self.error: str | None = None

    def _stat(self) -> tuple[int, int] | None:
        try:
            st = self.path.stat()
        except OSError:
            return None
        return st.st_mtime_ns, st.st_size

    def load(self) -> None:
        """Load the file now if it exists; raises :class:`WorldError` if it is unusable."""
        stamp = self._stat()
        if stamp is None:
            return
        self.cloud = Cloud.build(*load_world(self.path))
        self._stamp, self.error = stamp, None
        self.loads += 1

    def current(self) -> tuple[Cloud | None, str]:
        """(cloud, why-none): reloads first if the file changed.

        A file that vanished keeps nothing; a file that cannot be used keeps
        nothing either (the reason is logged once per change and returned).
        """
        stamp = self._stat()
        if stamp is None:
            if self._stamp is not None or self.error is None:
                log.warning("world %s: no such file; captures see nothing", self.path)
            self.cloud = None
            self._stamp = None
            self.error = f"world file {self.path} does not exist"
            return None, self.error
        if stamp != self._stamp:
            self._stamp = stamp
            t0 = time.perf_counter()
            try:
                self.cloud = Cloud.build(*load_world(self.path))
            except WorldError as exc:
                self.cloud = None
                self.error = str(exc)
                log.error("%s; captures see nothing until the file changes", exc)
            else:
                self.error = None
                self.loads += 1
                log.info(
                    "world %s: %d points loaded in %.0f ms",
                    self.path,
                    len(self.cloud),
                    (time.perf_counter() - t0) * 1000,
                )
        if self.cloud is None:
            return None, self.error or "no world"
        return self.cloud, ""


@dataclass(frozen=True)
class Cloud:
    """A world laid out for the camera: coordinates as three contiguous float32
    arrays, sorted by the :data:`CELL_M` grid cell they fall in, so that the
    points near the camera are a few slices (:meth:`near`)."""

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    intensity: np.ndarray | None
    keys: np.ndarray  # (C,) int64: the occupied cells, increasing
    starts: np.ndarray  # (C + 1,) int64: cell c holds points starts[c] … starts[c+1] − 1

    def __len__(self) -> int:
        return len(self.x)

    @classmethod
    def build(cls, points: np.ndarray, intensity: np.ndarray | None = None) -> Cloud:
        pts = np.asarray(points, dtype=np.float32).reshape(-1, 3)
        cell = _cells(pts)
        key = _key(cell[:, 0], cell[:, 1], cell[:, 2])
        order = np.argsort(key, kind="stable")
        key = key[order]
        first = np.flatnonzero(np.r_[True, key[1:] != key[:-1]]) if len(key) else key
        keys = key[first]
        starts = np.append(first, len(key)).astype(np.int64)
        inten = None if intensity is None else np.ascontiguousarray(intensity[order])
        return cls(
            x=np.ascontiguousarray(pts[order, 0]),
            y=np.ascontiguousarray(pts[order, 1]),
            z=np.ascontiguousarray(pts[order, 2]),
            intensity=inten,
            keys=keys,
            starts=starts,
        )

    def near(self, lo: np.ndarray, hi: np.ndarray) -> list[slice]:
        """Slices of the points in every cell that meets the box ``lo`` … ``hi`` (world)."""
        c_lo = np.floor(np.clip(lo, -MAX_WORLD_M, MAX_WORLD_M) / CELL_M).astype(np.int64)
        c_hi = np.floor(np.clip(hi, -MAX_WORLD_M, MAX_WORLD_M) / CELL_M).astype(np.int64)
        out: list[slice] = []
        for ix in range(int(c_lo[0]), int(c_hi[0]) + 1):
            for iy in range(int(c_lo[1]), int(c_hi[1]) + 1):
                # Cells of one (ix, iy) column are consecutive keys (iz varies fastest).
                a, b = np.searchsorted(
                    self.keys, [_key(ix, iy, c_lo[2]), _key(ix, iy, c_hi[2])], side="left"
                )
                b2 = b + int(b < len(self.keys) and self.keys[b] == _key(ix, iy, c_hi[2]))
                if b2 > a:
                    out.append(slice(int(self.starts[a]), int(self.starts[b2])))
        return out


#: Grid cell of the world index, metres.
CELL_M = 1.0
_OFF = 4096  # cell indices are offset by this (|index| ≤ 2000 / CELL_M)
_SPAN = 2 * _OFF


def _cells(pts: np.ndarray) -> np.ndarray:
    return np.floor(pts.astype(np.float64) / CELL_M).astype(np.int64)


def _key(ix: Any, iy: Any, iz: Any) -> Any:
    return ((np.int64(ix) + _OFF) * _SPAN + (np.int64(iy) + _OFF)) * _SPAN + (np.int64(iz) + _OFF)


def render(
    spec: CameraSpec,
    world: Cloud | np.ndarray,
    intensity: np.ndarray | None,
    camera_to_world: np.ndarray,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray | None]:
    """What the camera at ``camera_to_world`` sees of ``world``.

    ``world``: a :class:`Cloud` (its own intensities; ``intensity`` is then
    ignored) or (N, 3) world points with ``intensity`` (N,) or ``None``.
    Returns camera-frame points (K, 3) float32, K ≤ ``spec.max_points``, in
    pixel order, and their intensities (K,) uint8 (``None`` without).
    """
    cloud = world if isinstance(world, Cloud) else Cloud.build(world, intensity)
    T = np.asarray(camera_to_world, dtype=np.float64)
    R = T[:3, :3]
    tan_h = math.tan(spec.hfov_rad / 2)
    tan_v = math.tan(spec.vfov_rad / 2)
    # The frustum is the hull of the camera and its far rectangle: its bounding
    # box picks the grid cells worth looking at.
    far = spec.max_range_m
    corners = np.array(
        [[sx * tan_h * far, sy * tan_v * far, far] for sx in (-1, 1) for sy in (-1, 1)]
    )
    hull = np.vstack([T[:3, 3], corners @ R.T + T[:3, 3]])
    parts = cloud.near(hull.min(axis=0), hull.max(axis=0))
    # Camera coordinates c = Rᵀ (p − t) = Rᵀ p − Rᵀ t, one coordinate at a time
    # (contiguous float32 arithmetic: a (N, 3) @ (3, 3) product is 15× slower).
    Rf = R.astype(np.float32)
    off = (R.T @ T[:3, 3]).astype(np.float32)
    zs, xs, ys, idx = [], [], [], []
    for part in parts:
        for start in range(part.start, part.stop, BLOCK):
            blk = slice(start, min(part.stop, start + BLOCK))
            X, Y, Z = cloud.x[blk], cloud.y[blk], cloud.z[blk]
            z = X * Rf[0, 2]
            z += Y * Rf[1, 2]
            z += Z * Rf[2, 2]
            z -= off[2]
            sel = np.flatnonzero((z >= spec.min_range_m) & (z <= spec.max_range_m))
            if not len(sel):
                continue
            Xs, Ys, Zs, zk = X[sel], Y[sel], Z[sel], z[sel]
            x = Xs * Rf[0, 0] + Ys * Rf[1, 0] + Zs * Rf[2, 0] - off[0]
            y = Xs * Rf[0, 1] + Ys * Rf[1, 1] + Zs * Rf[2, 1] - off[1]
            inside = (np.abs(x) <= tan_h * zk) & (np.abs(y) <= tan_v * zk)
            if not inside.any():
                continue
            zs.append(zk[inside])
            xs.append(x[inside])
            ys.append(y[inside])
            idx.append(sel[inside] + start)
    if not zs:
        none = None if cloud.intensity is None else np.zeros(0, dtype=np.uint8)
        return np.zeros((0, 3), dtype=np.float32), none
    z = np.concatenate(zs)
    x = np.concatenate(xs)
    y = np.concatenate(ys)
    src = np.concatenate(idx)
    W, H = spec.width_px, spec.height_px
    u = np.minimum(((x / z * (1.0 / tan_h) + 1.0) * (0.5 * W)).astype(np.int64), W - 1)
    v = np.minimum(((y / z * (1.0 / tan_v) + 1.0) * (0.5 * H)).astype(np.int64), H - 1)
    pix = v * W + u
    # Occlusion: the nearest point of each pixel (of equally near ones, the last
    # in the world's order); the winners come out in pixel order.
    zmin = np.full(W * H, np.inf, dtype=np.float32)
    np.minimum.at(zmin, pix, z)
    front = np.flatnonzero(z == zmin[pix])
    owner = np.full(W * H, -1, dtype=np.int64)
    owner[pix[front]] = front
    win = owner[owner >= 0]
    k = len(win)
    if k > spec.max_points:
        win = win[(np.arange(spec.max_points) * k) // spec.max_points]
    zw = z[win].astype(np.float64)
    sigma = spec.noise_sigma0_m + spec.noise_sigma2_per_m * (zw - 0.4) ** 2
    zn = np.clip(zw + rng.standard_normal(len(win)) * sigma, 1e-3, MAX_POINT_M / 2)
    scale = zn / zw  # axial noise: move each point along its ray
    out = np.empty((len(win), 3), dtype=np.float32)
    out[:, 0] = x[win] * scale
    out[:, 1] = y[win] * scale
    out[:, 2] = zn
    ok = np.all(np.abs(out) < MAX_POINT_M, axis=1)  # what i16 millimetres can carry
    if not ok.all():
        out, win = out[ok], win[ok]
    inten = None if cloud.intensity is None else cloud.intensity[src[win]]
    return out, inten


__all__ = [
    "BLOCK",
    "CELL_M",
    "MAX_WORLD_POINTS",
    "CameraSpec",
    "Cloud",
    "World",
    "WorldError",
    "load_world",
    "render",
]
