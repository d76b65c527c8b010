"""Synthetic 3D steel structures as a terrestrial laser scanner sees them, with truth.

Test and benchmark material for :func:`planners.structure.model_structure`.

Structures (``SCAN_KINDS``), dimensions drawn per seed:

* ``"warren"`` / ``"pratt"``: a planar truss girder, 3–8 panels of 2–4 m,
  1.5–3 m deep, on bearings 0.5–1.5 m above the ground; chords I/H or
  channels (continuous members through the panel points), diagonals and
  verticals angles, channels or hollow sections;
* ``"frame"``: a 1–3 × 1–2 bay, 1–3 storey frame, HEB columns continuous
  from the ground, IPE beams between column faces, a few braced bays;
* ``"grillage"``: a horizontal deck grillage, 2–4 main girders (IPE/HEB,
  8–20 m) and cross girders between them, tops flush, main girder soffits
  1–3 m above the ground.

Members are prismatic (:mod:`.sections`): a section swept along the
centroid line, rolled about it.  Secondary members stop short of the
primary member's axis by about half its depth, so their ends overlap the
primary member's envelope as steel does at gusset and end plates.

TLS model, per scanner (2–4, at 1.5–2 m height, 5–12 m out from the
structure's footprint):

* a constant angular step ``dθ`` in azimuth and elevation, set from the
  requested ``spacing_m`` at the scanner's distance to the structure centre
  (times √scanners and a calibration factor, :data:`BIN_CALIBRATION`, so
  the median nearest-neighbour spacing of the merged member points is near
  ``spacing_m``); the density falls as 1/range² and the horizontal step
  shrinks with cos(elevation) as on a real scanner;
* first return: candidate points on every surface (members on a jittered
  grid at half the bin footprint at their nearest range, so a facing
  surface leaves no bin empty; the ground plane ray-cast, one ray per
  bin; vegetation volume-filled) and the nearest
  candidate per angular bin is kept, which casts occlusion shadows; back
  faces are dropped before binning (a closed prism always shows its
  front face first);
* range noise along the beam, σ = 2 mm + 0.1 mm/m (mid-range phase/pulse
  scanners quote 1–3 mm at 10 m); the point keeps its position on the
  surface across the bin (no snapping to the beam centre);
* clutter, label −1: the ground patch under the structure, 1–3 vegetation
  blobs (volume-filled ellipsoids, the first return gives a fuzzy shell), a
  person-sized box, and 0.2 % outliers (mixed pixels: copies of scan points
  moved 0.3–2 m along their beam).

Not modelled: beam divergence and mixed pixels at silhouettes (beyond the
outlier copies), intensity, incidence-dependent noise and dropout,
multipath, registration error between scanner set-ups, end faces of
members, bolts, gusset plates and stiffeners.

Cost (one core, seeds 0–1): 2 cm scans have 40–135 k points and take
0.1–0.8 s; 5 mm scans 0.6–2.1 M points in 1.5–16 s with a peak RSS of
0.8 GB (candidates are merged per 1.5 M, so memory follows the output, not
the candidates).  At 5 mm the range noise (2–4 mm σ) lifts the median
nearest-neighbour distance to 1.2–1.5 × ``spacing_m``.

Survey frame: the local scene is turned by a random yaw about z and moved to
UTM-like coordinates (x ≈ 4–6·10⁵ m, y ≈ 5.3–5.5·10⁶ m, z 50–500 m);
float64 resolves 10⁻⁹ m there.  Ground truth (axes, joints, scanners) is in
metres of the survey frame; ``points`` are in the output units, ``scale``
(1 or 1000) converts: truth in output units = truth × ``scale``.

Everything is a pure function of the arguments: no files, no global state;
an explicit ``numpy.random.Generator`` from ``seed`` drives every draw.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from planners.errors import InvalidInputError
from planners.structure.sections import (
    SECTIONS,
    Section,
    iter_member_surface,
    member_frame,
    outline_radius,
)

#: new kinds go at the end: a kind's index seeds its random stream
SCAN_KINDS: tuple[str, ...] = ("warren", "pratt", "frame", "grillage", "deck", "frame_slabs")
UNITS: dict[str, float] = {"m": 1.0, "mm": 1000.0}

#: Angular step = BIN_CALIBRATION × √(scanners) × spacing / reference range.
#: Measured (seeds 0–1, all kinds, 2–4 scanners) so the median nearest-neighbour
#: distance between member points of the merged scans comes out near
#: ``spacing_m``: with one bin per footprint it came out at 0.55 (2 scanners)
#: to 0.4 (4 scanners) of it, since a random point per bin has a nearer
#: neighbour than the bin pitch and overlapping scans add points.
BIN_CALIBRATION = 1.27
#: Range noise σ = NOISE_M + NOISE_PER_M × range (metres).
NOISE_M = 0.002
NOISE_PER_M = 1e-4
OUTLIER_FRACTION = 0.002
#: Candidate chunk size before a nearest-per-bin merge (bounds memory).
_MERGE_AT = 1_500_000
#: Candidate spacing / bin footprint: 0.5 puts a whole stratum in every bin.
_CANDIDATE_FACTOR = 0.5
_PERSON = Section("person", "box", 0.30, 0.45, 0.01, 0.01)


@dataclass(frozen=True)
class TrueMember:
    """A member as built: ``axis`` (2, 3) end points of the centroid line,
    metres in the survey frame; ``roll`` radians (see
    :func:`planners.structure.sections.member_frame`); ``role`` what it does
    in the structure (chord, diagonal, vertical, column, beam, brace, main, cross)."""

    id: int
    axis: np.ndarray
    section: Section
    roll: float
    role: str

    @property
    def length_m(self) -> float:
        return float(np.linalg.norm(self.axis[1] - self.axis[0]))


@dataclass(frozen=True)
class TrueJoint:
    """Where members meet: ``pos`` (3,) metres, survey frame, and the member ids."""

    pos: np.ndarray
    members: tuple[int, ...]


@dataclass
class ScanStructure:
    """A synthetic TLS scan with ground truth (see the module docstring).

    ``points`` (N, 3) float64 in ``units``; ``labels`` (N,) member id or −1;
    ``normals`` (N, 3) true outward surface normals (clutter without a surface:
    the unit vector to its scanner); ``scanner_index`` (N,) which scanner saw
    the point.  ``members``, ``joints``, ``scanners`` (S, 3), ``frame_offset``
    and ``ground_z`` are in metres of the survey frame; multiply by ``scale``
    to compare with ``points``.  ``yaw`` (radians) turned the local build
    frame about z before the offset was added.
    """

    kind: str
    seed: int
    points: np.ndarray
    labels: np.ndarray
    normals: np.ndarray
    scanner_index: np.ndarray
    members: list[TrueMember]
    joints: list[TrueJoint]
    scanners: np.ndarray
    spacing_m: float
    units: str
    scale: float
    frame_offset: np.ndarray
    yaw: float
    ground_z: float
    timings_s: dict[str, float] = field(default_factory=dict)
    #: the concrete's large faces as built (``deck`` and ``frame_slabs``):
    #: (kind, (4, 3) rectangle, metres, survey frame): a deck's or slab's
    #: soffit (``"deck/slab"``), a pier's long faces (``"wall"``) and the
    #: ground (``"ground"``, when there is clutter)
    surfaces: list[tuple[str, np.ndarray]] = field(default_factory=list)

    def true_axes(self) -> np.ndarray:
        """(T, 2, 3) member axes, metres, survey frame."""
        return np.stack([m.axis for m in self.members]) if self.members else np.zeros((0, 2, 3))

    def member_point_counts(self) -> np.ndarray:
        """(T,) scan points per member; 0 for a member hidden from every scanner."""
        lab = self.labels[self.labels >= 0]
        return np.bincount(lab, minlength=len(self.members))

    def true_depths(self) -> np.ndarray:
        """(T,) section depth ``h`` per member, metres."""
        return np.array([m.section.h for m in self.members], dtype=float)

    def match(self, found_axes: npt.ArrayLike) -> MemberMatch:
        """:func:`match_members` of found axes (F, 2, 3), metres in the survey frame."""
        return match_members(self.true_axes(), self.true_depths(), found_axes)


# --------------------------------------------------------------------------- layout


@dataclass
class _Build:
    """Members and joints in the local build frame (x span, z up, ground z = 0)."""

    sections: list[Section] = field(default_factory=list)
    axes: list[np.ndarray] = field(default_factory=list)
    rolls: list[float] = field(default_factory=list)
    roles: list[str] = field(default_factory=list)
    joints: list[tuple[np.ndarray, list[int]]] = field(default_factory=list)
    #: concrete (not members, label −1): axis-aligned boxes (lo (3,), hi (3,))
    #: and what each is (``"deck/slab"``, ``"wall"`` for a pier, ``"bearing"``)
    solids: list[tuple[np.ndarray, np.ndarray, str]] = field(default_factory=list)

    def add(self, sec: Section, p0: np.ndarray, p1: np.ndarray, roll: float, role: str) -> int:
        self.sections.append(sec)
        self.axes.append(np.array([p0, p1], dtype=float))
        self.rolls.append(float(roll))
        self.roles.append(role)
        return len(self.sections) - 1

    def joint(self, pos: np.ndarray, ids: list[int]) -> None:
        self.joints.append((np.asarray(pos, float), sorted(set(ids))))


def _pick(rng: np.random.Generator, names: tuple[str, ...]) -> Section:
    return SECTIONS[names[int(rng.integers(len(names)))]]


def _setback(p0: np.ndarray, p1: np.ndarray, s0: float, s1: float) -> tuple[np.ndarray, np.ndarray]:
    """Shorten the segment by ``s0`` at p0 and ``s1`` at p1 (each ≤ 30 % of it)."""
    d = p1 - p0
    n = float(np.linalg.norm(d))
    d = d / n
    return p0 + d * min(s0, 0.3 * n), p1 - d * min(s1, 0.3 * n)


_CHORDS = ("HEA 200", "HEA 300", "HEB 200", "HEB 300", "IPE 300", "UPN 300")
_WEB_MEMBERS = ("L 80x80x8", "L 100x100x10", "L 120x120x12", "UPN 200", "UPE 200",
                "SHS 150x150x8", "CHS 168.3x8", "T 100")  # fmt: skip


def _truss(kind: str, rng: np.random.Generator) -> _Build:
    n = int(rng.integers(3, 9))
    p = float(rng.uniform(2.0, 4.0))
    depth = float(rng.uniform(1.5, 3.0))
    chord = _pick(rng, _CHORDS)
    web = _pick(rng, _WEB_MEMBERS)
    z0 = float(rng.uniform(0.5, 1.5)) + chord.h / 2
    web_roll = float(rng.integers(4)) * np.pi / 2
    sb = 0.5 * chord.h
    b = _Build()
    if kind == "warren":
        bot = [np.array([i * p, 0, z0]) for i in range(n + 1)]
        top = [np.array([(i + 0.5) * p, 0, z0 + depth]) for i in range(n)]
        webs = [(bot[i], top[i]) for i in range(n)] + [(top[i], bot[i + 1]) for i in range(n)]
        if rng.random() < 0.3:
            webs += [(np.array([(i + 0.5) * p, 0, z0]), top[i]) for i in range(n)]
    else:
        bot = [np.array([i * p, 0, z0]) for i in range(n + 1)]
        top = [np.array([i * p, 0, z0 + depth]) for i in range(n + 1)]
        webs = [(bot[i], top[i]) for i in range(n + 1)]
        # Pratt: diagonals slope down towards mid-span
        webs += [(top[i], bot[i + 1]) if (i + 0.5) * p < n * p / 2 else (bot[i], top[i + 1])
                 for i in range(n)]  # fmt: skip
    cb = b.add(chord, bot[0], bot[-1], 0.0, "chord")
    ct = b.add(chord, top[0], top[-1], 0.0, "chord")
    at: dict[tuple[float, float], list[int]] = {}
    for q in bot:
        at[(q[0], q[2])] = [cb]
    for q in top:
        at.setdefault((q[0], q[2]), []).append(ct)
    for q0, q1 in webs:
        role = "vertical" if abs(q0[0] - q1[0]) < 1e-9 else "diagonal"
        a0, a1 = _setback(q0, q1, sb, sb)
        m = b.add(web, a0, a1, web_roll, role)
        for q in (q0, q1):
            at.setdefault((q[0], q[2]), [cb if q[2] == z0 else ct]).append(m)
    for (x, z), ids in at.items():
        if len(set(ids)) > 1:
            b.joint(np.array([x, 0.0, z]), ids)
    return b


def _frame(rng: np.random.Generator, slabs: bool = False) -> _Build:
    """A frame; with ``slabs``, 2–3 × 2–3 bays, 2–4 storeys and a concrete
    floor slab 0.15–0.25 m thick on the beams of every floor (the roof's
    too), 0.1–0.4 m past the columns' outer faces: the columns run on
    through them."""
    if slabs:
        nx, ny, ns = int(rng.integers(2, 4)), int(rng.integers(2, 4)), int(rng.integers(2, 5))
    else:
        nx, ny, ns = int(rng.integers(1, 4)), int(rng.integers(1, 3)), int(rng.integers(1, 4))
    xs = np.concatenate([[0.0], np.cumsum(rng.uniform(4.0, 8.0, nx))])
    ys = np.concatenate([[0.0], np.cumsum(rng.uniform(4.0, 7.0, ny))])
    zs = np.concatenate([[0.0], np.cumsum(rng.uniform(3.0, 4.5, ns))])
    col = _pick(rng, ("HEB 200", "HEB 300", "HEB 400"))
    bx = _pick(rng, ("IPE 300", "IPE 400", "IPE 500"))
    by = _pick(rng, ("IPE 200", "IPE 300"))
    brace = _pick(rng, ("SHS 150x150x8", "CHS 168.3x8", "L 100x100x10"))
    col_roll = float(rng.integers(2)) * np.pi / 2
    # roll 0 on a column puts its depth along y, so its half extent along x is b/2
    half_x = col.b / 2 if col_roll == 0 else col.h / 2
    half_y = col.h / 2 if col_roll == 0 else col.b / 2
    b = _Build()
    cols = {(i, j): b.add(col, np.array([x, y, 0.0]), np.array([x, y, zs[-1]]), col_roll, "column")
            for i, x in enumerate(xs) for j, y in enumerate(ys)}  # fmt: skip
    at: dict[tuple[int, int, int], list[int]] = {(i, j, 0): [c] for (i, j), c in cols.items()}
    for k in range(1, ns + 1):
        for j, y in enumerate(ys):
            for i in range(nx):
                z = zs[k] - bx.h / 2
                a0 = np.array([xs[i] + half_x, y, z])
                a1 = np.array([xs[i + 1] - half_x, y, z])
                m = b.add(bx, a0, a1, 0.0, "beam")
                at.setdefault((i, j, k), [cols[i, j]]).append(m)
                at.setdefault((i + 1, j, k), [cols[i + 1, j]]).append(m)
        for i, x in enumerate(xs):
            for j in range(ny):
                z = zs[k] - by.h / 2
                a0 = np.array([x, ys[j] + half_y, z])
                a1 = np.array([x, ys[j + 1] - half_y, z])
                m = b.add(by, a0, a1, 0.0, "beam")
                at.setdefault((i, j, k), [cols[i, j]]).append(m)
                at.setdefault((i, j + 1, k), [cols[i, j + 1]]).append(m)
    # bracing in the outer planes y = ys[0] (along x) and x = xs[0] (along y)
    for k in range(ns):
        i = int(rng.integers(nx))
        q0, q1 = np.array([xs[i], ys[0], zs[k]]), np.array([xs[i + 1], ys[0], zs[k + 1]])
        a0, a1 = _setback(q0, q1, 0.35, 0.35 + bx.h / 2)
        m = b.add(brace, a0, a1, 0.0, "brace")
        at.setdefault((i, 0, k), [cols[i, 0]]).append(m)
        at.setdefault((i + 1, 0, k + 1), [cols[i + 1, 0]]).append(m)
        j = int(rng.integers(ny))
        q0, q1 = np.array([xs[0], ys[j + 1], zs[k]]), np.array([xs[0], ys[j], zs[k + 1]])
        a0, a1 = _setback(q0, q1, 0.35, 0.35 + by.h / 2)
        m = b.add(brace, a0, a1, 0.0, "brace")
        at.setdefault((0, j + 1, k), [cols[0, j + 1]]).append(m)
        at.setdefault((0, j, k + 1), [cols[0, j]]).append(m)
    for (i, j, k), ids in at.items():
        if len(set(ids)) > 1:
            b.joint(np.array([xs[i], ys[j], zs[k]]), ids)
    if slabs:
        thick = float(rng.uniform(0.15, 0.25))
        over = float(rng.uniform(0.1, 0.4))
        lo = np.array([xs[0] - half_x - over, ys[0] - half_y - over])
        hi = np.array([xs[-1] + half_x + over, ys[-1] + half_y + over])
        for k in range(1, ns + 1):
            b.solids.append((np.array([*lo, zs[k]]), np.array([*hi, zs[k] + thick]), "deck/slab"))
    return b


_GIRDERS = ("IPE 400", "IPE 500", "HEB 400")
_DIAPHRAGMS = ("UPN 200", "UPN 300", "IPE 300")


def _deck(rng: np.random.Generator) -> _Build:
    """A composite deck: 3–5 I-girders 2–3 m apart, continuous over 1–2
    spans of 10–18 m, on bearings (0.3 m boxes) on concrete piers (1 m
    thick walls) with a 3.5–5.5 m clearance; diaphragm cross frames
    between the girders' webs at every pier and 3–6 m apart in the spans;
    a concrete deck 0.2–0.3 m thick on the top flanges (which it hides),
    overhanging the outer girders by 0.8–1.2 m."""
    n_g = int(rng.integers(3, 6))
    ys = np.concatenate([[0.0], np.cumsum(rng.uniform(2.0, 3.0, n_g - 1))])
    n_span = int(rng.integers(1, 3))
    piers = np.concatenate([[0.0], np.cumsum(rng.uniform(10.0, 18.0, n_span))])
    girder = _pick(rng, _GIRDERS)
    dia = _pick(rng, _DIAPHRAGMS)
    z_b = float(rng.uniform(3.5, 5.5))
    thick = float(rng.uniform(0.2, 0.3))
    over = float(rng.uniform(0.8, 1.2))
    end = 0.4
    x0, x1 = piers[0] - end, piers[-1] + end
    b = _Build()
    zg = z_b + girder.h / 2
    mains = [b.add(girder, np.array([x0, y, zg]), np.array([x1, y, zg]), 0.0, "main") for y in ys]
    stations: list[float] = []
    for a, c in itertools.pairwise(piers):
        n_in = max(1, round((c - a) / float(rng.uniform(3.0, 6.0))))
        stations += list(a + (c - a) * np.arange(n_in) / n_in)
    stations.append(float(piers[-1]))
    zc = z_b + girder.h / 2
    for x in stations:
        ids: dict[int, list[int]] = {g: [mains[g]] for g in range(n_g)}
        for g in range(n_g - 1):
            a0 = np.array([x, ys[g] + girder.tw / 2, zc])
            a1 = np.array([x, ys[g + 1] - girder.tw / 2, zc])
            m = b.add(dia, a0, a1, float(g % 2) * np.pi, "cross")
            ids[g].append(m)
            ids[g + 1].append(m)
        for g, jm in ids.items():
            b.joint(np.array([x, ys[g], zc]), jm)
    top = z_b + girder.h
    b.solids.append(
        (np.array([x0, ys[0] - over, top]), np.array([x1, ys[-1] + over, top + thick]), "deck/slab")
    )
    bearing = 0.3
    for xp in piers:
        b.solids.append(
            (
                np.array([xp - 0.5, ys[0] - 0.8, 0.0]),
                np.array([xp + 0.5, ys[-1] + 0.8, z_b - bearing]),
                "wall",
            )
        )
        for y in ys:
            b.solids.append(
                (
                    np.array([xp - 0.2, y - 0.2, z_b - bearing]),
                    np.array([xp + 0.2, y + 0.2, z_b]),
                    "bearing",
                )
            )
    return b


def _grillage(rng: np.random.Generator) -> _Build:
    n_main = int(rng.integers(2, 5))
    length = float(rng.uniform(8.0, 20.0))
    ys = np.concatenate([[0.0], np.cumsum(rng.uniform(2.0, 3.0, n_main - 1))])
    main = _pick(rng, ("IPE 400", "IPE 500", "HEB 400"))
    cross = _pick(rng, ("IPE 200", "IPE 300", "UPN 200", "UPN 300"))
    top = float(rng.uniform(1.0, 3.0)) + main.h
    n_cross = round(length / float(rng.uniform(2.0, 4.0))) + 1
    xs = np.linspace(0.25, length - 0.25, n_cross)
    b = _Build()
    mains = [b.add(main, np.array([0, y, top - main.h / 2]), np.array([length, y, top - main.h / 2]),
                   0.0, "main") for y in ys]  # fmt: skip
    zc = top - cross.h / 2
    for x in xs:
        ids: dict[int, list[int]] = {g: [mains[g]] for g in range(n_main)}
        for g in range(n_main - 1):
            a0 = np.array([x, ys[g] + main.b / 2, zc])
            a1 = np.array([x, ys[g + 1] - main.b / 2, zc])
            # channels alternate their toes so a row is not all one-sided
            m = b.add(cross, a0, a1, float(g % 2) * np.pi, "cross")
            ids[g].append(m)
            ids[g + 1].append(m)
        for g, jm in ids.items():
            b.joint(np.array([x, ys[g], zc]), jm)
    return b


def _build(kind: str, rng: np.random.Generator) -> _Build:
    if kind in ("warren", "pratt"):
        return _truss(kind, rng)
    if kind == "frame":
        return _frame(rng)
    if kind == "frame_slabs":
        return _frame(rng, slabs=True)
    if kind == "deck":
        return _deck(rng)
    return _grillage(rng)


# --------------------------------------------------------------------------- scene


@dataclass(frozen=True)
class _Prism:
    section: Section
    p0: np.ndarray
    p1: np.ndarray
    roll: float
    label: int


@dataclass(frozen=True)
class _Scene:
    """Everything a scanner can hit, in the local frame."""

    prisms: list[_Prism]
    ground: tuple[float, float, float, float] | None  # x0, x1, y0, y1 at z = 0
    blobs: list[tuple[np.ndarray, np.ndarray]]  # centre, semi-axes
    centre: np.ndarray
    #: faces of the concrete solids (deck, slabs, piers, bearings)
    rects: list[_Rect] = field(default_factory=list)


@dataclass(frozen=True)
class _Rect:
    """A planar rectangle ``o + s a + t b`` (s, t in [0, 1]) with outward unit ``normal``."""

    o: np.ndarray
    a: np.ndarray
    b: np.ndarray
    normal: np.ndarray


def _box_rects(lo: np.ndarray, hi: np.ndarray) -> list[_Rect]:
    """The six faces of the axis-aligned box ``lo``–``hi``."""
    out = []
    size = hi - lo
    for ax in range(3):
        u, v = [k for k in range(3) if k != ax]
        a = np.zeros(3)
        a[u] = size[u]
        b = np.zeros(3)
        b[v] = size[v]
        for side, base in ((-1.0, lo), (1.0, hi)):
            o = lo.copy()
            o[ax] = base[ax]
            nrm = np.zeros(3)
            nrm[ax] = side
            out.append(_Rect(o, a, b, nrm))
    return out


def _centre_build(build: _Build) -> None:
    """Move the structure so its footprint is centred on x = y = 0."""
    pts = np.concatenate(build.axes)
    c = np.array(
        [(pts[:, 0].min() + pts[:, 0].max()) / 2, (pts[:, 1].min() + pts[:, 1].max()) / 2, 0]
    )
    build.axes = [a - c for a in build.axes]
    build.joints = [(p - c, ids) for p, ids in build.joints]
    build.solids = [(lo - c, hi - c, what) for lo, hi, what in build.solids]


def _footprint(build: _Build) -> np.ndarray:
    """(2, 2) [[xmin, ymin], [xmax, ymax]] of the members' envelopes."""
    lo = np.min(
        [
            a[:, :2].min(0) - outline_radius(s)
            for a, s in zip(build.axes, build.sections, strict=True)
        ],
        0,
    )
    hi = np.max(
        [
            a[:, :2].max(0) + outline_radius(s)
            for a, s in zip(build.axes, build.sections, strict=True)
        ],
        0,
    )
    for s_lo, s_hi, _ in build.solids:
        lo = np.minimum(lo, s_lo[:2])
        hi = np.maximum(hi, s_hi[:2])
    return np.stack([lo, hi])


