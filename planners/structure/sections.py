"""Standard steel sections and the surface of a prismatic member.

Dimensions are the nominal values of the European tables:

* IPE, HEA, HEB: EN 10365:2017 (same values as the former DIN 1025-2/-3/-5,
  Euronorm 19-57 / 53-62);
* UPN channels: EN 10365 (DIN 1026-1, tapered flanges: ``tf`` is the mean
  flange thickness the table quotes), UPE channels: EN 10365 (parallel flanges);
* equal angles L: EN 10056-1;
* tees T: EN 10055 (equal-leg hot-rolled tees);
* SHS / CHS hot-finished hollow sections: EN 10210-2;
* flat plate FL: EN 10058 (width × thickness).

``area_m2`` is the tabulated cross-section area (including root fillets and
corner radii); the outline used here drops fillets and radii (sharp corners),
so its area is a few per cent below the table.

A member is the section outline swept along its centroid line: local ``v``
runs along the depth ``h`` (the web for I, channel, tee; "up" for roll 0 on a
non-vertical member), local ``u`` along the width ``b``.  The outline is
placed with its centroid on the axis.  End faces are not sampled: members end
at joints where the ends are hidden in connections, and leaving them off
keeps every surface point within the outline radius of the axis segment.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from planners.errors import InvalidInputError

PROFILES: tuple[str, ...] = ("I", "channel", "angle", "tee", "box", "tube", "plate")

#: Chord angle (radians) of the polygon standing in for a tube's circle.
_TUBE_SEGMENT_RAD = np.deg2rad(5.0)


@dataclass(frozen=True)
class Section:
    """A cross-section: depth ``h``, width ``b``, web ``tw``, flange ``tf`` (metres).

    For angles ``h``/``b`` are the two leg lengths, ``tw`` the thickness of the
    ``h`` leg and ``tf`` of the ``b`` leg; for box and tube ``tw = tf`` is the
    wall (tube: ``h = b`` the outside diameter); for a plate ``h`` is its
    thickness and ``b`` its width.
    """

    name: str
    profile: str
    h: float
    b: float
    tw: float
    tf: float
    area_m2: float = 0.0

    def __post_init__(self) -> None:
        if self.profile not in PROFILES:
            raise InvalidInputError(
                f"section profile {self.profile!r} is not one of {', '.join(PROFILES)}"
            )
        dims = (self.h, self.b, self.tw, self.tf)
        if not all(np.isfinite(d) and d > 0 for d in dims):
            raise InvalidInputError(f"section {self.name!r}: h, b, tw, tf must be > 0, got {dims}")


def _mm(name: str, profile: str, h: float, b: float, tw: float, tf: float, a_cm2: float) -> Section:
    return Section(name, profile, h / 1e3, b / 1e3, tw / 1e3, tf / 1e3, a_cm2 / 1e4)


#: name → section (h, b, tw, tf in mm and area in cm² as printed in the tables).
SECTIONS: dict[str, Section] = {
    s.name: s
    for s in (
        _mm("IPE 200", "I", 200, 100, 5.6, 8.5, 28.5),
        _mm("IPE 300", "I", 300, 150, 7.1, 10.7, 53.8),
        _mm("IPE 400", "I", 400, 180, 8.6, 13.5, 84.5),
        _mm("IPE 500", "I", 500, 200, 10.2, 16.0, 116.0),
        _mm("HEA 200", "I", 190, 200, 6.5, 10.0, 53.8),
        _mm("HEA 300", "I", 290, 300, 8.5, 14.0, 112.5),
        _mm("HEB 200", "I", 200, 200, 9.0, 15.0, 78.1),
        _mm("HEB 300", "I", 300, 300, 11.0, 19.0, 149.1),
        _mm("HEB 400", "I", 400, 300, 13.5, 24.0, 197.8),
        _mm("UPN 200", "channel", 200, 75, 8.5, 11.5, 32.2),
        _mm("UPN 300", "channel", 300, 100, 10.0, 16.0, 58.8),
        _mm("UPE 200", "channel", 200, 80, 6.0, 11.0, 29.0),
        _mm("L 80x80x8", "angle", 80, 80, 8.0, 8.0, 12.3),
        _mm("L 100x100x10", "angle", 100, 100, 10.0, 10.0, 19.2),
        _mm("L 120x120x12", "angle", 120, 120, 12.0, 12.0, 27.5),
        _mm("T 100", "tee", 100, 100, 11.0, 11.0, 20.9),
        _mm("SHS 150x150x8", "box", 150, 150, 8.0, 8.0, 44.8),
        _mm("SHS 200x200x10", "box", 200, 200, 10.0, 10.0, 74.9),
        _mm("CHS 168.3x8", "tube", 168.3, 168.3, 8.0, 8.0, 40.3),
        _mm("CHS 219.1x10", "tube", 219.1, 219.1, 10.0, 10.0, 65.7),
        _mm("FL 300x20", "plate", 20, 300, 20.0, 20.0, 60.0),
    )
}


def _raw_outline(s: Section) -> np.ndarray:
    """Counter-clockwise (K, 2) outline in (u, v), not yet centred."""
    h, b, tw, tf = s.h, s.b, s.tw, s.tf
    if s.profile == "I":
        u0, u1 = -b / 2, -tw / 2
        pts = [
            (u0, 0), (-u0, 0), (-u0, tf), (-u1, tf), (-u1, h - tf), (-u0, h - tf),
            (-u0, h), (u0, h), (u0, h - tf), (u1, h - tf), (u1, tf), (u0, tf),
        ]  # fmt: skip
    elif s.profile == "channel":
        pts = [(0, 0), (b, 0), (b, tf), (tw, tf), (tw, h - tf), (b, h - tf), (b, h), (0, h)]
    elif s.profile == "angle":
        pts = [(0, 0), (b, 0), (b, tf), (tw, tf), (tw, h), (0, h)]
    elif s.profile == "tee":
        pts = [
            (-tw / 2, 0), (tw / 2, 0), (tw / 2, h - tf), (b / 2, h - tf),
            (b / 2, h), (-b / 2, h), (-b / 2, h - tf), (-tw / 2, h - tf),
        ]  # fmt: skip
    elif s.profile == "tube":
        n = int(np.ceil(2 * np.pi / _TUBE_SEGMENT_RAD))
        a = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
        return np.stack([np.cos(a), np.sin(a)], axis=1) * (h / 2)
    else:  # box, plate: the outer rectangle
        pts = [(0, 0), (b, 0), (b, h), (0, h)]
    return np.asarray(pts, dtype=float)


def polygon_area_centroid(poly: np.ndarray) -> tuple[float, np.ndarray]:
    """Signed area and centroid of a closed (K, 2) polygon (shoelace)."""
    x, y = poly[:, 0], poly[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = 0.5 * float(cross.sum())
    cx = float(((x + xn) * cross).sum()) / (6 * area)
    cy = float(((y + yn) * cross).sum()) / (6 * area)
    return area, np.array([cx, cy])


def section_outline(s: Section) -> np.ndarray:
    """(K, 2) counter-clockwise outline in (u, v) metres, centroid at the origin.

    A tube's circle is a 72-gon; its outward normals are taken radial
    (see :func:`member_surface_points`), so the facets only shave < 0.1 % off the radius.
    """
    poly = _raw_outline(s)
    _, c = polygon_area_centroid(poly)
    return poly - c


def outline_area(s: Section) -> float:
    """Area (m²) enclosed by the outline; for box and tube the steel area (outer − inner)."""
    if s.profile == "box":
        return s.h * s.b - (s.h - 2 * s.tw) * (s.b - 2 * s.tw)
    if s.profile == "tube":
        return float(np.pi * (s.h - s.tw) * s.tw)
    return polygon_area_centroid(_raw_outline(s))[0]


def outline_radius(s: Section) -> float:
    """Largest distance (m) from the centroid to the outline: the member's envelope radius."""
    return float(np.linalg.norm(section_outline(s), axis=1).max())


