"""Sand-blasting planner pipeline (seed 004, Chapters 3–4).

``plan_blasting(surface, ...)`` (DESIGN §5) runs the chain of seed Fig. 3.1
as named steps: :func:`_validate` (Eq. 3.1 disc radius) →
:func:`_footprint_frame` (global tilt §3.2.1, exact cone–plane footprint) →
:func:`_cover` (hexagonal disc pattern §3.2.2, classification Eq. 3.2,
boundary editing §3.2.3 or ours) → :func:`_spot_poses` (IK per spot with
the least joint change §3.4.1, tilt / Eq. 3.11 rescue, Eq. 3.15 flags) →
:func:`_sequence` (Eq. 3.3–3.4, 3.15; the seed's GA or ours) →
:func:`planners.blasting.trajectory._trajectory` (way-points and speed
limits Eq. 3.12–3.13, force-field ellipsoid clearance §3.4.2) →
:func:`_result`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import shapely
import shapely.affinity

from planners.blasting import arm as _arm
from planners.blasting import coverage as _cov
from planners.blasting import sequencing as _seq
from planners.blasting.bound import pointwise_bound, zero_overspray_reach
from planners.blasting.collision import Box, Obstacles
from planners.blasting.constants import (
    COVERAGE_TARGET,
    FOCI,
    JOINT_PLANNERS,
    KP,
    MAX_TILT_DEG,
    NOZZLE_LENGTH_M,
    OVERSPRAY_TARGET,
    SAFETY_M,
    START_POSE_DEG,
)
from planners.blasting.footprint import Cone, ellipse_matrices, exact_ellipse
from planners.blasting.nozzle import Nozzle, check_stream_length, get_nozzle
from planners.blasting.result import BlastPlan
from planners.blasting.spots import (
    _choose_tilt,
    _collision_free,
    _family_groups,
    _join_tours,
    _penalty_matrix,
    _tilted_axis,
)
from planners.blasting.surface import Surface
from planners.blasting.trajectory import _Traj, _trajectory
from planners.errors import InfeasibleError, InvalidInputError

__all__ = ["plan_blasting"]

#: Targets per closed-form IK call in the re-tilt search (bounds its temporaries).
IK_CHUNK = 8192


def _progress(cb: Callable[[float, str], None] | None, f: float, stage: str) -> None:
    if cb is not None:
        cb(f, stage)


def _coerce_surface(surface: object) -> Surface:
    if isinstance(surface, Surface):
        return surface
    raise InvalidInputError(
        f"surface must be a planners.blasting.Surface (or built with Surface.from_points), got {type(surface).__name__}"
    )


@dataclass
class _Setup:
    """Validated inputs: nozzle, stream length ``ds`` (mm), disc radius ``r``
    (Eq. 3.1), the fill discs' radius/stream, obstacles, ellipsoid factors."""

    noz: Nozzle
    ds: float
    r: float
    small_r: float | None
    fill_ds: float | None
    obst: Obstacles
    kp: tuple[float, ...]
    poly: Any
    cone: Cone
    spacing: float
    q_start: np.ndarray


@dataclass
class _Frame:
    """Footprint frame (§3.2.1): the plane compressed by b/a along the tilt,
    where every footprint of the global tilt β is a disc of radius ``rp``."""

    side: float
    beta: float
    tilt_dir: np.ndarray
    L0: float
    a0: float
    b0: float
    c0: float
    squeeze: np.ndarray
    unsqueeze: np.ndarray
    poly_fp: Any
    rp: float
    rp_small: float | None


@dataclass
class _Discs:
    """Discs after coverage (§3.2): in the footprint frame (``c_fp``,
    ``radii``) and the plane (``c2``), with per-disc stream, tilt, exact
    ellipse semi-axes/major direction and aim points (edited in place when
    a spot is re-tilted)."""

    angle: float
    lattice: np.ndarray
    lat_cls: np.ndarray
    c_fp: np.ndarray
    radii: np.ndarray
    cls: np.ndarray
    scale: np.ndarray
    stream: np.ndarray
    m_plan: Any
    c2: np.ndarray
    semi: np.ndarray
    major: np.ndarray
    aim2: np.ndarray
    world: np.ndarray
    tilt: np.ndarray


