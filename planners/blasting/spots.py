"""Per-spot robot poses of the sand-blasting planner (seed 004, §3.2.1,
§3.4.1–3.4.2, Eq. 3.15): the global nozzle tilt, the collision-free IK
branches of each spot, the Eq. 3.15 collision-penalty flags and the
grouping of spots by arm family.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import shapely
from scipy.spatial import cKDTree
from shapely.geometry import Polygon

from planners.blasting import arm as _arm
from planners.blasting.collision import Obstacles
from planners.blasting.constants import FOCI, SAFETY_M
from planners.blasting.surface import Surface


def _tilted_axis(surface: Surface, side: float, beta: float, direction: np.ndarray) -> np.ndarray:
    """Blast axis (into the surface) tilted by β toward the in-plane
    ``direction`` (plane coordinates)."""
    e = direction[0] * surface.x_axis + direction[1] * surface.y_axis
    return np.cos(beta) * (-side * surface.normal) + np.sin(beta) * e


def _choose_tilt(
    robot: Any, surface: Surface, side: float, standoff: float, q_start: np.ndarray
) -> tuple[float, np.ndarray]:
    """Global tilt (β, in-plane direction) that keeps every sampled surface
    point reachable in one arm family (shoulder × elbow branch) and the wrist
    centre as far from the J1 axis as possible (up to 0.15 m: beyond that a
    0.1 m/s nozzle needs < 40°/s on J1), smallest β first.
    Candidates: β ∈ {0, 10, 20, 30, 40}°, 12 directions."""
    poly = surface.polygon
    minx, miny, maxx, maxy = poly.bounds
    h = max(maxx - minx, maxy - miny) / 12.0
    gx, gy = np.meshgrid(np.arange(minx, maxx + h, h), np.arange(miny, maxy + h, h))
    g = np.stack([gx.ravel(), gy.ravel()], axis=1)
    g = g[shapely.contains_xy(poly, g[:, 0], g[:, 1])]
    outer = poly if isinstance(poly, Polygon) else poly.convex_hull
    # the surface encloses area (Surface.__post_init__), so its hull is a Polygon
    assert isinstance(outer, Polygon)
    ext = np.asarray(outer.exterior.coords)
    pts = surface.to_world(np.vstack([g, ext]))
    Binv = np.linalg.inv(robot.base)
    best = None
    for beta_deg in (0.0, 10.0, 20.0, 30.0, 40.0):
        dirs = [0.0] if beta_deg == 0 else np.linspace(0, 2 * np.pi, 12, endpoint=False)
        for phi in dirs:
            d2 = np.array([np.cos(phi), np.sin(phi)])
            a = _tilted_axis(surface, side, np.deg2rad(beta_deg), d2)
            fl = pts - a * standoff
            _, ok = robot.ik_axis(fl, np.repeat(a[None], len(fl), axis=0), q_start)
            # one arm family (shoulder × elbow; either wrist) for all points
            # means no reconfiguration is needed while blasting
            reach = float((ok[:, :4] | ok[:, 4:]).mean(axis=0).max())
            wc = (fl - a * robot.d[5]) @ Binv[:3, :3].T + Binv[:3, 3]
            rho = min(float(np.hypot(wc[:, 0], wc[:, 1]).min()), 0.15)
            key = (round(reach, 3), round(rho, 3), -beta_deg)
            if best is None or key > best[0]:
                best = (key, np.deg2rad(beta_deg), d2)
    # β = 0 is always tried, so best holds a candidate
    assert best is not None
    return best[1], best[2]


def _collision_free(
    robot: Any,
    Q: np.ndarray,
    ok: np.ndarray,
    obst: Obstacles,
    nozzle_m: float,
    kp: tuple[float, ...],
) -> np.ndarray:
    """ok & positive ellipsoid clearance for every (spot, branch)."""
    if obst.empty or not ok.any():
        return ok.copy()
    flat = Q.reshape(-1, 6)[ok.reshape(-1)]
    clear = _arm.waypoint_clearance(
        robot, flat, obst, nozzle_m, kp, FOCI, sign_only=True, margin=SAFETY_M
    )
    out = ok.copy()
    out[ok] = clear > SAFETY_M
    return out


def _penalty_matrix(
    robot: Any,
    surface: Surface,
    c2: np.ndarray,
    keep: np.ndarray,
    r: float,
    obst: Obstacles,
    axis: np.ndarray,
    standoff: np.ndarray,
    nozzle_m: float,
    kp: tuple[float, ...],
    q_start: np.ndarray,
) -> np.ndarray | None:
    """Eq. 3.15 flags: a move i→j is flagged when it passes within r of a
    surface point whose normal pose has no collision-free branch (a grid of
    pitch r over the surface)."""
    poly = surface.polygon
    minx, miny, maxx, maxy = poly.bounds
    gx, gy = np.meshgrid(np.arange(minx, maxx + r, r), np.arange(miny, maxy + r, r))
    g = np.stack([gx.ravel(), gy.ravel()], axis=1)
    g = g[shapely.contains_xy(poly, g[:, 0], g[:, 1])]
    if len(g) == 0:
        return None
    fl = surface.to_world(g) - axis * float(standoff[0, 0])
    Q, ok = robot.ik_axis(fl, np.repeat(axis[None], len(g), axis=0), q_start)
    free = _collision_free(robot, Q, ok, obst, nozzle_m, kp).any(axis=1)
    blocked = g[~free]
    if len(blocked) == 0:
        return None
    n = len(c2)
    if n > 1500:
        return None  # dense N² flags would cost more than they help; trajectory check still applies
    tree = cKDTree(blocked)
    pen = np.zeros((n, n))
    samples = np.linspace(0.0, 1.0, 9)
    # exact pruning: a point at t along i→j (length L) is at least
    # max(d_i − tL, d_j − (1 − t)L) ≥ (d_i + d_j − L)/2 from the blocked
    # points (d = each centre's distance to them), so pairs with that ≥ r
    # cannot be flagged; a pair with an end within r of them is flagged by
    # its end sample; only the others are sampled
    dc, _ = tree.query(c2, k=1)
    dc = np.asarray(dc, dtype=float).reshape(n)
    L = np.linalg.norm(c2[:, None, :] - c2[None, :, :], axis=-1)
    end = dc < r
    pen[end, :] = 1.0
    pen[:, end] = 1.0
    ii, jj = np.nonzero(((dc[:, None] + dc[None, :] - L) / 2.0 < r) & ~end[:, None] & ~end[None, :])
    for s in range(0, len(ii), 65536):
        a, b = ii[s : s + 65536], jj[s : s + 65536]
        seg = c2[a][:, None, :] + samples[None, :, None] * (c2[b] - c2[a])[:, None, :]
        d, _ = tree.query(seg.reshape(-1, 2), k=1)
        # k=1 over many points gives an array (the stubs also allow a scalar)
        pen[a, b] = (np.asarray(d).reshape(len(a), len(samples)) < r).any(axis=1)
    np.fill_diagonal(pen, 0.0)
    return pen


def _family_mask(f: np.ndarray) -> np.ndarray:
    """(K,8) branches of arm families ``f`` (K,): IK branch b = 4·wrist + f
    (robots.denso_vm6083.ik_all), so a family is a position branch with
    either wrist."""
    return (np.arange(8)[None, :] % 4) == np.asarray(f)[:, None]


def _family_groups(free: np.ndarray) -> list[tuple[np.ndarray, int]] | None:
    """Spots grouped by arm family when obstacles split them: None when one
    family (position branch, either wrist) reaches every spot collision-free;
    else a greedy set cover — the family reaching most of the spots left
    takes them all — as (spot indices, family), largest first.  Each group
    is then sequenced and blasted in its family, so the arm reconfigures
    (typically a 180° J1 swing) once per group instead of wherever the
    sequence happens to cross between spots only one family reaches."""
    fam = free[:, :4] | free[:, 4:]
    if fam.all(axis=0).any() or not fam.any(axis=1).all():
        return None
    left = np.ones(len(fam), dtype=bool)
    out = []
    while left.any():
        f = int(np.argmax((fam & left[:, None]).sum(axis=0)))
        g = np.nonzero(left & fam[:, f])[0]
        out.append((g, f))
        left[g] = False
    return out


def _join_tours(tours: list[np.ndarray], pts: np.ndarray) -> np.ndarray:
    """Concatenate tours in the given order, each after the first run in the
    direction that starts nearer to where the previous one ended."""
    out = [tours[0]]
    for t in tours[1:]:
        end = pts[out[-1][-1]]
        if np.linalg.norm(pts[t[-1]] - end) < np.linalg.norm(pts[t[0]] - end):
            t = t[::-1]
        out.append(t)
    return np.concatenate(out)
