"""Synthetic depth scans mirroring the seed's switching experiments (§5.2.1–5.2.2).

Each scene is a set of planar steel surfaces (polygons in their own plane
frame) around an ARA robot standing on z = 0 of its base frame, seen by the
depth camera on foot 2's mast: rays over the pixel grid are cast against the
surfaces, clipped to the sensor's range, and perturbed along the ray by the
axial noise model σ(z) = s0 + s2·(z − 0.4)² (Nguyen et al. 2012, Kinect
class), with random pixel dropout.  Points come back in the camera (optical)
frame, as a real scan would.  Everything is deterministic given ``seed``.

| scene              | seed experiment                        |
| ------------------ | -------------------------------------- |
| same_height        | Fig. 5.3(a): surface at base height    |
| step_down_7cm      | Fig. 5.3(b): surface 7 cm lower        |
| perpendicular      | Fig. 5.4: two perpendicular slabs      |
| narrow_surface     | Fig. 5.2(b)-(d): 1 of 5 rectangles fit |
| too_small          | Fig. 5.2 (insufficient surface)        |
| corroded_slab      | §5.1 corroded slabs, holes (Alg. 1)    |
| no_surface         | Eq. 3.2 with P_cl = ∅                  |

The mode each scene must give is the seed's, asserted in the tests
(``tests/switching/test_scenes.py``), not stated here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from planners.errors import InvalidInputError
from planners.switching.availability import PlaneFrame


@dataclass(frozen=True)
class DepthCamera:
    """Pinhole depth camera (defaults: the ARA's, robots/ara/params.toml)."""

    position: tuple[float, float, float] = (0.06, 0.13, 0.40)
    pitch_down_deg: float = 35.0
    hfov_deg: float = 58.0
    vfov_deg: float = 45.0
    width_px: int = 160
    height_px: int = 120
    min_range_m: float = 0.2
    max_range_m: float = 2.5
    noise_sigma0_m: float = 0.0012
    noise_sigma2_per_m: float = 0.0019
    dropout: float = 0.01

    def camera_to_base(self) -> np.ndarray:
        """4×4 optical frame → base: z along the view, x right, y down."""
        a = np.radians(self.pitch_down_deg)
        z = np.array([np.cos(a), 0.0, -np.sin(a)])
        x = np.array([0.0, -1.0, 0.0])
        T = np.eye(4)
        T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
        T[:3, 3] = self.position
        return T


@dataclass
class SceneSurface:
    """A planar polygon ``polygon`` (shapely, plane coordinates) in ``frame``."""

    name: str
    frame: PlaneFrame
    polygon: BaseGeometry


@dataclass
class Scene:
    """A synthetic scan of one of the seed's experiments (the verdict it must
    give is asserted in ``tests/switching/test_scenes.py``, from the seed)."""

    name: str
    points: np.ndarray  # (N, 3) camera frame
    camera_to_base: np.ndarray
    base_height: float
    surfaces: list[SceneSurface]
    description: str
    spheres: list[tuple[np.ndarray, float]] = field(default_factory=list)

    def points_base(self) -> np.ndarray:
        T = self.camera_to_base
        return self.points @ T[:3, :3].T + T[:3, 3]


def _horizontal(name: str, z: float, poly: BaseGeometry) -> SceneSurface:
    """Surface in the plane z = const, polygon in base x/y, normal +z."""
    return SceneSurface(
        name, PlaneFrame.from_normal(np.array([0.0, 0.0, z]), np.array([0, 0, 1.0])), poly
    )


def _wall_facing_minus_x(name: str, x: float, poly_yz: shapely.Polygon) -> SceneSurface:
    """Surface in the plane x = const facing the robot (normal −x); the
    polygon is given in base (y, z) and mapped into the plane frame."""
    frame = PlaneFrame.from_normal(np.array([x, 0.0, 0.0]), np.array([-1.0, 0.0, 0.0]))
    yz = shapely.get_coordinates(poly_yz.exterior)
    xyz = np.column_stack([np.full(len(yz), x), yz])
    return SceneSurface(name, frame, shapely.Polygon(frame.to_plane(xyz)))


def raycast(
    surfaces: list[SceneSurface],
    camera: DepthCamera,
    *,
    seed: int = 0,
    spheres: list[tuple[np.ndarray, float]] = (),  # type: ignore[assignment]
) -> np.ndarray:
    """Simulated depth scan (N, 3) in the camera frame (vectorised over rays)."""
    rng = np.random.default_rng(seed)
    T = camera.camera_to_base()
    u = np.linspace(-1, 1, camera.width_px) * np.tan(np.radians(camera.hfov_deg) / 2)
    v = np.linspace(-1, 1, camera.height_px) * np.tan(np.radians(camera.vfov_deg) / 2)
    uu, vv = np.meshgrid(u, v)
    d_cam = np.stack([uu.ravel(), vv.ravel(), np.ones(uu.size)], axis=1)
    d_cam /= np.linalg.norm(d_cam, axis=1, keepdims=True)
    d = d_cam @ T[:3, :3].T
    c = T[:3, 3]
    best = np.full(len(d), np.inf)
    for s in surfaces:  # a few surfaces
        n = s.frame.normal
        denom = d @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((s.frame.origin - c) @ n) / denom
        ok = np.isfinite(t) & (t > 0)
        hit2 = s.frame.to_plane(c + t[:, None] * d)
        ok &= shapely.contains_xy(s.polygon, hit2[:, 0], hit2[:, 1])
        best = np.where(ok & (t < best), t, best)
    for centre, radius in spheres:
        oc = c - np.asarray(centre, float)
        b = d @ oc
        disc = b**2 - (oc @ oc - radius**2)
        t = -b - np.sqrt(np.maximum(disc, 0.0))
        ok = (disc >= 0) & (t > 0)
        best = np.where(ok & (t < best), t, best)
    z = best * d_cam[:, 2]  # depth along the optical axis
    keep = np.isfinite(best) & (z >= camera.min_range_m) & (z <= camera.max_range_m)
    keep &= rng.random(len(best)) >= camera.dropout
    sigma = camera.noise_sigma0_m + camera.noise_sigma2_per_m * (z[keep] - 0.4) ** 2
    t_noisy = best[keep] + rng.normal(0.0, 1.0, keep.sum()) * sigma / d_cam[keep, 2]
    return t_noisy[:, None] * d_cam[keep]


def _standing(x_end: float) -> SceneSurface:
    """The slab the robot stands on: z = 0, from behind the robot to ``x_end``."""
    return _horizontal("standing", 0.0, shapely.box(-0.9, -0.5, x_end, 0.5))


def _same_height(rng: np.random.Generator) -> tuple[list[SceneSurface], list, str]:
    return [_standing(1.8)], [], "Fig. 5.3(a): the slab continues ahead at base height"


def _step_down(rng: np.random.Generator) -> tuple[list[SceneSurface], list, str]:
    surfaces = [
        _standing(0.14),
        _horizontal("lower", -0.07, shapely.box(0.14, -0.5, 1.8, 0.5)),
    ]
    return surfaces, [], "Fig. 5.3(b): the next slab is 7 cm below the base"


def _perpendicular(rng: np.random.Generator) -> tuple[list[SceneSurface], list, str]:
    surfaces = [
        _standing(0.45),
        _wall_facing_minus_x("wall", 0.45, shapely.box(-0.5, 0.0, 0.5, 0.8)),
    ]
    return surfaces, [], "Fig. 5.4: a second slab perpendicular to the first, ahead"


def _narrow(rng: np.random.Generator) -> tuple[list[SceneSurface], list, str]:
    # An irregular pentagonal plate 5 cm below the base, barely larger than a
    # foot: of Alg. 2's five rectangles exactly one passes (Fig. 5.2(b)-(c)).
    # The outline was picked by a seeded random search over pentagons for one
    # where that holds for every noise seed 0-7 (tests check 0-4).
    plate = shapely.Polygon(
        [(0.55, 0.07), (0.35, 0.02), (0.32, -0.15), (0.52, -0.19), (0.54, -0.16)]
    )
    surfaces = [_standing(0.12), _horizontal("plate", -0.05, plate)]
    return (
        surfaces,
        [],
        "Fig. 5.2: an irregular plate where one of five rectangles fits",
    )


def _too_small(rng: np.random.Generator) -> tuple[list[SceneSurface], list, str]:
    plate = shapely.box(0.45, -0.06, 0.60, 0.05)  # 15 × 11 cm < foot 18 × 12 cm
    surfaces = [_standing(0.12), _horizontal("plate", -0.05, plate)]
    return surfaces, [], "Fig. 5.2 (insufficient area): a plate smaller than a foot"


def _corroded(rng: np.random.Generator) -> tuple[list[SceneSurface], list, str]:
    slab = shapely.box(-0.9, -0.5, 1.8, 0.5)
    centres = rng.uniform((0.35, -0.35), (0.85, 0.35), (10, 2))
    radii = rng.uniform(0.012, 0.03, 10)
    holes = shapely.union_all(
        [shapely.Point(*p).buffer(r) for p, r in zip(centres, radii, strict=True)]
    )
    return (
        [_horizontal("corroded", 0.0, slab.difference(holes))],
        [],
        "§5.1 corroded slab at base height with pits (NCBE ignores small holes)",
    )


def _no_surface(rng: np.random.Generator) -> tuple[list[SceneSurface], list, str]:
    # The beam ends just ahead of foot 2; beyond it only clutter (cables,
    # bolts) far below: nothing planar to step on.
    spheres = [
        (np.array([0.7, -0.1, -0.35]), 0.05),
        (np.array([0.9, 0.2, -0.3]), 0.04),
        (np.array([1.2, -0.3, -0.45]), 0.08),
    ]
    return [_standing(0.12)], spheres, "Eq. 3.2: no planar surface in view (P_cl = ∅)"


SCENES: dict[str, Callable[[np.random.Generator], tuple[list[SceneSurface], list, str]]] = {
    "same_height": _same_height,
    "step_down_7cm": _step_down,
    "perpendicular": _perpendicular,
    "narrow_surface": _narrow,
    "too_small": _too_small,
    "corroded_slab": _corroded,
    "no_surface": _no_surface,
}


def make_scene(name: str, seed: int = 0, *, camera: DepthCamera | None = None) -> Scene:
    """Build scene ``name`` (one of :data:`SCENES`) with noise seed ``seed``."""
    if name not in SCENES:
        raise InvalidInputError(f"unknown scene {name!r}; known: {', '.join(SCENES)}")
    cam = camera or DepthCamera()
    rng = np.random.default_rng(seed)
    surfaces, spheres, text = SCENES[name](rng)
    pts = raycast(surfaces, cam, seed=seed, spheres=spheres)
    return Scene(
        name=name,
        points=pts,
        camera_to_base=cam.camera_to_base(),
        base_height=0.0,
        surfaces=surfaces,
        description=text,
        spheres=spheres,
    )