@dataclass
class _Poses:
    """Robot poses per spot (§3.4.1): ``keep`` (blastable), IK solutions
    ``Qs`` (N,8,6) and collision-free branches ``oks`` (N,8), Eq. 3.11
    residuals, the Eq. 3.15 penalty matrix, blast axes and flange points."""

    keep: np.ndarray
    Qs: np.ndarray | None = None
    oks: np.ndarray | None = None
    residual_mm: np.ndarray | None = None
    residual_deg: np.ndarray | None = None
    penalty: np.ndarray | None = None
    axes: np.ndarray | None = None
    flange: np.ndarray | None = None


def _validate(
    surface: Surface,
    nozzle: str | Nozzle,
    stream_length_mm: float,
    sequencer: str,
    joint_planner: str,
    editing: str,
    disc_radius_m: float | None,
    fill_stream_mm: float | None,
    obstacles: Obstacles | Sequence[Box | np.ndarray],
    kp: Sequence[float],
    start_pose_deg: Sequence[float],
) -> _Setup:
    """Check the options and derive the disc radius r from Eq. 3.1 (nozzle,
    stream length 100–500 mm) unless ``disc_radius_m`` is given; fill discs
    at the shorter ``fill_stream_mm`` have radius r·R(fill)/R(ds) (Eq. 3.1)."""
    noz = get_nozzle(nozzle)
    ds = check_stream_length(stream_length_mm)
    if sequencer not in ("default", "ga"):
        raise InvalidInputError(f"sequencer must be 'default' or 'ga', got {sequencer!r}")
    if joint_planner not in JOINT_PLANNERS:
        raise InvalidInputError(
            f"joint_planner must be one of {', '.join(JOINT_PLANNERS)}, got {joint_planner!r}"
        )
    if editing not in ("improved", "seed", "none"):
        raise InvalidInputError(f"editing must be 'improved', 'seed' or 'none', got {editing!r}")
    if disc_radius_m is not None:
        r = float(disc_radius_m)
        if not (np.isfinite(r) and r > 0):
            raise InvalidInputError(
                f"disc_radius_m must be a positive number of metres, got {disc_radius_m!r}"
            )
    else:
        r = noz.radius_mm(ds) / 1000.0
    small_r, fill_ds = None, None
    if fill_stream_mm is not None and editing == "improved":
        fill_ds = check_stream_length(fill_stream_mm)
        if fill_ds < ds:
            small_r = r * noz.radius_mm(fill_ds) / noz.radius_mm(ds)
    obst = Obstacles.coerce(obstacles)
    kp_t = tuple(float(k) for k in kp)
    if len(kp_t) != len(FOCI) or min(kp_t) <= 1.0:
        raise InvalidInputError(
            f"kp must be {len(FOCI)} numbers > 1 (seed: 1.05, 1.10, 1.10), got {kp_t}"
        )
    poly = surface.polygon
    cone = Cone.of(noz, r, ds / 1000.0)
    spacing = np.sqrt(3.0) * r
    q_start = np.deg2rad(np.asarray(start_pose_deg, dtype=float))
    return _Setup(noz, ds, r, small_r, fill_ds, obst, kp_t, poly, cone, spacing, q_start)


def _footprint_frame(
    surface: Surface,
    st: _Setup,
    robot: Any,
    tilt_deg: float | str,
    nozzle_length_m: float,
    start_pose_deg: Sequence[float],
) -> _Frame:
    """Global nozzle tilt (§3.2.1) and the frame where its footprints are discs.

    The seed's surfaces put the wrist centre almost on the J1 axis
    (shoulder singularity); tilting every spot's nozzle the same way (45–90°
    to the surface is allowed) moves it off.  The footprint becomes the
    exact conic section (footprint.py): an ellipse with semi-axes a (along
    the tilt) and b, centred c beyond the point where the axis meets the
    surface.  Coverage is planned in the plane compressed by b/a along the
    tilt, where every footprint of that tilt is a disc (of radius b at the
    nominal stream; all scale with the apex distance); area ratios, hence
    coverage and overspray, are unchanged by that map.  Each spot is aimed
    c before its footprint centre."""
    side = 1.0
    beta, tilt_dir = 0.0, np.array([1.0, 0.0])
    if robot is not None:
        if st.q_start.shape != (6,):
            raise InvalidInputError(f"start_pose_deg must have 6 angles, got {len(start_pose_deg)}")
        side = 1.0 if (robot.base[:3, 3] - surface.origin) @ surface.normal >= 0 else -1.0
        if tilt_deg == "auto":
            beta, tilt_dir = _choose_tilt(
                robot, surface, side, st.ds / 1000.0 + nozzle_length_m, st.q_start
            )
        else:
            beta = float(np.deg2rad(float(tilt_deg)))
            if not (0.0 <= beta <= np.deg2rad(MAX_TILT_DEG)):
                raise InvalidInputError(
                    f"tilt_deg must be 'auto' or 0–{MAX_TILT_DEG:g}°, got {tilt_deg!r}"
                )
    elif tilt_deg not in ("auto", 0, 0.0):
        raise InvalidInputError("tilt_deg needs a robot (it is chosen for reachability)")
    L0 = float(st.cone.length(st.ds / 1000.0))
    a0, b0, c0 = (float(v) for v in exact_ellipse(L0, st.cone.tan_alpha, beta))
    squeeze = _squeeze_map(b0 / a0, tilt_dir)  # plane → footprint-is-a-disc frame
    unsqueeze = np.linalg.inv(squeeze)
    poly_fp = shapely.affinity.affine_transform(
        st.poly, [squeeze[0, 0], squeeze[0, 1], squeeze[1, 0], squeeze[1, 1], 0.0, 0.0]
    )
    rp = b0  # footprint radius in that frame at the nominal stream (= r untilted)
    rp_small = rp * st.small_r / st.r if st.small_r else None
    return _Frame(side, beta, tilt_dir, L0, a0, b0, c0, squeeze, unsqueeze, poly_fp, rp, rp_small)


