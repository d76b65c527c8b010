"""Faces and section of a member from its points.

The faces of a prismatic member are planes containing its axis direction,
so in the cross-section (the points projected on the plane normal to the
axis) each face is a line.  Sequential RANSAC (Fischler & Bolles 1981 — the
seed's plane detection, §3.1 Eq. 3.2, one dimension down) finds up to
``max_faces`` such lines; each becomes a :class:`Face` whose boundary is the
rectangle spanned by its inliers along the axis and across the face.

The section's depth and width are the extents of the cross-section in its
own principal frame, and the profile is read off which sides of that box
carry a face and whether a face runs through the middle (a web).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from planners.structure.model import Face

#: points a RANSAC hypothesis is scored on at most
SCORE_SAMPLE = 1500
#: a RANSAC hypothesis's two points are at least this many tolerances apart
HYPOTHESIS_SEPARATION = 0.25
#: a section fewer spacings deep than this is not classified (final pass)
UNRESOLVED_SPACINGS = 3.0
#: fewest points across a section per spacing of its length to read it (final pass)
UNRESOLVED_ACROSS = 2.0
#: the box sides' and middle lines' half band in section depths at least (final pass)
SIDE_BAND_DEPTHS = 0.08
#: a side bin is occupied from this share of the best face's points per bin (final pass)
OCCUPIED_SHARE = 0.01
#: neighbours of a point whose plane measures the surface noise
NOISE_NEIGHBOURS = 8
#: the percentile of the neighbourhoods' plane RMS taken: the flat middles
#: of faces, not their edges and corners (most of a thin member's points)
NOISE_QUANTILE = 25.0
#: that percentile in units of σ on a noisy plane (measured, k = 8)
NOISE_CALIBRATION = 0.58
#: points whose neighbourhoods measure the surface noise, at most
NOISE_SAMPLE = 2000


@dataclass
class CrossSection:
    """Points of one member in its axis frame: ``t`` along the axis, ``uv``
    in the cross-section (basis ``u``, ``v``), about ``centre``."""

    centre: np.ndarray
    direction: np.ndarray
    u: np.ndarray
    v: np.ndarray
    t: np.ndarray
    uv: np.ndarray


def cross_section(points: np.ndarray, centre: np.ndarray, direction: np.ndarray) -> CrossSection:
    d = direction / np.linalg.norm(direction)
    ref = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(d, ref)
    u /= np.linalg.norm(u)
    v = np.cross(d, u)
    rel = points - centre
    return CrossSection(centre, d, u, v, rel @ d, np.column_stack([rel @ u, rel @ v]))


def surface_noise(points: np.ndarray) -> float:
    """Estimated Gaussian noise σ (m) of a member's surface points.

    For (a stride sample of) its points, the RMS distance of the
    ``NOISE_NEIGHBOURS`` nearest neighbours from their own plane (the square
    root of the least eigenvalue of their covariance, as in the seed's
    normal estimation); the ``NOISE_QUANTILE`` percentile of those keeps to
    the flat middles of faces, and ``NOISE_CALIBRATION`` turns it into σ
    (measured on noisy planes: the percentile is 0.57–0.62 σ while σ is
    under half the spacing).  On a face that is the scanner's range noise —
    the same 2–5 mm whatever the point spacing — where a spacing-based
    tolerance grows with the spacing.  It reads low where σ nears the
    spacing (no neighbourhood then spans a plane: 0.4 σ at σ = 2 spacings)
    and about 0 on a row of single points (a coarse scan of a thin member).
    ``nan`` with too few points."""
    n = len(points)
    k = NOISE_NEIGHBOURS
    if n <= k:
        return float("nan")
    centred = points - points.mean(axis=0)
    query = centred[:: -(-n // NOISE_SAMPLE)]
    _, idx = cKDTree(centred).query(query, k=k)
    nb = centred[idx]  # (≤ NOISE_SAMPLE, k, 3): bounded by the sample
    nb = nb - nb.mean(axis=1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", nb, nb) / k
    least = np.linalg.eigvalsh(cov)[:, 0]
    return float(np.sqrt(max(float(np.percentile(least, NOISE_QUANTILE)), 0.0))) / NOISE_CALIBRATION


def ransac_lines(
    uv: np.ndarray,
    tol: float,
    min_inliers: int,
    max_lines: int,
    rng: np.random.Generator,
    trials: int = 200,
) -> list[tuple[np.ndarray, float, np.ndarray]]:
    """Up to ``max_lines`` 2D lines ``(unit normal n, offset c, inlier mask)``
    with ``n·x = c``, each the line with most inliers within ``tol`` among
    ``trials`` random point pairs of what earlier lines left."""
    left = np.ones(len(uv), dtype=bool)
    out: list[tuple[np.ndarray, float, np.ndarray]] = []
    for _ in range(max_lines):
        idx = np.flatnonzero(left)
        if len(idx) < max(min_inliers, 2):
            break
        a = idx[rng.integers(0, len(idx), trials)]
        b = idx[rng.integers(0, len(idx), trials)]
        dvec = uv[b] - uv[a]
        ln = np.hypot(dvec[:, 0], dvec[:, 1])
        # pairs a fraction of tol apart still give lines to score: a face
        # seen as a blob hardly wider than tol (a tee's stem end-on, 4 cm
        # at 2 cm spacing) has few or no pairs tol apart, and was lost
        ok = ln > HYPOTHESIS_SEPARATION * tol
        if not ok.any():
            break
        n = np.column_stack([-dvec[ok, 1], dvec[ok, 0]]) / ln[ok, None]
        c = np.einsum("ij,ij->i", n, uv[a[ok]])
        best, best_count = -1, 0
        pts = uv[idx]
        # hypotheses are scored on a sample: the best line's share of the
        # points is estimated within a few percent, at a fraction of the cost
        probe = (
            pts
            if len(pts) <= SCORE_SAMPLE
            else pts[rng.choice(len(pts), SCORE_SAMPLE, replace=False)]
        )
        for s in range(0, len(n), 32):  # trials × points in bounded blocks
            cnt = (np.abs(probe @ n[s : s + 32].T - c[s : s + 32]) <= tol).sum(axis=0)
            k = int(np.argmax(cnt))
            if cnt[k] > best_count:
                best, best_count = s + k, int(cnt[k])
        nn, cc = n[best], c[best]
        if int((np.abs(pts @ nn - cc) <= tol).sum()) < min_inliers:
            break
        inl = np.zeros(len(uv), dtype=bool)
        inl[idx] = np.abs(pts @ nn - cc) <= tol
        # least-squares refit on the inliers
        q = uv[inl]
        mu = q.mean(axis=0)
        _, _, vt = np.linalg.svd(q - mu, full_matrices=False)
        nn = vt[1]
        cc = float(nn @ mu)
        inl = np.zeros(len(uv), dtype=bool)
        inl[idx] = np.abs(pts @ nn - cc) <= tol
        out.append((nn, cc, inl))
        left &= ~inl
    return out


def member_faces(
    cs: CrossSection,
    member: int,
    first_id: int,
    tol: float,
    min_inliers: int,
    rng: np.random.Generator,
    max_faces: int = 4,
) -> list[Face]:
    """Planar faces of a member (outward normals: away from the section's middle)."""
    lines = ransac_lines(cs.uv, tol, min_inliers, max_faces, rng)
    mid = 0.5 * (cs.uv.min(axis=0) + cs.uv.max(axis=0)) if len(cs.uv) else np.zeros(2)
    faces: list[Face] = []
    for nn, cc, inl in lines:
        # the extent from every point in the plane, also those an earlier face
        # took: corners belong to both faces that meet there
        on = np.abs(cs.uv @ nn - cc) <= tol
        q = cs.uv[on]
        ts = cs.t[on]
        along = np.array([-nn[1], nn[0]])
        s = q @ along
        s0, s1 = np.percentile(s, [1, 99])
        t0, t1 = np.percentile(ts, [0.5, 99.5])
        if (cc - nn @ mid) < 0:  # outward: the side away from the section's middle
            nn, cc, along = -nn, -cc, -along
            s0, s1 = -s1, -s0
        normal = nn[0] * cs.u + nn[1] * cs.v
        x_axis = cs.direction
        y_axis = np.cross(normal, x_axis)
        # in-plane y must match ``along`` up to sign
        sign = 1.0 if float(y_axis @ (along[0] * cs.u + along[1] * cs.v)) >= 0 else -1.0
        ys = (s0, s1) if sign > 0 else (-s1, -s0)
        origin = cs.centre + cc * normal
        boundary = np.array([[t0, ys[0]], [t1, ys[0]], [t1, ys[1]], [t0, ys[1]]])
        faces.append(
            Face(
                id=first_id + len(faces),
                member=member,
                kind="face",
                origin=origin,
                normal=normal,
                x_axis=x_axis.copy(),
                boundary=boundary,
                area_m2=float((t1 - t0) * (ys[1] - ys[0])),
                n_points=int(inl.sum()),
            )
        )
    return faces


def section_box(
    uv: np.ndarray, axis0: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frame (2×2, rows = the box axes) of the cross-section, its mean and the
    box's low and high corners in it (robust 1–99 % extents).  ``axis0``
    (a face's 2D normal) fixes the first axis; otherwise the principal axes."""
    mu = uv.mean(axis=0)
    if axis0 is not None and np.linalg.norm(axis0) > 1e-9:
        a = axis0 / np.linalg.norm(axis0)
        vt = np.array([a, [-a[1], a[0]]])
    else:
        vt = np.linalg.svd(uv - mu, full_matrices=False)[2]
    q = (uv - mu) @ vt.T
    lo, hi = np.percentile(q, [1, 99], axis=0)
    return vt, mu, np.vstack([lo, hi])


def persistent_section(
    uv: np.ndarray,
    t: np.ndarray,
    cell: float,
    bin_length: float,
    min_share: float,
    max_points: float = np.inf,
    min_kept: float = 0.0,
) -> np.ndarray:
    """(n,) mask of the section points in cells (``cell`` wide) that hold
    points in at least ``min_share`` of the member's occupied stretches
    (``bin_length`` long, along ``t``).  A member's own section is seen all
    along it; the stub of each diagonal inside a chord's envelope only at its
    joint, so at coarse spacing (a chord of 20 points a metre, each joint
    adding 5–10) the stubs widen the section box and pull the axis towards
    the diagonals.  All points when fewer than four stretches hold points, or
    when they hold more than ``max_points`` on average (a fine scan: the
    stubs are a few percent, which the box's 1–99 % extents leave out, and a
    face seen from one scanner only over part of the length is the
    member's), or when the persistent cells hold fewer than ``min_kept`` of
    the points (a member seen whole near a scanner and by one flange far
    from it: those are its own cells, not stubs)."""
    n = len(uv)
    if n == 0 or cell <= 0 or bin_length <= 0:
        return np.ones(n, bool)
    b = np.floor((t - t.min()) / bin_length).astype(np.int64)
    stretches = len(np.unique(b))
    if stretches < 4 or n > max_points * stretches:
        return np.ones(n, bool)
    ij = np.floor(uv / cell).astype(np.int64)
    _, cell_id = np.unique(ij, axis=0, return_inverse=True)
    cell_id = cell_id.reshape(-1)
    pairs = np.unique(cell_id * (int(b.max()) + 1) + b)
    seen = np.bincount(pairs // (int(b.max()) + 1), minlength=int(cell_id.max()) + 1)
    keep = seen[cell_id] >= min_share * stretches
    if int(keep.sum()) < max(3.0, min_kept * n):
        return np.ones(n, bool)
    return keep


def face_axis(faces: list[Face], cs: CrossSection) -> np.ndarray | None:
    """2D normal, in the cross-section, of the face with the most points."""
    if not faces:
        return None
    f = max(faces, key=lambda f: f.n_points)
    return np.array([f.normal @ cs.u, f.normal @ cs.v])


def classify_profile(
    uv: np.ndarray,
    faces: list[Face],
    cs: CrossSection,
    spacing: float,
    band: float | None = None,
) -> tuple[str, float, float, np.ndarray]:
    """``(profile, depth_m, width_m, depth axis)`` from the cross-section's
    occupancy; the depth axis (2D, in the cross-section) runs along the web.

    ``band``: the faces' tolerance when it was measured from the surface
    noise (:func:`surface_noise`).  The box sides and middle lines are then
    read in half bands of twice that or ``SIDE_BAND_DEPTHS`` section
    depths, a bin counting from ``OCCUPIED_SHARE`` of the best face's
    points per bin; the plate and tube tests take the band for the
    spacing; and a section under ``UNRESOLVED_SPACINGS`` spacings deep, or
    with fewer than ``UNRESOLVED_ACROSS`` points across it per spacing of
    length, is ``"unknown"`` — its few points across cannot tell an I from
    a channel or a plate.  ``None``: half bands of two spacings and any
    point counts (the model's first passes, which only need depth and
    width)."""
    if len(uv) < 12:
        return "unknown", 0.0, 0.0, np.array([1.0, 0.0])
    vt, mu, box = section_box(uv, face_axis(faces, cs))
    q = (uv - mu) @ vt.T
    ext = box[1] - box[0]
    depth, width = float(max(ext)), float(min(ext))
    big = vt[int(np.argmax(ext))]
    if depth <= 0:
        return "unknown", 0.0, 0.0, np.array([1.0, 0.0])
    if band is not None:
        # too few points to read a section: under three spacings deep, or
        # few points across per spacing of length (a girder seen as a row
        # of its flange's underside)
        across = len(uv) * spacing / max(float(np.ptp(cs.t)), spacing)
        if depth < UNRESOLVED_SPACINGS * spacing or across < UNRESOLVED_ACROSS:
            return "unknown", depth, width, big
    # circle fit (Kåsa): a tube's points lie on one circle
    A = np.column_stack([2 * uv, np.ones(len(uv))])
    b = (uv**2).sum(axis=1)
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    r = float(np.sqrt(max(sol[2] + sol[0] ** 2 + sol[1] ** 2, 0.0)))
    res = np.abs(np.hypot(uv[:, 0] - sol[0], uv[:, 1] - sol[1]) - r)
    biggest = max((f.n_points for f in faces), default=0)
    # an arc is also close to a line: a tube is a circle no face explains
    if (
        r > 0
        and r < depth
        and np.percentile(res, 90) < max(0.05 * r, 1.5 * spacing if band is None else 2 * band)
        and biggest < 0.4 * len(uv)
    ):
        ang = np.arctan2(uv[:, 1] - sol[1], uv[:, 0] - sol[0])
        if np.ptp(ang) > np.pi / 2:
            return "tube", 2 * r, 2 * r, big
    tol = (
        max(2.0 * spacing, 0.05 * depth)
        if band is None
        else max(2.0 * band, SIDE_BAND_DEPTHS * depth)
    )
    # flat: thinner than three spacings, or (measured band) than the noise
    # allows — an unresolved flange two spacings wide is not a plate
    if width < max(3 * spacing if band is None else 3 * band, 0.12 * depth):
        return "plate", depth, width, big

    # occupancy of the four box sides and the two middle lines; with a
    # measured band a bin counts from a share of what the best-seen face
    # holds per bin: stray points (a neighbour's at a joint, mixed pixels
    # along an edge) dot an I's open sides all along, and made it a box
    least = 1
    if band is not None and biggest:
        least = max(1, int(OCCUPIED_SHARE * biggest / 8))

    def occ(mask: np.ndarray, coord: np.ndarray, lo: float, hi: float) -> float:
        if not mask.any():
            return 0.0
        bins = np.clip(((coord[mask] - lo) / max(hi - lo, 1e-9) * 8).astype(int), 0, 7)
        return int((np.bincount(bins, minlength=8) >= least).sum()) / 8.0

    x, y = q[:, 0], q[:, 1]
    (x0, y0), (x1, y1) = box
    sides = {
        "x0": occ(np.abs(x - x0) <= tol, y, y0, y1),
        "x1": occ(np.abs(x - x1) <= tol, y, y0, y1),
        "y0": occ(np.abs(y - y0) <= tol, x, x0, x1),
        "y1": occ(np.abs(y - y1) <= tol, x, x0, x1),
    }
    xm, ym = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    mid_x = occ(np.abs(x - xm) <= tol, y, y0, y1)  # a web across y
    mid_y = occ(np.abs(y - ym) <= tol, x, x0, x1)
    full = {k: v >= 0.6 for k, v in sides.items()}
    n_full = sum(full.values())
    # flanges along x (sides y0, y1) carry a web across y at mid-x, and the other way round
    flanges_y = full["y0"] and full["y1"]
    flanges_x = full["x0"] and full["x1"]
    ey, ex = float(ext[1]), float(ext[0])
    if n_full == 4:
        return "box", depth, width, big
    if flanges_y and mid_x >= 0.6:
        return "I", ey, ex, vt[1]
    if flanges_x and mid_y >= 0.6:
        return "I", ex, ey, vt[0]
    if flanges_y and (full["x0"] or full["x1"]):
        return "channel", ey, ex, vt[1]
    if flanges_x and (full["y0"] or full["y1"]):
        return "channel", ex, ey, vt[0]
    if n_full == 2 and not flanges_x and not flanges_y:
        return "angle", depth, width, big
    if n_full == 1 and (full["y0"] or full["y1"]) and mid_x >= 0.6:
        return "tee", ey, ex, vt[1]
    if n_full == 1 and (full["x0"] or full["x1"]) and mid_y >= 0.6:
        return "tee", ex, ey, vt[0]
    return "unknown", depth, width, big