def member_frame(p0: np.ndarray, p1: np.ndarray, roll: float) -> np.ndarray:
    """(3, 3) rows ``u``, ``v``, ``d``: section axes and unit axis direction.

    Roll 0 puts ``v`` (the depth) in the vertical plane through the axis,
    pointing up; a vertical member takes world +y as its roll-0 ``v``.
    Roll turns ``u``, ``v`` about ``d`` (right hand).
    """
    d = np.asarray(p1, float) - np.asarray(p0, float)
    n = float(np.linalg.norm(d))
    if not np.isfinite(n) or n <= 0:
        raise InvalidInputError("a member needs two distinct, finite end points")
    d = d / n
    ref = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.999 else np.array([0.0, 1.0, 0.0])
    v = ref - d * float(ref @ d)
    v /= np.linalg.norm(v)
    u = np.cross(v, d)
    c, s = np.cos(roll), np.sin(roll)
    return np.stack([c * u + s * v, -s * u + c * v, d])


class _Perimeter:
    """The outline as arc-length segments, for sampling points on it."""

    def __init__(self, s: Section) -> None:
        self.tube = s.profile == "tube"
        self.poly = section_outline(s)
        self.edges = np.roll(self.poly, -1, axis=0) - self.poly
        self.lengths = np.linalg.norm(self.edges, axis=1)
        self.cum = np.concatenate([[0.0], np.cumsum(self.lengths)])

    @property
    def length(self) -> float:
        return float(self.cum[-1])

    def at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points at arc lengths ``t`` and their outward unit normals, (n, 2) each."""
        k = np.clip(np.searchsorted(self.cum, t, side="right") - 1, 0, len(self.poly) - 1)
        frac = (t - self.cum[k]) / self.lengths[k]
        pts = self.poly[k] + frac[:, None] * self.edges[k]
        if self.tube:
            return pts, pts / np.linalg.norm(pts, axis=1, keepdims=True)
        e = self.edges[k] / self.lengths[k, None]
        return pts, np.stack([e[:, 1], -e[:, 0]], axis=1)  # CCW outline: outward is to the right


def iter_member_surface(
    section: Section,
    p0: np.ndarray,
    p1: np.ndarray,
    roll: float,
    spacing: float,
    rng: np.random.Generator,
    *,
    chunk_points: int = 500_000,
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Yield (points, normals) chunks covering the member surface at ``spacing``.

    Stratified (jittered-grid) sampling: ``ceil(perimeter / spacing)`` strata
    round the outline times ``ceil(length / spacing)`` along the axis, one
    uniform point per stratum; chunks hold at most ``chunk_points`` points
    (whole axial rows) so memory stays bounded for long members at fine spacing.
    """
    if not (np.isfinite(spacing) and spacing > 0):
        raise InvalidInputError(f"spacing must be > 0 metres, got {spacing!r}")
    p0 = np.asarray(p0, float)
    frame = member_frame(p0, p1, roll)
    length = float(np.linalg.norm(np.asarray(p1, float) - p0))
    per = _Perimeter(section)
    n_per = max(1, int(np.ceil(per.length / spacing)))
    n_ax = max(1, int(np.ceil(length / spacing)))
    rows = max(1, chunk_points // n_per)
    for r0 in range(0, n_ax, rows):
        r1 = min(n_ax, r0 + rows)
        m = (r1 - r0) * n_per
        arc = (np.tile(np.arange(n_per), r1 - r0) + rng.random(m)) * (per.length / n_per)
        ax = (np.repeat(np.arange(r0, r1), n_per) + rng.random(m)) * (length / n_ax)
        uv, nuv = per.at(arc)
        yield _lift(uv, frame, p0, ax), _lift(nuv, frame, None, None)


def _lift(
    uv: np.ndarray, frame: np.ndarray, origin: np.ndarray | None, ax: np.ndarray | None
) -> np.ndarray:
    """(n, 2) section coordinates (+ axial offsets) → (n, 3), one column at a time.

    Three 1-D multiply-adds per column beat ``uv @ frame[:2]`` several times
    over: numpy's matmul with an inner size of 2 does not go to BLAS.
    """
    out = np.empty((len(uv), 3))
    u, v = uv[:, 0], uv[:, 1]
    for j in range(3):
        col = u * frame[0, j] + v * frame[1, j]
        if ax is not None:
            col += ax * frame[2, j]
        if origin is not None:
            col += origin[j]
        out[:, j] = col
    return out


def member_surface_points(
    section: Section,
    p0: np.ndarray,
    p1: np.ndarray,
    roll: float,
    spacing: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """(M, 3) points on the member's outer surface and (M, 3) unit outward normals.

    The member is ``section`` swept from ``p0`` to ``p1`` (centroid line),
    turned by ``roll`` radians about its axis (see :func:`member_frame`);
    points are ``spacing`` metres apart on average (jittered grid).
    """
    chunks = list(iter_member_surface(section, p0, p1, roll, spacing, rng))
    return (
        np.concatenate([c[0] for c in chunks]),
        np.concatenate([c[1] for c in chunks]),
    )