def _cover(
    surface: Surface,
    st: _Setup,
    fr: _Frame,
    editing: str,
    coverage_target: float,
    overspray_budget: float,
) -> _Discs:
    """Coverage (§3.2) in the footprint frame: hexagonal lattice (§3.2.2),
    Eq. 3.2 classes, then boundary editing (ours, the seed's §3.2.3 or none);
    each disc of radius ρ is blasted from apex distance L = L0·ρ/rp (every
    footprint of the cone scales with L), aimed c before its centre."""
    angle = _lattice_angle(fr.poly_fp)
    lattice = _cov.hex_lattice(fr.poly_fp, fr.rp, angle=angle)
    lat_cls = _cov.classify(lattice, fr.poly_fp, fr.rp)
    if editing == "improved":
        ed = _cov.edit_improved(
            fr.poly_fp, fr.rp, lattice=lattice, small_r=fr.rp_small,
            coverage_target=coverage_target, overspray_budget=overspray_budget,
            r_min=fr.rp_small,
        )  # fmt: skip
        c_fp, radii, cls = ed.centers, ed.radii, ed.classes
    elif editing == "seed":
        c_fp, cls = _cov.edit_seed(lattice, fr.poly_fp, fr.rp)
        radii = np.full(len(c_fp), fr.rp)
    else:
        keep = lat_cls != _cov.OUTSIDE
        c_fp, cls = lattice[keep], lat_cls[keep]
        radii = np.full(len(c_fp), fr.rp)
    if len(c_fp) == 0:
        raise InfeasibleError(
            f"no blasting disc of radius {st.r * 1000:.1f} mm fits the surface (area {surface.area:.4f} m²); "
            "use a smaller nozzle or a shorter stream length"
        )
    # every footprint of the cone scales with the apex distance L: a disc of
    # radius ρ in the footprint frame is blasted from L = L0·ρ/rp
    scale = radii / fr.rp
    stream = np.clip((fr.L0 * scale - st.cone.apex_m) * 1000.0, st.fill_ds or st.ds, st.ds)
    m_plan = _cov.measure(fr.poly_fp, c_fp, radii)
    c2 = c_fp @ fr.unsqueeze.T
    N = len(c2)
    semi = np.stack([fr.a0 * scale, fr.b0 * scale], axis=1)
    major = np.repeat(fr.tilt_dir[None], N, axis=0)
    aim2 = c2 - (fr.c0 * scale)[:, None] * fr.tilt_dir
    world = surface.to_world(c2)
    tilt = np.full(N, np.degrees(fr.beta))
    return _Discs(
        angle, lattice, lat_cls, c_fp, radii, cls, scale, stream, m_plan, c2, semi, major,
        aim2, world, tilt,
    )  # fmt: skip


