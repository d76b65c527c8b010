"""Sample clouds of the blasting scenes (seed 004 Fig. 4.4), for the console
and the tests: points drawn uniformly on the seed's surfaces and boxes."""

from __future__ import annotations

import numpy as np
import shapely

from planners.blasting import scenes


def under_deck_cloud(seed: int) -> np.ndarray:
    """The seed's Fig. 4.4 environment as a cloud (2 mm noise): the three
    rusted patches (Surfaces 1–3) densely, and the I-beam channel around them
    sparsely — pick a plane with ``plane_index``."""
    rng = np.random.default_rng(seed)
    parts = []
    for k in (1, 2, 3):
        s = scenes.bridge_surface(k)
        minx, miny, maxx, maxy = s.polygon.bounds
        uv = rng.uniform([minx, miny], [maxx, maxy], size=(int(s.area / 2.5e-5) * 2, 2))
        uv = uv[shapely.contains_xy(s.polygon, uv[:, 0], uv[:, 1])]
        parts.append(s.to_world(uv))
    # sparse context: the flanges of both girders and the far girder's web
    # (the deck and the near web carry the patches and are left out so the
    # patches come out as planes of their own)
    for b in scenes.bridge_obstacles()[1:]:
        if "x=0 web" in b.name:
            continue
        n = int(np.prod(np.sort(b.half)[1:]) * 4 / 4e-4)
        loc = rng.uniform(-1, 1, size=(n, 3))
        ax = rng.integers(0, 3, n)
        loc[np.arange(n), ax] = np.sign(loc[np.arange(n), ax])  # on a face
        parts.append(b.center + loc * b.half)
    pts = np.concatenate(parts)
    return pts + rng.normal(scale=0.002, size=pts.shape)
