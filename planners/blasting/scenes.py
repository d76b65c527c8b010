"""The seed's test shapes and the under-deck environment (seed §4.1.2, §4.2).

Figures 4.4/4.5 are not in the seed text, so the environment is rebuilt
from what the text states — robot base at (500, 375, 370) mm, Surface 1
centred at (500, 500, 1700) mm on the roof of the channel between the
I-beams (Fig. 4.27), Surfaces 2 and 3 centred at (0, 500, 1500) and
(0, 1000, 1500) mm, the I-beam channel and the deck (Fig. 4.4) — and the
rest is chosen (marked below):

* chosen: the channel runs along world y between two I-beam girders whose
  webs face the robot at x = 0 and x = 1000 mm (the robot at x = 500 sits
  in the middle); girders 500 mm deep (z 1200–1700), flanges 200 × 20 mm,
  web 12 mm; the deck slab lies on top (underside z = 1700).
* chosen: Surfaces 2 and 3 are patches of the x = 0 girder web (normal +x).
  The issue's labels "front/top/side" cannot all hold with these centres:
  a vertical surface at y = 500 facing the robot would put the flange behind
  the base, out of reach, and a horizontal one at z = 1500, x = 0 would need
  a girder only 200 mm deep.  Surface 3 is small because its far edge is at
  the arm's reach (the seed needed 1,756 s there); the planner tilts the
  nozzle to reach it.
* chosen: outline sizes (Fig. 4.5 is not in the text): Surface 1 ≈ 0.55 ×
  0.40 m, Surface 2 ≈ 0.40 × 0.28 m, Surface 3 ≈ 0.31 × 0.27 m.

Everything here is plain data (no files): real field outlines are converted
by :func:`outline_from_lonlat` from coordinates the caller reads.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from planners.blasting.collision import Box
from planners.blasting.surface import Surface
from planners.errors import InvalidInputError

MM = 1e-3
ROBOT_BASE_MM = (500.0, 375.0, 370.0)  # seed §4.2.4
SURFACE_CENTRES_MM = {  # seed §4.2.4
    1: (500.0, 500.0, 1700.0),
    2: (0.0, 500.0, 1500.0),
    3: (0.0, 1000.0, 1500.0),
}
DISC_RADIUS_M = 0.04  # seed §4.2.1: discs of 0.04 m at 0.3 m stream
STREAM_MM = 300.0  # seed §4.2.1, §4.2.4


def robot_base() -> np.ndarray:
    """4×4 pose of the robot base in the world (seed §4.2.4)."""
    T = np.eye(4)
    T[:3, 3] = np.asarray(ROBOT_BASE_MM) * MM
    return T


# -- seed Fig. 4.9 shapes (unit size, centred; scaled by the caller) ----------------
def seed_shape(name: str, size_m: float = 0.5, *, n_circle: int = 96) -> np.ndarray:
    """Outline (K,2) of the seed's test shapes (Fig. 4.9): ``trapezoid``,
    ``circle`` or ``arbitrary`` (chosen vertices: a concave blob with a
    notch, since the figure is not in the text), largest extent ``size_m``."""
    if name == "trapezoid":
        P = np.array([[0.0, 0.0], [1.0, 0.0], [0.78, 0.62], [0.18, 0.62]])
    elif name == "circle":
        t = np.linspace(0, 2 * np.pi, n_circle, endpoint=False)
        P = 0.5 * np.stack([np.cos(t), np.sin(t)], axis=1)
    elif name == "arbitrary":
        P = np.array(
            [
                [0.00, 0.10], [0.22, 0.00], [0.48, 0.06], [0.70, 0.00], [1.00, 0.14],
                [0.92, 0.42], [0.98, 0.70], [0.74, 0.78], [0.60, 0.58], [0.46, 0.80],
                [0.20, 0.74], [0.06, 0.52], [0.14, 0.34],
            ]
        )  # fmt: skip
    else:
        raise InvalidInputError(
            f"unknown seed shape {name!r}; choose trapezoid, circle or arbitrary"
        )
    P = P - (P.min(axis=0) + P.max(axis=0)) / 2.0
    return P * (size_m / np.ptp(P, axis=0).max())


def outline_from_lonlat(
    rings: Sequence[np.ndarray], size_m: float, *, geographic: bool = True
) -> tuple[np.ndarray, list[np.ndarray]]:
    """A field outline (exterior ring first, then holes; lon/lat degrees, or
    plain units with ``geographic=False``) as a local outline in metres
    scaled so its largest extent is ``size_m``, centred on its bounding box."""
    rings = [np.asarray(r, dtype=float)[:, :2] for r in rings]
    if geographic:
        lat0 = np.deg2rad(np.mean(rings[0][:, 1]))
        k = np.array([np.cos(lat0), 1.0])
        rings = [r * k for r in rings]  # equirectangular, then rescaled anyway
    lo = rings[0].min(axis=0)
    hi = rings[0].max(axis=0)
    s = size_m / (hi - lo).max()
    c = (lo + hi) / 2.0
    out = [(r - c) * s for r in rings]
    return out[0], out[1:]


# -- the environment under the deck (Fig. 4.4) -------------------------------------------
def _ibeam_along_y(web_face_x: float, facing: int, name: str) -> list[Box]:
    """I-beam running along y, web face at ``web_face_x`` (mm) toward
    ``facing`` (+1: +x)."""
    y0, y1 = -800.0, 2000.0
    z_bot, z_top, tf, tw, bf = 1200.0, 1700.0, 20.0, 12.0, 200.0
    web_c = web_face_x - facing * tw / 2
    boxes = [
        ((web_c - tw / 2, y0, z_bot + tf), (web_c + tw / 2, y1, z_top - tf), "web"),
        ((web_c - bf / 2, y0, z_top - tf), (web_c + bf / 2, y1, z_top), "top flange"),
        ((web_c - bf / 2, y0, z_bot), (web_c + bf / 2, y1, z_bot + tf), "bottom flange"),
    ]
    return [
        Box.from_bounds(np.array(lo) * MM, np.array(hi) * MM, f"{name} {n}") for lo, hi, n in boxes
    ]


def bridge_obstacles() -> tuple[Box, ...]:
    """The I-beam channel and the deck slab (Fig. 4.4; dimensions chosen)."""
    deck = Box.from_bounds(
        np.array([-800.0, -800.0, 1700.0]) * MM, np.array([1800.0, 2000.0, 1900.0]) * MM, "deck"
    )
    return (
        deck,
        *_ibeam_along_y(0.0, +1, "girder x=0"),
        *_ibeam_along_y(1000.0, -1, "girder x=1000"),
    )


def obstacle_points(
    seed: int = 0, n: int = 400, *, xy: tuple[float, float] = (0.75, 0.55), z_low: float = 1.40
) -> np.ndarray:
    """A point obstacle in the workspace (the seed's red points, Fig. 4.27):
    a chosen 40 mm hanger rod from the deck down to ``z_low`` at ``xy`` (m),
    sampled on its surface.  The default stands at the edge of Surface 1,
    where the wrist passes close to it."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(z_low, 1.70, n)
    t = rng.uniform(0, 2 * np.pi, n)
    return np.stack([xy[0] + 0.02 * np.cos(t), xy[1] + 0.02 * np.sin(t), z], axis=1)


_S1 = np.array(
    [[-0.27, -0.17], [-0.05, -0.20], [0.20, -0.19], [0.28, -0.05], [0.24, 0.12],
     [0.10, 0.20], [-0.12, 0.19], [-0.26, 0.08]]
)  # fmt: skip
_S2 = np.array(
    [[-0.20, -0.13], [0.12, -0.14], [0.20, -0.02], [0.17, 0.14], [-0.08, 0.13], [-0.19, 0.06]]
)  # fmt: skip
_S3 = np.array(
    [[-0.15, -0.13], [0.14, -0.12], [0.16, 0.02], [0.13, 0.13], [-0.04, 0.14], [-0.15, 0.07]]
)


def bridge_surface(k: int) -> Surface:
    """Surface 1 (roof, normal −z), 2 or 3 (girder web, normal +x) with the
    seed's centres; outlines chosen (the boundary is relative to the centre)."""
    if k not in SURFACE_CENTRES_MM:
        raise InvalidInputError(f"unknown bridge surface {k!r}; choose 1, 2 or 3")
    c = np.asarray(SURFACE_CENTRES_MM[k]) * MM
    if k == 1:
        return Surface(c, np.array([0.0, 0.0, -1.0]), _S1)
    return Surface(c, np.array([1.0, 0.0, 0.0]), _S2 if k == 2 else _S3)


def table42_surface() -> Surface:
    """The surface of Table 4.2 / Fig. 4.11 (the seed's arbitrary shape; size
    chosen ≈ 0.8 m so ~90 discs of 0.04 m, like the seed's 6.6 m paths), on
    the roof."""
    return Surface(
        np.asarray(SURFACE_CENTRES_MM[1]) * MM,
        np.array([0.0, 0.0, -1.0]),
        seed_shape("arbitrary", 0.8),
    )