def _spot_poses(
    robot: Any,
    surface: Surface,
    st: _Setup,
    fr: _Frame,
    d: _Discs,
    nozzle_length_m: float,
    kp: tuple[float, ...],
    seed: int,
) -> _Poses:
    """Robot poses and collision status per spot (§3.4.1–3.4.2): closed-form
    IK along the blast axis, collision-free branches; a spot with none is
    re-tilted (least extra tilt first, exact footprint re-aimed), rejected
    when reachable but every configuration penetrates, else given the
    Eq. 3.11 approximate-IK optimum when that is clear.  With obstacles the
    Eq. 3.15 penalty flags are computed.  Edits ``d`` in place for re-tilted
    spots (tilt, semi-axes, major direction, aim point)."""
    N = len(d.c2)
    keep = np.ones(N, dtype=bool)
    residual_mm = np.zeros(N)
    residual_deg = np.zeros(N)
    obst, cone, beta, L0 = st.obst, st.cone, fr.beta, fr.L0
    n_in = -fr.side * surface.normal
    axis0 = _tilted_axis(surface, fr.side, beta, fr.tilt_dir)
    axes = np.repeat(axis0[None], N, axis=0)  # blast axis into the surface
    standoff = (d.stream / 1000.0 + nozzle_length_m)[:, None]
    flange = surface.to_world(d.aim2) - axes * standoff
    Qs, oks = robot.ik_axis(flange, axes, st.q_start)
    ok_free = _collision_free(robot, Qs, oks, obst, nozzle_length_m, kp)
    # Surface.__post_init__ always resolves x_axis (None only as an argument)
    assert surface.x_axis is not None
    # spots with no collision-free closed-form solution: tilt, then Eq. 3.11,
    # all in one vectorised pass
    fail = np.nonzero(~ok_free.any(axis=1))[0]
    if len(fail):
        tilts = np.arange(5.0, MAX_TILT_DEG - np.degrees(beta) + 1e-9, 5.0)
        # reach bound: every tilt candidate's flange lies within standoff +
        # the largest footprint-centre shift of the disc centre (see
        # _aim_shift_bound), so beyond that no tilt has an exact solution
        far = _arm.beyond_reach_any_axis(
            robot, d.world[fail], standoff[fail, 0] + _aim_shift_bound(L0 * d.scale[fail], cone)
        )
        near = fail[~far]
        tried = np.zeros(N, dtype=bool)  # some tilt candidate has an exact solution
        if len(tilts) and len(near):
            tried[near] = _retilt(
                robot, surface, st, fr, d, near, tilts, n_in, standoff, axes, flange, Qs, oks,
                ok_free, nozzle_length_m, kp,
            )  # fmt: skip
        rescued = ok_free[fail].any(axis=1)
        # reachable, but every configuration penetrates: rejected
        reject = ~rescued & (oks[fail].any(axis=1) | tried[fail])
        keep[fail[reject]] = False
        # out of reach (or limits) for every axis tried: Eq. 3.11 optimum, batched
        rest = fail[~rescued & ~reject]
        if len(rest):
            qa, pe, ae, _ = _arm.approximate_ik_batch(
                robot, flange[rest], axes[rest], st.q_start, seed=seed
            )
            if obst.empty:
                clear_ok = np.ones(len(rest), dtype=bool)
            else:
                c = _arm.waypoint_clearance(robot, qa, obst, nozzle_length_m, kp, FOCI)
                clear_ok = c > SAFETY_M
            good, bad = rest[clear_ok], rest[~clear_ok]
            Qs[good] = qa[clear_ok, None, :]
            oks[good] = False
            oks[good, 0] = True
            ok_free[good] = oks[good]
            residual_mm[good] = pe[clear_ok] * 1000.0
            residual_deg[good] = ae[clear_ok]
            keep[bad] = False
    penalty = None
    if not obst.empty:
        penalty = _penalty_matrix(
            robot, surface, d.c2, keep, st.r, obst, axes[0], standoff, nozzle_length_m, kp,
            st.q_start,
        )  # fmt: skip
    return _Poses(keep, Qs, ok_free, residual_mm, residual_deg, penalty, axes, flange)


def _aim_shift_bound(L: np.ndarray, cone: Cone) -> np.ndarray:
    """Upper bound on the footprint-centre shift |c| of
    :func:`planners.blasting.footprint.exact_ellipse` for apex distances
    ``L`` and any tilt β ≤ 45° (:data:`MAX_TILT_DEG`): c = h·sβ·cβ/A −
    h·tan β with h = L·cos β ≤ L, A = cos²α − sin²β; both terms grow with β
    on [0°, 45°], so |c| ≤ L·(½/(cos²α − ½) + 1)."""
    ca2 = 1.0 / (1.0 + cone.tan_alpha**2)
    return np.asarray(L, dtype=float) * (0.5 / (ca2 - 0.5) + 1.0)