def _scene(build: _Build, clutter: bool, rng: np.random.Generator) -> tuple[_Scene, np.ndarray]:
    fp = _footprint(build)
    prisms = [_Prism(s, a[0], a[1], r, i)
              for i, (s, a, r) in enumerate(zip(build.sections, build.axes, build.rolls, strict=True))]  # fmt: skip
    zmax = max(float(a[:, 2].max()) for a in build.axes)
    centre = np.array([0.0, 0.0, zmax / 2])
    ground = None
    blobs: list[tuple[np.ndarray, np.ndarray]] = []
    if clutter:
        g = fp + np.array([[-1.5, -1.5], [1.5, 1.5]])
        ground = (float(g[0, 0]), float(g[1, 0]), float(g[0, 1]), float(g[1, 1]))
        for _ in range(int(rng.integers(1, 4))):
            r = rng.uniform(0.3, 0.8) * np.array(
                [1.0, rng.uniform(0.6, 1.0), rng.uniform(0.5, 0.9)]
            )
            c = _on_rim(g, 0.6, rng)
            blobs.append((np.array([c[0], c[1], r[2]]), r))
        c = _on_rim(g, 0.5, rng)
        prisms.append(_Prism(_PERSON, np.array([c[0], c[1], 0.0]), np.array([c[0], c[1], 1.75]),
                             float(rng.uniform(0, np.pi)), -1))  # fmt: skip
        if build.solids:
            blobs += _shrubs(build, g, rng)
    rects = [r for lo, hi, _ in build.solids for r in _box_rects(lo, hi)]
    return _Scene(prisms, ground, blobs, centre, rects), fp


