"""Reference only (tests and benchmarks): the plain-float GJK that
``planners/cmbot/distance.py`` used before it was measured slower
than the closed form, copied verbatim.

:func:`gjk_distance` is the Gilbert–Johnson–Keerthi algorithm (Gilbert,
Johnson & Keerthi 1988; closest point of each simplex by Johnson's
sub-algorithm, here by enumerating the simplex's faces) on support
functions; a sphere is its centre point grown by its radius.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from planners.cmbot.distance import Cuboid


def support_tuple(box: Cuboid, d: tuple[float, float, float]) -> tuple[float, float, float]:
    """Farthest point of ``box`` in direction ``d`` on plain floats (GJK's inner loop)."""
    cache = box.__dict__.get("_py")
    if cache is None:
        cache = (
            tuple(box.center.tolist()),
            tuple(map(tuple, box.rotation.T.tolist())),
            tuple(box.half.tolist()),
        )
        object.__setattr__(box, "_py", cache)
    c, rows, h = cache  # rows: box axes
    x, y, z = c
    for axis, hk in zip(rows, h, strict=True):
        sk = hk if axis[0] * d[0] + axis[1] * d[1] + axis[2] * d[2] >= 0.0 else -hk
        x += sk * axis[0]
        y += sk * axis[1]
        z += sk * axis[2]
    return (x, y, z)


@dataclass(frozen=True)
class GJKResult:
    """``distance`` ≥ 0 between the shapes (0 when they intersect), closest
    points on A and B, the iterations used and whether they intersect."""

    distance: float
    point_a: np.ndarray
    point_b: np.ndarray
    iterations: int
    intersect: bool


Vec = tuple[float, float, float]


def _dot(a: Vec, b: Vec) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _sub(a: Vec, b: Vec) -> Vec:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _comb(P: list[Vec], lam: list[float]) -> Vec:
    x = y = z = 0.0
    for p, w in zip(P, lam, strict=True):
        x += w * p[0]
        y += w * p[1]
        z += w * p[2]
    return (x, y, z)


def _closest_segment(a: Vec, b: Vec) -> tuple[list[int], list[float]]:
    ab = _sub(b, a)
    t = -_dot(a, ab) / max(_dot(ab, ab), 1e-300)
    if t <= 0.0:
        return [0], [1.0]
    if t >= 1.0:
        return [1], [1.0]
    return [0, 1], [1.0 - t, t]


def _closest_triangle(a: Vec, b: Vec, c: Vec) -> tuple[list[int], list[float]]:
    """Ericson, Real-Time Collision Detection §5.1.5, for the query point at the origin."""
    ab, ac = _sub(b, a), _sub(c, a)
    ap = (-a[0], -a[1], -a[2])
    d1, d2 = _dot(ab, ap), _dot(ac, ap)
    if d1 <= 0.0 and d2 <= 0.0:
        return [0], [1.0]
    bp = (-b[0], -b[1], -b[2])
    d3, d4 = _dot(ab, bp), _dot(ac, bp)
    if d3 >= 0.0 and d4 <= d3:
        return [1], [1.0]
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return [0, 1], [1.0 - v, v]
    cp = (-c[0], -c[1], -c[2])
    d5, d6 = _dot(ab, cp), _dot(ac, cp)
    if d6 >= 0.0 and d5 <= d6:
        return [2], [1.0]
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return [0, 2], [1.0 - w, w]
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return [1, 2], [1.0 - w, w]
    den = 1.0 / (va + vb + vc)
    v, w = vb * den, vc * den
    return [0, 1, 2], [1.0 - v - w, v, w]


def _outside_plane(a: Vec, b: Vec, c: Vec, d: Vec) -> bool:
    """Whether the origin and ``d`` lie on opposite sides of plane abc."""
    ab, ac = _sub(b, a), _sub(c, a)
    n = (
        ab[1] * ac[2] - ab[2] * ac[1],
        ab[2] * ac[0] - ab[0] * ac[2],
        ab[0] * ac[1] - ab[1] * ac[0],
    )
    so = -_dot(a, n)
    sd = _dot(_sub(d, a), n)
    return so * sd < 0.0


def _closest_on_simplex(W: list[Vec]) -> tuple[list[int], list[float]]:
    """Johnson's sub-algorithm: the sub-simplex (indices, barycentric weights)
    whose point is nearest the origin; a tetrahedron enclosing the origin
    returns all four vertices."""
    n = len(W)
    if n == 1:
        return [0], [1.0]
    if n == 2:
        return _closest_segment(W[0], W[1])
    if n == 3:
        return _closest_triangle(W[0], W[1], W[2])
    best: tuple[float, list[int], list[float]] | None = None
    for f in ((0, 1, 2, 3), (0, 1, 3, 2), (0, 2, 3, 1), (1, 2, 3, 0)):
        a, b, c, d = (W[i] for i in f)
        if not _outside_plane(a, b, c, d):
            continue
        idx, lam = _closest_triangle(a, b, c)
        p = _comb([(a, b, c)[i] for i in idx], lam)
        d2 = _dot(p, p)
        if best is None or d2 < best[0]:
            best = (d2, [f[i] for i in idx], lam)
    if best is None:  # inside every face plane: the origin is in the tetrahedron
        return [0, 1, 2, 3], [0.25] * 4
    return best[1], best[2]


def gjk_distance(
    support_a: Callable[[Vec], Vec],
    support_b: Callable[[Vec], Vec],
    start: Vec | np.ndarray,
    *,
    tol: float = 1e-12,
    max_iter: int = 64,
) -> GJKResult:
    """GJK distance between convex A and B given their support functions
    (plain-float 3-tuples in and out).

    ``start`` is any vector a − b of the Minkowski difference (e.g. centre
    difference).  Stops when the support point no longer improves the bound
    (‖v‖² − v·w ≤ tol·‖v‖²) or the simplex encloses the origin.
    """
    v: Vec = (float(start[0]), float(start[1]), float(start[2]))
    if _dot(v, v) < 1e-30:
        v = (1.0, 0.0, 0.0)
    Wa: list[Vec] = []
    Wb: list[Vec] = []
    lam: list[float] = []
    it = 0
    for it in range(1, max_iter + 1):
        a = support_a((-v[0], -v[1], -v[2]))
        b = support_b(v)
        w = _sub(a, b)
        vv = _dot(v, v)
        if Wa and vv - _dot(v, w) <= tol * max(vv, 1e-30):
            break
        Wa.append(a)
        Wb.append(b)
        W = [_sub(x, y) for x, y in zip(Wa, Wb, strict=True)]
        idx, lam = _closest_on_simplex(W)
        Wa = [Wa[i] for i in idx]
        Wb = [Wb[i] for i in idx]
        v = _comb([W[i] for i in idx], lam)
        if len(idx) == 4 or _dot(v, v) <= 1e-24:
            return GJKResult(0.0, np.array(_comb(Wa, lam)), np.array(_comb(Wb, lam)), it, True)
    pa, pb = np.array(_comb(Wa, lam)), np.array(_comb(Wb, lam))
    return GJKResult(float(np.linalg.norm(pa - pb)), pa, pb, it, False)


def sphere_box_gjk(center: np.ndarray, radius: float, box: Cuboid) -> tuple[float, np.ndarray]:
    """Signed distance d_ij and unit direction u_ij (box → sphere) by GJK.

    The sphere is its centre point grown by ``radius``; a centre inside the
    box (GJK reports intersection) falls back to the nearest face.
    """
    c = np.asarray(center, dtype=float)
    ct = (float(c[0]), float(c[1]), float(c[2]))
    res = gjk_distance(lambda d: ct, lambda d: support_tuple(box, d), c - box.center)
    if res.intersect or res.distance < 1e-12:
        d, u = _inside_box(c, box)
        return d - radius, u
    u = (res.point_a - res.point_b) / res.distance
    return res.distance - radius, u


def _inside_box(c: np.ndarray, box: Cuboid) -> tuple[float, np.ndarray]:
    """Negative depth of a point inside a box and the outward normal of the nearest face."""
    local = box.rotation.T @ (c - box.center)
    gap = box.half - np.abs(local)
    k = int(np.argmin(gap))
    n = np.zeros(3)
    n[k] = 1.0 if local[k] >= 0 else -1.0
    return -float(gap[k]), box.rotation @ n