def _retilt(
    robot: Any,
    surface: Surface,
    st: _Setup,
    fr: _Frame,
    d: _Discs,
    spots: np.ndarray,
    tilts: np.ndarray,
    n_in: np.ndarray,
    standoff: np.ndarray,
    axes: np.ndarray,
    flange: np.ndarray,
    Qs: np.ndarray,
    oks: np.ndarray,
    ok_free: np.ndarray,
    nozzle_length_m: float,
    kp: tuple[float, ...],
) -> np.ndarray:
    """Re-tilt ``spots`` (no collision-free closed-form solution on the
    global tilt) to the least extra tilt with one, the exact footprint
    re-aimed so it stays centred: the closed-form IK of every candidate of
    every spot in one batch, the collision check tilt by tilt over the spots
    still unresolved (least extra tilt first, then azimuth order, as the
    per-spot search).  Edits the arrays and ``d`` in place for re-tilted
    spots; returns, per spot, whether any candidate had an exact solution."""
    assert surface.x_axis is not None
    n = len(spots)
    # every failing spot still has the global axis here
    cand = _arm.tilted_axes(axes[spots[0]], tilts)  # (C,3), tilts ascend, 8 azimuths each
    C = len(cand)
    bc = np.arccos(np.clip(cand @ n_in, -1.0, 1.0))
    e3 = cand - np.cos(bc)[:, None] * n_in
    e2 = np.stack([e3 @ surface.x_axis, e3 @ surface.y_axis], axis=1)
    e2 /= np.maximum(np.linalg.norm(e2, axis=1, keepdims=True), 1e-12)
    ac, bcm, cc = exact_ellipse(fr.L0 * d.scale[spots][:, None], st.cone.tan_alpha, bc[None, :])
    aims = d.c2[spots][:, None, :] - cc[..., None] * e2[None]  # (n,C,2)
    fl = (
        surface.to_world(aims.reshape(-1, 2)).reshape(n, C, 3)
        - cand[None] * standoff[spots][:, :, None]
    )
    # closed-form IK of every candidate the reach bound leaves (its wrist
    # centre within wrist_reach_m of the shoulder circle: beyond it no
    # branch exists, :func:`planners.blasting.arm.wrist_reach_m`; on the 4 m
    # square 91 % of the 181,888 candidates), IK_CHUNK targets a call: its
    # temporaries are a few (targets, 8, 4, 4) arrays each.  The others keep
    # ok = False (their Q is never read: only ok branches are checked/taken)
    flat, axs = fl.reshape(-1, 3), np.tile(cand, (n, 1))
    Qf: np.ndarray = np.zeros((len(flat), 8, 6))
    okf: np.ndarray = np.zeros((len(flat), 8), dtype=bool)
    live = np.nonzero(~_arm.beyond_reach(robot, flat, axs))[0]
    for a in range(0, len(live), IK_CHUNK):
        sel = live[a : a + IK_CHUNK]
        Qf[sel], okf[sel] = robot.ik_axis(flat[sel], axs[sel], st.q_start)
    Qt, okt = Qf.reshape(n, C, 8, 6), okf.reshape(n, C, 8)
    reach = np.asarray(okt.any(axis=2), dtype=bool)
    open_ = np.ones(n, dtype=bool)
    per = C // len(tilts)
    for t in range(len(tilts)):
        cols = slice(t * per, (t + 1) * per)
        rows = np.nonzero(open_ & reach[:, cols].any(axis=1))[0]
        if not len(rows):
            continue
        freet: np.ndarray = np.asarray(
            _collision_free(
                robot, Qt[rows, cols].reshape(-1, 8, 6), okt[rows, cols].reshape(-1, 8), st.obst,
                nozzle_length_m, kp,
            )
        ).reshape(len(rows), per, 8)  # fmt: skip
        hit = np.asarray(freet.any(axis=2))
        for r in np.nonzero(hit.any(axis=1))[0]:
            k = rows[r]
            j = t * per + int(np.argmax(hit[r]))
            i = spots[k]
            axes[i], flange[i], d.aim2[i] = cand[j], fl[k, j], aims[k, j]
            Qs[i], oks[i], ok_free[i] = Qt[k, j], okt[k, j], freet[r, j - t * per]
            d.tilt[i] = float(np.degrees(bc[j]))
            d.semi[i] = (ac[k, j], bcm[k, j])
            d.major[i] = e2[j]
            open_[k] = False
    return np.asarray(reach.any(axis=1), dtype=bool)