def _shrubs(
    build: _Build, g: np.ndarray, rng: np.random.Generator
) -> list[tuple[np.ndarray, np.ndarray]]:
    """2–5 more blobs of vegetation anywhere on the ground (the scenes with
    concrete), kept 0.3 m clear of every member that reaches the ground."""
    feet = np.array([a[0, :2] for a in build.axes if min(a[0, 2], a[1, 2]) < 0.5]).reshape(-1, 2)
    out = []
    for _ in range(int(rng.integers(2, 6))):
        r = rng.uniform(0.3, 0.9) * np.array([1.0, rng.uniform(0.6, 1.0), rng.uniform(0.4, 0.9)])
        for _ in range(20):
            c = rng.uniform(g[0] + 0.5, g[1] - 0.5)
            if not len(feet) or float(np.min(np.linalg.norm(feet - c, axis=1))) > r[0] + 0.5:
                out.append((np.array([c[0], c[1], r[2]]), r))
                break
    return out


def _deck_scanners(
    fp: np.ndarray,
    build: _Build,
    n: int,
    rng: np.random.Generator,
    blobs: list[tuple[np.ndarray, np.ndarray]],
) -> np.ndarray:
    """One scanner under the deck (between the girders, clear of the piers
    and of the vegetation) and the others on both sides, 5–12 m clear of
    the deck, 1.5–2 m high."""
    piers = [0.5 * (lo[0] + hi[0]) for lo, hi, what in build.solids if what == "wall"]
    y_g = [
        float(a[0, 1]) for a, role in zip(build.axes, build.roles, strict=True) if role == "main"
    ]
    out = []
    for _ in range(50):
        x = float(rng.uniform(fp[0, 0] + 1.5, fp[1, 0] - 1.5))
        y = float(rng.uniform(min(y_g), max(y_g)))
        clear = all(np.hypot(x - c[0], y - c[1]) > float(r.max()) + 1.0 for c, r in blobs)
        if clear and all(abs(x - p) > 2.0 for p in piers):
            break
    out.append([x, y, float(rng.uniform(1.5, 2.0))])
    for k in range(1, n):
        side = 1.0 if k % 2 else -1.0
        y = (fp[1, 1] if side > 0 else fp[0, 1]) + side * float(rng.uniform(5.0, 12.0))
        x = float(rng.uniform(fp[0, 0], fp[1, 0]))
        out.append([x, y, float(rng.uniform(1.5, 2.0))])
    return np.asarray(out)


