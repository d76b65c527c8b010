"""The blast footprint of a tilted nozzle: exact cone–plane section (seed §3.2.1).

Eq. 3.1 (``Rc = ds·(dmax − dmin)/2L + dmax/2``) is linear in the stream
length ``ds``: the sand stream is a cone whose half-angle α has
``tan α = (dmax − dmin)/2L`` and whose apex lies ``ds_apex = dmax·L/(dmax −
dmin)`` behind the nozzle exit (208 mm for the medium nozzle).  A disc radius
given explicitly (the seed's 0.04 m at 0.3 m, §4.2.1) scales that cone
(same apex, wider angle): ``r(ds) = r·Rc(ds)/Rc(ds0)``.

With the axis perpendicular to the surface the footprint is the disc of
radius ``r = L·tan α`` (``L = ds + ds_apex``, apex to surface along the
axis).  Tilted by β off the normal (§3.2.1 allows 45–90° to the surface) it is
an ellipse (the conic section, derived in :func:`exact_ellipse`):

* semi-minor ``b = h·sin α / √(cos²β − sin²α)`` (across the tilt),
* semi-major ``a = h·sin α·cos α / (cos²α − sin²β)`` (along the tilt),
* centre ``h·sin β·cos β / (cos²α − sin²β)`` from the foot of the apex,

with ``h = L·cos β`` the apex height, i.e. the centre lies ``c = centre −
h·tan β`` beyond the point where the axis meets the surface (toward the
tilt).  The first-order approximation (:func:`first_order_ellipse`) is
``a = r/cos β``, ``b = r``, ``c = 0``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planners.blasting.nozzle import Nozzle
from planners.errors import InvalidInputError


@dataclass(frozen=True)
class Cone:
    """The stream cone: ``tan_alpha`` and the apex distance behind the nozzle
    exit (m).  ``radius(ds)`` is the untilted footprint radius at stream
    length ``ds`` (m)."""

    tan_alpha: float
    apex_m: float

    @classmethod
    def of(cls, nozzle: Nozzle, radius_m: float, stream_m: float) -> Cone:
        """The Eq. 3.1 cone of ``nozzle`` scaled so the footprint at
        ``stream_m`` has radius ``radius_m`` (the scale is 1 when the radius
        is the nozzle's own Eq. 3.1 value)."""
        apex = nozzle.d_max_mm * nozzle.cone_length_mm / (nozzle.d_max_mm - nozzle.d_min_mm)
        apex_m = apex / 1000.0
        return cls(float(radius_m) / (float(stream_m) + apex_m), apex_m)

    def length(self, stream_m: np.ndarray | float) -> np.ndarray:
        """Apex-to-surface distance L along the axis."""
        return np.asarray(stream_m, dtype=float) + self.apex_m

    def radius(self, stream_m: np.ndarray | float) -> np.ndarray:
        return self.tan_alpha * self.length(stream_m)

    def stream_for_radius(self, radius_m: np.ndarray | float) -> np.ndarray:
        """Inverse of :meth:`radius`."""
        return np.asarray(radius_m, dtype=float) / self.tan_alpha - self.apex_m


def exact_ellipse(
    L: np.ndarray | float, tan_alpha: float, beta: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact section of the cone (apex L from the surface along the axis,
    half-angle α) by the plane, axis tilted β off the normal: semi-major
    ``a`` (along the tilt), semi-minor ``b``, and the centre offset ``c``
    from the axis hit point toward the tilt (all in the units of L).

    Derivation: apex at the origin, plane z = −h (h = L cos β), axis u =
    (sin β, 0, −cos β).  The cone (X·u)² = |X|² cos²α on the plane gives
    −A x² + 2h sβ cβ x + h²(cβ² − cα²) = y² cα² with A = cα² − sβ²: an
    ellipse centred at x0 = h sβ cβ/A with b² = h² sα²/A and a = b cα/√A.
    Needs β < 90° − α."""
    L = np.asarray(L, dtype=float)
    beta = np.asarray(beta, dtype=float)
    alpha = np.arctan(tan_alpha)
    sa, ca = np.sin(alpha), np.cos(alpha)
    sb, cb = np.sin(beta), np.cos(beta)
    A = ca * ca - sb * sb
    if np.any(A <= 0):
        raise InvalidInputError("the tilt must stay below 90° − the cone half-angle")
    h = L * cb
    b = h * sa / np.sqrt(A)
    a = h * sa * ca / A
    c = h * sb * cb / A - h * np.tan(beta)
    return a, b, c


def first_order_ellipse(
    L: np.ndarray | float, tan_alpha: float, beta: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The first-order approximation: a = r/cos β, b = r, centre on the axis."""
    r = tan_alpha * np.asarray(L, dtype=float)
    beta = np.asarray(beta, dtype=float)
    return r / np.cos(beta), r * np.ones_like(beta), np.zeros_like(r * beta)


def squeeze_ratio(tan_alpha: float, beta: float) -> float:
    """b/a of the exact ellipse (independent of L): compressing the plane by
    this factor along the tilt turns every footprint of the cone at tilt β
    into a disc of radius b."""
    a, b, _ = exact_ellipse(1.0, tan_alpha, beta)
    return float(b / a)


def ellipse_matrices(
    semi_major: np.ndarray, semi_minor: np.ndarray, major_dir: np.ndarray
) -> np.ndarray:
    """(N,2,2) matrices M with ``|M (p − centre)| ≤ 1`` inside each ellipse."""
    a = np.asarray(semi_major, dtype=float).reshape(-1)
    b = np.asarray(semi_minor, dtype=float).reshape(-1)
    d = np.asarray(major_dir, dtype=float).reshape(-1, 2)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    n = np.stack([-d[:, 1], d[:, 0]], axis=1)
    return np.stack([d / a[:, None], n / b[:, None]], axis=1)


def ray_footprint(L: float, tan_alpha: float, beta: float, n_rays: int = 720) -> np.ndarray:
    """Brute force: where the cone's boundary rays meet the plane (2-D points,
    origin at the axis hit point, x along the tilt) — for tests and the
    benchmark's error table."""
    alpha = np.arctan(tan_alpha)
    h = L * np.cos(beta)
    apex = np.array([-L * np.sin(beta), 0.0, h])  # axis hits (0, 0, 0)
    u = -apex / L
    e1 = np.array([np.cos(beta), 0.0, np.sin(beta)])  # ⟂ u in the tilt plane
    e2 = np.array([0.0, 1.0, 0.0])
    t = np.linspace(0, 2 * np.pi, n_rays, endpoint=False)[:, None]
    dirs = np.cos(alpha) * u + np.sin(alpha) * (np.cos(t) * e1 + np.sin(t) * e2)
    s = -apex[2] / dirs[:, 2]
    hit = apex + s[:, None] * dirs
    return hit[:, :2]