def _sequence(
    d: _Discs,
    ps: _Poses,
    idx: np.ndarray,
    r: float,
    sequencer: str,
    collision_penalty_m: float,
    seed: int,
) -> tuple[np.ndarray, np.ndarray, list[tuple[np.ndarray, int]] | None]:
    """Sequencing (§3.3): Eq. 3.3–3.4 tour of the kept discs ``idx`` with the
    Eq. 3.15 collision penalty, by our row sequencer or the seed's GA
    (§3.3.2); spots split between arm families are toured per family group
    and the tours joined.  Returns the disc order, each disc's family (−1:
    ungrouped) and the groups."""
    P2 = d.c2[idx]
    pen = ps.penalty[np.ix_(idx, idx)] if ps.penalty is not None else None
    cpen = collision_penalty_m if pen is not None else 0.0

    def sequence(g: np.ndarray) -> np.ndarray:
        pg = pen[np.ix_(g, g)] if pen is not None else None
        if len(g) <= 2:
            return g
        if sequencer == "ga":
            return g[_seq.sequence_ga(P2[g], penalty=pg, c=cpen, seed=seed).order]
        return g[
            _seq.sequence_default(P2[g], row_pitch=1.5 * r, angles=(d.angle,), penalty=pg, c=cpen)
        ]

    family = np.full(len(d.c2), -1)
    # oks and Qs are set together (with a robot)
    groups = _family_groups(ps.oks[idx]) if ps.oks is not None else None
    if groups is None:
        sub = sequence(np.arange(len(idx)))
    else:
        sub = _join_tours([sequence(g) for g, _ in groups], P2)
        for g, f in groups:
            family[idx[g]] = f
    return idx[sub], family, groups


def _params(
    st: _Setup, fr: _Frame, d: _Discs, editing: str, sequencer: str, seed: int, joint_planner: str
) -> dict[str, Any]:
    """The plan's resolved parameters, as stored with it."""
    return {
        "nozzle": st.noz.name, "stream_length_mm": st.ds, "disc_radius_m": st.r,
        "fill_stream_mm": st.fill_ds, "small_radius_m": st.small_r, "editing": editing,
        "sequencer": sequencer, "seed": seed, "lattice_angle_rad": d.angle,
        "turn_threshold_deg": _seq.TURN_THRESHOLD_DEG,
        "tilt_deg": float(np.degrees(fr.beta)), "tilt_direction_2d": fr.tilt_dir.tolist(),
        "cone_tan_alpha": st.cone.tan_alpha, "cone_apex_m": st.cone.apex_m,
        "footprint_semi_axes_m": [fr.a0, fr.b0], "footprint_center_shift_m": fr.c0,
        "joint_planner": joint_planner,
    }  # fmt: skip


def _result(
    surface: Surface,
    st: _Setup,
    fr: _Frame,
    d: _Discs,
    keep: np.ndarray,
    idx: np.ndarray,
    order: np.ndarray,
    penalty: np.ndarray | None,
    collision_penalty_m: float,
    per_spot_possible: bool,
    editing: str,
    params: dict[str, Any],
    timings: dict[str, float],
) -> BlastPlan:
    """Sequence statistics (Eq. 3.3–3.4: distance, turns, objective, MST lower
    bound) of the final order and coverage/overspray of the visited
    footprints — exact ellipses when some spot carries its own tilt — with
    the zero-overspray reach and, below target, the certified pointwise bound."""
    pen = penalty[np.ix_(idx, idx)] if penalty is not None else None
    cpen = collision_penalty_m if pen is not None else 0.0
    P2 = d.c2[idx]
    pos = {int(i): k for k, i in enumerate(idx)}
    sub = np.array([pos[int(i)] for i in order], dtype=int)
    sq = _seq.stats(P2, sub, st.spacing, pen, cpen)
    per_spot = per_spot_possible and not np.allclose(d.tilt[keep], np.degrees(fr.beta))
    vis = np.nonzero(keep)[0]
    if per_spot:
        # some spots carry their own tilt: measure every footprint as it is
        mats = ellipse_matrices(d.semi[vis, 0], d.semi[vis, 1], d.major[vis])
        m_done = _cov.measure(st.poly, d.c2[vis], d.semi[vis, 1], mats)
    else:
        m_done = d.m_plan if keep.all() else _cov.measure(fr.poly_fp, d.c_fp[vis], d.radii[vis])
    reach = zero_overspray_reach(fr.poly_fp, float(fr.rp_small or fr.rp))
    bound_val = None
    if m_done.coverage < COVERAGE_TARGET and editing == "improved":
        bound_val = pointwise_bound(
            fr.poly_fp, float(fr.rp_small or fr.rp), OVERSPRAY_TARGET
        ).coverage_max
    return BlastPlan(
        radius=st.r, centers=d.world, centers_2d=d.c2, radii=d.radii,
        classes=np.asarray(d.cls, dtype=np.int8), stream_mm=d.stream, tilt_deg=d.tilt,
        order=order, skipped=np.nonzero(~keep)[0], distance_m=sq.distance_m, turns=sq.turns,
        objective=sq.objective, lower_bound_m=sq.lower_bound_m, mst_m=sq.mst_m,
        coverage=m_done.coverage, overspray=m_done.overspray, coverage_planned=d.m_plan.coverage,
        overspray_planned=d.m_plan.overspray, lattice_centers_2d=d.lattice,
        lattice_classes=d.lat_cls, spacing_m=st.spacing, params=params, timings_s=timings,
        aim_points=surface.to_world(d.aim2), aim_points_2d=d.aim2, semi_axes=d.semi,
        major_dir_2d=d.major, coverage_reach=reach, coverage_bound=bound_val,
        min_radius_m=float(fr.rp_small or fr.rp),
    )  # fmt: skip