def _on_rim(g: np.ndarray, inset: float, rng: np.random.Generator) -> np.ndarray:
    """A random xy point ``inset`` inside the edge of rectangle ``g`` (2, 2)."""
    lo, hi = g[0] + inset, g[1] - inset
    p = rng.uniform(lo, hi)
    axis = int(rng.integers(2))
    p[axis] = lo[axis] if rng.random() < 0.5 else hi[axis]
    return p


def _scanners(fp: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` scanner positions round the footprint, 5–12 m clear of it, 1.5–2 m high."""
    half = (fp[1] - fp[0]) / 2
    a0 = rng.uniform(0, 2 * np.pi)
    out = []
    for k in range(n):
        a = a0 + 2 * np.pi * k / n + rng.uniform(-0.3, 0.3)
        u = np.array([np.cos(a), np.sin(a)])
        clear = rng.uniform(5.0, 12.0)
        lo, hi = 0.0, float(np.linalg.norm(half)) + clear
        # the clearance grows monotonically along the ray: bisect for the distance
        for _ in range(60):
            mid = (lo + hi) / 2
            gap = np.linalg.norm(np.maximum(np.abs(mid * u) - half, 0.0))
            lo, hi = (mid, hi) if gap < clear else (lo, mid)
        out.append([hi * u[0], hi * u[1], rng.uniform(1.5, 2.0)])
    return np.asarray(out)


class _Grid:
    """The scanner's angular bins: step ``dtheta`` in azimuth and elevation."""

    def __init__(self, origin: np.ndarray, dtheta: float) -> None:
        self.origin = origin
        self.dtheta = dtheta
        self.n_az = int(np.ceil(2 * np.pi / dtheta))

    def bins(self, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bin id (int64) and range of each point."""
        v = pts - self.origin
        r = np.linalg.norm(v, axis=1)
        az = np.arctan2(v[:, 1], v[:, 0])
        el = np.arcsin(np.clip(v[:, 2] / np.maximum(r, 1e-12), -1.0, 1.0))
        i_el = np.floor((el + np.pi / 2) / self.dtheta).astype(np.int64)
        i_az = np.floor((az + np.pi) / self.dtheta).astype(np.int64) % self.n_az
        return i_el * self.n_az + i_az, r


class _Candidates(NamedTuple):
    pts: np.ndarray
    nrm: np.ndarray
    lab: np.ndarray


def nearest_per_bin(bins: np.ndarray, ranges: np.ndarray) -> np.ndarray:
    """Indices of the nearest entry per bin (first return), sorted by bin id.

    Ties go to the lowest index.  One stable integer sort and linear group
    reductions: a (bin, range) lexsort took 3× as long on 2.5 M entries.
    """
    if len(bins) == 0:
        return np.zeros(0, dtype=np.int64)
    order = np.argsort(bins, kind="stable")
    b = bins[order]
    r = ranges[order]
    start = np.flatnonzero(np.concatenate([[True], b[1:] != b[:-1]]))
    size = np.diff(np.append(start, len(b)))
    is_min = r == np.repeat(np.minimum.reduceat(r, start), size)
    pos = np.flatnonzero(is_min)
    grp = np.repeat(np.arange(len(start)), size)[pos]
    first = np.concatenate([[True], grp[1:] != grp[:-1]])
    return order[pos[first]]


def _prism_candidates(pr: _Prism, grid: _Grid, rng: np.random.Generator) -> Iterator[_Candidates]:
    """Front-facing surface samples of a prism, finer where it is nearer the scanner."""
    rad = outline_radius(pr.section)
    length = float(np.linalg.norm(pr.p1 - pr.p0))
    n_seg = max(1, int(np.ceil(length / 2.0)))
    ends = pr.p0 + np.linspace(0, 1, n_seg + 1)[:, None] * (pr.p1 - pr.p0)
    frame = member_frame(pr.p0, pr.p1, pr.roll)
    for a, c in itertools.pairwise(ends):
        r_min = max(_segment_distance(grid.origin, a, c) - rad, 0.5)
        # the azimuth footprint shrinks with cos(elevation): use the steepest end
        cos_el = min(_cos_elevation(grid.origin, q, rad) for q in (a, c))
        step = _CANDIDATE_FACTOR * r_min * grid.dtheta * cos_el
        roll = _roll_in(frame, a, c)
        for pts, nrm in iter_member_surface(pr.section, a, c, roll, step, rng):
            front = np.einsum("ij,ij->i", nrm, grid.origin - pts) > 0
            yield _Candidates(pts[front], nrm[front], np.full(int(front.sum()), pr.label))


def _roll_in(frame: np.ndarray, a: np.ndarray, c: np.ndarray) -> float:
    """The roll that gives the piece a→c the same section axes as ``frame``."""
    f0 = member_frame(a, c, 0.0)
    return float(np.arctan2(-frame[1] @ f0[0], frame[1] @ f0[1]))


def _segment_distance(q: np.ndarray, a: np.ndarray, c: np.ndarray) -> float:
    d = c - a
    t = float(np.clip((q - a) @ d / (d @ d), 0.0, 1.0))
    return float(np.linalg.norm(q - (a + t * d)))


def _cos_elevation(origin: np.ndarray, q: np.ndarray, rad: float) -> float:
    v = q - origin
    horiz = float(np.hypot(v[0], v[1]))
    return max(horiz / (float(np.linalg.norm(v)) + rad), 0.2)


def _ground_candidates(
    ground: tuple[float, float, float, float], grid: _Grid, rng: np.random.Generator
) -> Iterator[_Candidates]:
    """One ray per bin that can reach the ground rectangle, jittered within the bin."""
    x0, x1, y0, y1 = ground
    s = grid.origin
    corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]) - s[:2]
    az_c = np.arctan2(corners[:, 1], corners[:, 0])
    ref = az_c[0]
    rel = (az_c - ref + np.pi) % (2 * np.pi) - np.pi
    az_lo, az_hi = ref + rel.min(), ref + rel.max()
    near = np.hypot(max(x0 - s[0], 0, s[0] - x1), max(y0 - s[1], 0, s[1] - y1))
    far = float(np.linalg.norm(corners, axis=1).max())
    el_lo, el_hi = -np.arctan2(s[2], max(near, 0.5)), -np.arctan2(s[2], far)
    dt = grid.dtheta
    ia = np.arange(int(np.floor((az_lo + np.pi) / dt)), int(np.floor((az_hi + np.pi) / dt)) + 1)
    ie = np.arange(
        int(np.floor((el_lo + np.pi / 2) / dt)), int(np.floor((el_hi + np.pi / 2) / dt)) + 1
    )
    rows = max(1, _MERGE_AT // max(len(ia), 1))
    for k in range(0, len(ie), rows):
        e_idx = np.repeat(ie[k : k + rows], len(ia))
        a_idx = np.tile(ia, len(ie[k : k + rows]))
        el = (e_idx + rng.random(len(e_idx))) * dt - np.pi / 2
        az = (a_idx + rng.random(len(a_idx))) * dt - np.pi
        d = s[2] / np.tan(-el)
        x, y = s[0] + d * np.cos(az), s[1] + d * np.sin(az)
        inside = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
        pts = np.stack([x[inside], y[inside], np.zeros(int(inside.sum()))], axis=1)
        nrm = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
        yield _Candidates(pts, nrm, np.full(len(pts), -1))


def _rect_candidates(rect: _Rect, grid: _Grid, rng: np.random.Generator) -> Iterator[_Candidates]:
    """One ray per bin that can reach a rectangle facing the scanner, jittered within the bin."""
    s = grid.origin
    if float(rect.normal @ (s - rect.o)) <= 0:  # its back: the solid hides it
        return
    t = np.linspace(0.0, 1.0, 129)[:, None]
    edge = np.concatenate(
        [rect.o + t * rect.a, rect.o + rect.a + t * rect.b, rect.o + t * rect.b,
         rect.o + rect.b + t * rect.a]
    ) - s  # fmt: skip
    el_b = np.arcsin(np.clip(edge[:, 2] / np.linalg.norm(edge, axis=1), -1.0, 1.0))
    az_b = np.arctan2(edge[:, 1], edge[:, 0])
    el_lo, el_hi = float(el_b.min()), float(el_b.max())
    aa, bb = float(rect.a @ rect.a), float(rect.b @ rect.b)
    nz = float(rect.normal[2])
    overhead = False
    if abs(nz) > 1e-9:
        # the vertical through the scanner meets the rectangle: every azimuth
        lam = float(rect.normal @ (rect.o - s)) / nz
        q = s + np.array([0.0, 0.0, lam]) - rect.o
        overhead = 0 <= q @ rect.a <= aa and 0 <= q @ rect.b <= bb
        if overhead:
            el_lo, el_hi = (el_lo, np.pi / 2) if lam > 0 else (-np.pi / 2, el_hi)
    dt = grid.dtheta
    if overhead:
        ia = np.arange(grid.n_az)
    else:
        rel = (az_b - az_b[0] + np.pi) % (2 * np.pi) - np.pi
        lo_a, hi_a = az_b[0] + rel.min(), az_b[0] + rel.max()
        ia = np.arange(int(np.floor((lo_a + np.pi) / dt)), int(np.floor((hi_a + np.pi) / dt)) + 1)
    ie = np.arange(
        int(np.floor((el_lo + np.pi / 2) / dt)), int(np.floor((el_hi + np.pi / 2) / dt)) + 1
    )
    rows = max(1, _MERGE_AT // max(len(ia), 1))
    for k in range(0, len(ie), rows):
        e_idx = np.repeat(ie[k : k + rows], len(ia))
        a_idx = np.tile(ia, len(ie[k : k + rows]))
        el = np.clip((e_idx + rng.random(len(e_idx))) * dt - np.pi / 2, -np.pi / 2, np.pi / 2)
        az = (a_idx + rng.random(len(a_idx))) * dt - np.pi
        u = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        den = u @ rect.normal
        with np.errstate(divide="ignore", invalid="ignore"):
            r = float(rect.normal @ (rect.o - s)) / den
        ok = np.isfinite(r) & (r > 0)
        p = s + r[ok, None] * u[ok]
        q = p - rect.o
        qa, qb = q @ rect.a, q @ rect.b
        inside = (qa >= 0) & (qa <= aa) & (qb >= 0) & (qb <= bb)
        pts = p[inside]
        yield _Candidates(pts, np.tile(rect.normal, (len(pts), 1)), np.full(len(pts), -1))


def _blob_candidates(
    blob: tuple[np.ndarray, np.ndarray], grid: _Grid, rng: np.random.Generator
) -> Iterator[_Candidates]:
    """Points filling an ellipsoid, enough for several per bin of its silhouette."""
    c, semi = blob
    r = max(float(np.linalg.norm(c - grid.origin)) - float(semi.max()), 0.5)
    foot = r * grid.dtheta
    n = int(min(4 * np.pi * semi[0] * semi[1] / foot**2, 4_000_000))
    for k in range(0, n, _MERGE_AT):
        m = min(_MERGE_AT, n - k)
        u = rng.normal(size=(m, 3))
        u *= (rng.random(m) ** (1 / 3) / np.linalg.norm(u, axis=1))[:, None]
        pts = c + u * semi
        to_s = grid.origin - pts
        nrm = to_s / np.linalg.norm(to_s, axis=1, keepdims=True)
        yield _Candidates(pts, nrm, np.full(m, -1))


def _scene_candidates(
    scene: _Scene, grid: _Grid, rng: np.random.Generator
) -> Iterator[_Candidates]:
    for pr in scene.prisms:
        yield from _prism_candidates(pr, grid, rng)
    if scene.ground is not None:
        yield from _ground_candidates(scene.ground, grid, rng)
    for rect in scene.rects:
        yield from _rect_candidates(rect, grid, rng)
    for blob in scene.blobs:
        yield from _blob_candidates(blob, grid, rng)


def first_returns(
    grid_origin: np.ndarray,
    dtheta: float,
    chunks: Iterator[_Candidates],
    *,
    merge_at: int = _MERGE_AT,
) -> _Candidates:
    """The nearest candidate per angular bin over all chunks, merged a buffer at a time.

    Memory holds the current winners (one per occupied bin) plus one buffer of
    about ``merge_at`` candidates, never all candidates at once.
    """
    grid = _Grid(grid_origin, dtheta)
    best = _Candidates(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, dtype=np.int64))
    buf: list[_Candidates] = []
    size = 0

    def merge() -> _Candidates:
        parts = [best, *buf]
        allc = _Candidates(
            *(np.concatenate([getattr(p, f) for p in parts]) for f in _Candidates._fields)
        )
        b, r = grid.bins(allc.pts)
        keep = nearest_per_bin(b, r)
        return _Candidates(allc.pts[keep], allc.nrm[keep], allc.lab[keep])

    for ch in chunks:
        buf.append(ch)
        size += len(ch.pts)
        if size >= merge_at:
            best, buf, size = merge(), [], 0
    return merge() if buf else best


def _add_noise(pts: np.ndarray, origin: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    v = pts - origin
    r = np.linalg.norm(v, axis=1, keepdims=True)
    sigma = NOISE_M + NOISE_PER_M * r
    return origin + v * (1 + sigma * rng.normal(size=r.shape) / r)


# --------------------------------------------------------------------------- API


def _check_args(
    kind: str, spacing_m: float, units: str, n_scanners: int | None, max_points: int | None
) -> None:
    if kind not in SCAN_KINDS:
        raise InvalidInputError(
            f"unknown scan kind {kind!r}; expected one of {', '.join(SCAN_KINDS)}"
        )
    if not (isinstance(spacing_m, int | float) and np.isfinite(spacing_m) and spacing_m > 0):
        raise InvalidInputError(
            f"spacing_m must be a finite number > 0 (metres), got {spacing_m!r}"
        )
    if spacing_m < 0.001 or spacing_m > 1.0:
        raise InvalidInputError(f"spacing_m must lie in [0.001, 1] metres, got {spacing_m!r}")
    if units not in UNITS:
        raise InvalidInputError(f"units must be 'm' or 'mm', got {units!r}")
    if n_scanners is not None and not (isinstance(n_scanners, int) and 1 <= n_scanners <= 8):
        raise InvalidInputError(f"n_scanners must be an integer 1–8 or None, got {n_scanners!r}")
    if max_points is not None and not (isinstance(max_points, int) and max_points > 0):
        raise InvalidInputError(
            f"max_points must be a positive integer or None, got {max_points!r}"
        )


def _outliers(
    pts: np.ndarray, idx: np.ndarray, scanners: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mixed-pixel style outliers: copies of scan points moved 0.3–2 m along their beam.

    Returns the points, their "normals" (towards the scanner) and the indices
    of the scan points they were copied from.
    """
    n = round(OUTLIER_FRACTION * len(pts))
    pick = rng.integers(len(pts), size=n)
    s = scanners[idx[pick]]
    v = pts[pick] - s
    u = v / np.linalg.norm(v, axis=1, keepdims=True)
    shift = rng.uniform(0.3, 2.0, n) * rng.choice([-1.0, 1.0], n)
    return pts[pick] + u * shift[:, None], -u, pick


def make_scan(
    kind: str,
    seed: int,
    *,
    spacing_m: float = 0.02,
    units: str = "m",
    n_scanners: int | None = None,
    clutter: bool = True,
    max_points: int | None = None,
) -> ScanStructure:
    """A synthetic TLS scan of a ``kind`` structure with ground truth (module docstring).

    ``spacing_m`` is the target point spacing on the members (median nearest
    neighbour of the merged member points, metres); ``units`` ``"m"`` or
    ``"mm"`` (points × 1000); ``n_scanners`` defaults to 2–4 from the seed;
    ``clutter`` adds ground, vegetation, a person and outliers; ``max_points``
    keeps a uniform random subset of that many points (density falls).
    """
    _check_args(kind, spacing_m, units, n_scanners, max_points)
    t0 = time.perf_counter()
    rng = np.random.default_rng([int(seed), SCAN_KINDS.index(kind)])
    build = _build(kind, rng)
    _centre_build(build)
    scene, fp = _scene(build, clutter, rng)
    n_sc = int(rng.integers(2, 5)) if n_scanners is None else n_scanners
    if kind == "deck":
        # under the deck and both sides: one more than the others get
        n_sc = n_sc + 1 if n_scanners is None else n_sc
        scanners = _deck_scanners(fp, build, n_sc, rng, scene.blobs)
    else:
        scanners = _scanners(fp, n_sc, rng)
    t1 = time.perf_counter()
    parts: list[_Candidates] = []
    which: list[np.ndarray] = []
    for k, s in enumerate(scanners):
        dtheta = (
            BIN_CALIBRATION * np.sqrt(n_sc) * spacing_m / float(np.linalg.norm(scene.centre - s))
        )
        grid = _Grid(s, dtheta)
        hits = first_returns(s, dtheta, _scene_candidates(scene, grid, rng))
        parts.append(hits._replace(pts=_add_noise(hits.pts, s, rng)))
        which.append(np.full(len(hits.pts), k))
    pts = np.concatenate([p.pts for p in parts])
    nrm = np.concatenate([p.nrm for p in parts])
    lab = np.concatenate([p.lab for p in parts]).astype(np.int64)
    idx = np.concatenate(which).astype(np.int64)
    if clutter and len(pts):
        o_pts, o_nrm, pick = _outliers(pts, idx, scanners, rng)
        pts = np.concatenate([pts, o_pts])
        nrm = np.concatenate([nrm, o_nrm])
        lab = np.concatenate([lab, np.full(len(o_pts), -1)])
        idx = np.concatenate([idx, idx[pick]])
    if max_points is not None and len(pts) > max_points:
        keep = np.sort(rng.choice(len(pts), size=max_points, replace=False))
        pts, nrm, lab, idx = pts[keep], nrm[keep], lab[keep], idx[keep]
    t2 = time.perf_counter()
    return _to_survey(kind, int(seed), build, pts, nrm, lab, idx, scanners, spacing_m, units, rng,
                      {"layout": t1 - t0, "scan": t2 - t1}, scene.ground)  # fmt: skip


def _to_survey(
    kind: str,
    seed: int,
    build: _Build,
    pts: np.ndarray,
    nrm: np.ndarray,
    lab: np.ndarray,
    idx: np.ndarray,
    scanners: np.ndarray,
    spacing_m: float,
    units: str,
    rng: np.random.Generator,
    timings: dict[str, float],
    ground: tuple[float, float, float, float] | None = None,
) -> ScanStructure:
    """Turn the local scene by a random yaw and move it to UTM-like coordinates."""
    yaw = float(rng.uniform(0, 2 * np.pi))
    offset = np.array([rng.uniform(4e5, 6e5), rng.uniform(5.3e6, 5.5e6), rng.uniform(50.0, 500.0)])
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    def fwd(p: np.ndarray) -> np.ndarray:
        return p @ rot.T + offset

    members = []
    for i, (sec, ax, roll, role) in enumerate(
        zip(build.sections, build.axes, build.rolls, build.roles, strict=True)
    ):
        frame = member_frame(ax[0], ax[1], roll) @ rot.T
        axis = fwd(ax)
        members.append(TrueMember(i, axis, sec, _roll_in(frame, axis[0], axis[1]), role))
    joints = [TrueJoint(fwd(p[None])[0], tuple(ids)) for p, ids in build.joints]
    surfaces = []
    for lo, hi, what in build.solids:
        if what == "deck/slab":
            z = lo[2]
            rect = np.array(
                [[lo[0], lo[1], z], [hi[0], lo[1], z], [hi[0], hi[1], z], [lo[0], hi[1], z]]
            )
            surfaces.append((what, fwd(rect)))
        elif what == "wall":
            for x in (lo[0], hi[0]):
                rect = np.array(
                    [[x, lo[1], lo[2]], [x, hi[1], lo[2]], [x, hi[1], hi[2]], [x, lo[1], hi[2]]]
                )
                surfaces.append((what, fwd(rect)))
    if ground is not None and build.solids:
        x0, x1, y0, y1 = ground
        surfaces.append(
            ("ground", fwd(np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])))
        )
    scale = UNITS[units]
    survey = fwd(pts)
    return ScanStructure(
        kind=kind,
        seed=seed,
        points=survey * scale if scale != 1.0 else survey,
        labels=lab,
        normals=nrm @ rot.T,
        scanner_index=idx,
        members=members,
        joints=joints,
        scanners=fwd(scanners),
        spacing_m=float(spacing_m),
        units=units,
        scale=scale,
        frame_offset=offset,
        yaw=yaw,
        ground_z=float(offset[2]),
        timings_s=timings,
        surfaces=surfaces,
    )


# --------------------------------------------------------------------------- matching


class MemberMatch(NamedTuple):
    """Result of :func:`match_members`."""

    recall: float
    precision: float
    pairs: list[tuple[int, int]]  # (true index, found index) that match


def _seg_points(axes: np.ndarray, n: int) -> np.ndarray:
    """(K, n, 3) midpoints of ``n`` equal pieces of each segment."""
    t = (np.arange(n) + 0.5) / n
    return axes[:, None, 0] + t[None, :, None] * (axes[:, None, 1] - axes[:, None, 0])


def _dist_to_segments(q: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """(K, n) points ``q`` (K, n, 3) → (K, n, F) distances to every segment of ``axes`` (F, 2, 3)."""
    a, d = axes[:, 0], axes[:, 1] - axes[:, 0]
    dd = np.maximum(np.einsum("fj,fj->f", d, d), 1e-30)
    w = q[:, :, None, :] - a[None, None]
    t = np.clip(np.einsum("knfj,fj->knf", w, d) / dd, 0.0, 1.0)
    return np.linalg.norm(w - t[..., None] * d[None, None], axis=-1)


def _coverage(src: np.ndarray, tol: np.ndarray, dst: np.ndarray, n: int) -> np.ndarray:
    """(S, D) fraction of each ``src`` segment's length within ``tol`` (S,) of each ``dst`` segment."""
    out = np.zeros((len(src), len(dst)))
    rows = max(1, 200_000 // max(n * len(dst), 1))
    for k in range(0, len(src), rows):
        q = _seg_points(src[k : k + rows], n)
        dist = _dist_to_segments(q, dst)
        out[k : k + rows] = (dist <= tol[k : k + rows, None, None]).mean(axis=1)
    return out


def _angles_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(A, B) angle between the undirected lines of two segment sets, degrees."""
    da = a[:, 1] - a[:, 0]
    db = b[:, 1] - b[:, 0]
    da = da / np.maximum(np.linalg.norm(da, axis=1, keepdims=True), 1e-30)
    db = db / np.maximum(np.linalg.norm(db, axis=1, keepdims=True), 1e-30)
    return np.degrees(np.arccos(np.clip(np.abs(da @ db.T), 0.0, 1.0)))


def match_members(
    true_axes: npt.ArrayLike,
    true_depths: npt.ArrayLike,
    found_axes: npt.ArrayLike,
    *,
    min_tol_m: float = 0.05,
    depth_factor: float = 0.6,
    max_angle_deg: float = 5.0,
    min_cover: float = 0.8,
    n_samples: int = 64,
) -> MemberMatch:
    """Recall and precision of found member axes against the true ones.

    Tolerance of true member ``t``: ``tol_t = max(min_tol_m, depth_factor × depth_t)``.
    Coverage is measured at ``n_samples`` evenly spaced points along a
    segment (midpoints of equal pieces), distances to the other *segment*.

    * ``f`` matches ``t`` (a pair) when the lines are within ``max_angle_deg``
      and ≥ ``min_cover`` of ``t``'s length lies within ``tol_t`` of ``f``'s
      segment — the true member is found along most of its length.
    * recall = fraction of true members with at least one matching ``f``.
    * precision = fraction of found members that are a pair's ``f`` **or**
      lie, within ``max_angle_deg``, with ≥ ``min_cover`` of their own length
      within ``tol_t`` of some true segment: a correct fragment of a member
      (split by an occlusion) is not a false detection, but it does not
      make the member found.

    With no true members recall is 1; with no found members precision is 1.
    All inputs in the same length unit (``min_tol_m`` in that unit too).
    """
    ta = np.asarray(true_axes, float).reshape(-1, 2, 3)
    fa = np.asarray(found_axes, float).reshape(-1, 2, 3)
    depths = np.asarray(true_depths, float).reshape(-1)
    if len(depths) != len(ta):
        raise InvalidInputError(f"true_depths has {len(depths)} entries for {len(ta)} true axes")
    if not (np.isfinite(ta).all() and np.isfinite(fa).all() and np.isfinite(depths).all()):
        raise InvalidInputError("axes and depths must be finite")
    if len(ta) == 0 or len(fa) == 0:
        return MemberMatch(1.0 if len(ta) == 0 else 0.0, 1.0 if len(fa) == 0 else 0.0, [])
    tol = np.maximum(min_tol_m, depth_factor * depths)
    ang_ok = _angles_deg(ta, fa) <= max_angle_deg
    pair = ang_ok & (_coverage(ta, tol, fa, n_samples) >= min_cover)
    # a found segment is near true t when its samples are within t's tolerance
    f_q = _seg_points(fa, n_samples)
    near = np.zeros((len(fa), len(ta)), dtype=bool)
    for k in range(len(fa)):
        d = _dist_to_segments(f_q[k : k + 1], ta)[0]  # (n, T)
        near[k] = (d <= tol[None]).mean(axis=0) >= min_cover
    good_f = pair.any(axis=0) | (near & ang_ok.T).any(axis=1)
    pairs = [(int(t), int(f)) for t, f in zip(*np.nonzero(pair), strict=True)]
    return MemberMatch(float(pair.any(axis=1).mean()), float(good_f.mean()), pairs)


# --------------------------------------------------------------------------- samples


def _sample_fn(kind: str) -> Callable[[int], np.ndarray]:
    def make(seed: int) -> np.ndarray:
        return make_scan(kind, seed, spacing_m=0.02, max_points=300_000).points

    make.__doc__ = (
        f"(N, 3) survey-frame TLS scan (metres, 2 cm spacing) of a synthetic {kind} structure."
    )
    return make


#: name → seed → (N, 3) cloud, for ``POST /clouds {"sample": name}``.
SCAN_SAMPLES: dict[str, Callable[[int], np.ndarray]] = {
    f"scan_{k}": _sample_fn(k) for k in SCAN_KINDS
}