def _attach_trajectory(
    plan: BlastPlan,
    traj: _Traj,
    robot: Any,
    obst: Obstacles,
    ps: _Poses,
    nozzle_length_m: float,
    kp: tuple[float, ...],
    traverse_speed_m_s: float,
    speed_limit_deg_s: float,
) -> None:
    """Clearance at every way-point (§3.4.2) and time stamps: blasting moves
    at the traverse speed, every step stretched to the joint speed limit
    (Eq. 3.12–3.13)."""
    q, seg, spot = traj.q, traj.segment, traj.spot
    clear = _arm.waypoint_clearance(robot, q, obst, nozzle_length_m, kp, FOCI)
    nominal = np.zeros(len(q) - 1)
    blast = seg[1:] == 2
    F = robot.frames(q)[:, -1, :3, 3]
    nominal[blast] = np.linalg.norm(np.diff(F, axis=0), axis=1)[blast] / traverse_speed_m_s
    v = np.deg2rad(speed_limit_deg_s)
    plan.joint_trajectory = q
    plan.times = _arm.time_stamps(q, nominal, v)
    plan.clearance = clear
    plan.segment = seg
    plan.waypoint_spot = spot
    plan.ik_residual_mm = ps.residual_mm
    plan.ik_residual_deg = ps.residual_deg
    plan.joint_limits = robot.joint_limits.copy()
    plan.speed_limit_rad_s = v
    plan.unreached = np.asarray(traj.unreached, dtype=int)
    plan.motion = traj.stats


def plan_blasting(
    surface: Surface,
    *,
    nozzle: str | Nozzle = "medium",
    stream_length_mm: float = 300.0,
    sequencer: str = "default",
    robot: Any = None,
    obstacles: Obstacles | Sequence[Box | np.ndarray] = (),
    seed: int = 0,
    disc_radius_m: float | None = None,
    editing: str = "improved",
    fill_stream_mm: float | None = 100.0,
    coverage_target: float = 0.993,
    overspray_budget: float = 0.004,
    collision_penalty_m: float = 1.0,
    kp: Sequence[float] = KP,
    nozzle_length_m: float = NOZZLE_LENGTH_M,
    speed_limit_deg_s: float = 30.0,
    traverse_speed_m_s: float = 0.1,
    step_m: float = 0.01,
    approach_waypoints: int = 100,
    start_pose_deg: Sequence[float] = START_POSE_DEG,
    tilt_deg: float | str = "auto",
    joint_planner: str = "none",
    progress: Callable[[float, str], None] | None = None,
) -> BlastPlan:
    """Plan blasting of a planar ``surface`` (DESIGN §5).

    Disc radius from Eq. 3.1 (``nozzle``, ``stream_length_mm`` in 100–500 mm)
    unless ``disc_radius_m`` is given (the seed's scenes use 0.04 m).
    ``editing``: ``"improved"`` (ours), ``"seed"`` (§3.2.3) or ``"none"``;
    with ``fill_stream_mm`` ours may add discs at that shorter stream length
    (smaller, Eq. 3.1) where full discs cannot reach without overspray.
    ``sequencer``: ``"default"`` (ours) or ``"ga"`` (the seed's, §3.3.2).
    ``robot``: a model with ``frames``/``ik_axis`` (``robots.load_robot(
    "denso_vm6083")`` placed with ``with_base``), nozzle on the side of the
    plane where the robot base is; ``obstacles``: :class:`Box` es and (M,3)
    point arrays (world frame, metres).  Deterministic for a given ``seed``.
    ``joint_planner``: ``"none"`` (default) keeps the clearest via-point
    move for a transition that is not certified free (the clearance check
    then fails); ``"rrt"`` plans such moves with RRT-Connect
    (:mod:`planners.blasting.motion`, budget :data:`RRT_MAX_ITER` per move,
    :data:`RRT_BUDGET_ITER` per plan) and leaves out spots it cannot reach.
    Not the default: a spot blasted from a pose with millimetres of
    clearance traps the search, and every later spot is then tried from it
    (on Surface 2 with a blocking box: 63 of 66 spots unreached, ~80 s).
    """
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    surface = _coerce_surface(surface)
    st = _validate(
        surface, nozzle, stream_length_mm, sequencer, joint_planner, editing, disc_radius_m,
        fill_stream_mm, obstacles, kp, start_pose_deg,
    )  # fmt: skip
    fr = _footprint_frame(surface, st, robot, tilt_deg, nozzle_length_m, start_pose_deg)

    _progress(progress, 0.0, "coverage")
    d = _cover(surface, st, fr, editing, coverage_target, overspray_budget)
    timings["coverage_s"] = time.perf_counter() - t0
    params = _params(st, fr, d, editing, sequencer, seed, joint_planner)

    if robot is not None:
        t1 = time.perf_counter()
        _progress(progress, 0.25, "inverse kinematics")
        ps = _spot_poses(robot, surface, st, fr, d, nozzle_length_m, st.kp, seed)
        timings["ik_collision_s"] = time.perf_counter() - t1
    else:
        N = len(d.c2)
        ps = _Poses(np.ones(N, dtype=bool), residual_mm=np.zeros(N), residual_deg=np.zeros(N))
    keep = ps.keep
    idx = np.nonzero(keep)[0]
    if len(idx) == 0:
        raise InfeasibleError("no disc of the surface can be blasted without a collision")

    t2 = time.perf_counter()
    _progress(progress, 0.5, "sequencing")
    order, family, groups = _sequence(d, ps, idx, st.r, sequencer, collision_penalty_m, seed)
    timings["sequencing_s"] = time.perf_counter() - t2

    traj = None
    if robot is not None:
        t3 = time.perf_counter()
        _progress(progress, 0.75, "trajectory")
        # _spot_poses sets all four whenever there is a robot
        assert ps.flange is not None and ps.axes is not None
        assert ps.Qs is not None and ps.oks is not None
        traj = _trajectory(
            robot, order, ps.flange, ps.axes, ps.Qs, ps.oks, st.q_start, step_m,
            approach_waypoints, st.obst, nozzle_length_m, st.kp, joint_planner, seed, family,
        )  # fmt: skip
        traj.stats["family_groups"] = 1 if groups is None else len(groups)
        if len(traj.unreached):
            keep[traj.unreached] = False
            order = order[~np.isin(order, traj.unreached)]

    plan = _result(
        surface, st, fr, d, keep, idx, order, ps.penalty, collision_penalty_m, robot is not None,
        editing, params, timings,
    )  # fmt: skip
    if traj is not None:
        _attach_trajectory(
            plan, traj, robot, st.obst, ps, nozzle_length_m, st.kp, traverse_speed_m_s,
            speed_limit_deg_s,
        )  # fmt: skip
        timings["trajectory_s"] = time.perf_counter() - t3
    timings["total_s"] = time.perf_counter() - t0
    _progress(progress, 1.0, "done")
    return plan


def _lattice_angle(poly: Any) -> float:
    """Rows along the long side of the minimum rotated rectangle: fewer,
    longer rows mean fewer row changes (turns)."""
    rect = poly.minimum_rotated_rectangle
    xy = np.asarray(rect.exterior.coords)[:4]
    e = np.diff(np.vstack([xy, xy[:1]]), axis=0)
    k = int(np.argmax(np.linalg.norm(e, axis=1)))
    return float(np.arctan2(e[k, 1], e[k, 0]) % np.pi)


def _squeeze_map(ratio: float, direction: np.ndarray) -> np.ndarray:
    """2×2 map compressing the plane by ``ratio`` (= b/a of the tilted
    footprint, :func:`planners.blasting.footprint.squeeze_ratio`) along
    ``direction``: every footprint of that tilt becomes a disc."""
    d = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    return np.eye(2) - (1.0 - float(ratio)) * np.outer(d, d)
