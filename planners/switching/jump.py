"""Inch-worm jump planning for the ARA robot (seed §3.2, §5.2.2, Fig. 3.5/5.4).

Phases (magnet states as (foot 1, foot 2)):

  A  magnet 2 touched                               (untouched, touched)
  B  foot 1 lifts off and the arm goes to P_conv    anchor foot 2
  C  foot 1 to the target: RRT-Connect in joint space to a pose hovering
     ``standoff_m`` above the foothold, then a straight approach to contact
  D  magnets swap: 1 touched, 2 untouched           (touched, untouched)
  E  foot 2 lifts off, swings (RRT-Connect) and lands beside foot 1 on the
     target surface                                 anchor foot 1
  F  both arrays untouched: mobile configuration    (untouched, untouched)

The seed ran MoveIt's KDL IK and RRTConnect and reports the planner "was not
robust and needed to redo sometimes".  Robustness here: many IK seeds give
several goal configurations (all roots of the goal tree), goal biasing, and
up to ``attempts`` restarts with fresh random streams; every path is
shortcut-smoothed, then time-parameterised (rest-to-rest trapezoids per
segment under the joint speed and acceleration limits) and re-checked at
every output sample (joint limits, speeds, clearance to the scene, self
clearance).

Collision model: the robot's URDF primitives covered by spheres
(:mod:`planners.switching.collision`) against the scene points (base frame)
plus a known patch of the standing surface under the robot (the camera does
not see it).  The anchored foot is not checked against the scene (it stands
on it); the moving foot may touch the surface only inside its own footprint
during lift-off and the final approach ("contact zones").
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from planners.errors import InvalidInputError, MotionPlanningError, UnreachableError
from planners.motion import plan_motion
from planners.motion.lipschitz import lipschitz_minimum
from planners.switching.collision import PointObstacles, SphereCover, self_pairs, sphere_cover
from planners.switching.decide import check_rigid

Progress = Callable[[float, str], None]
_DEBUG = False


@dataclass(frozen=True)
class JumpParams:
    """Tunables of :func:`plan_inchworm_jump` (all chosen; the seed gives none)."""

    lift_m: float = 0.04  # straight lift-off along the foot normal
    standoff_m: float = 0.04  # hover height above the target before landing
    cartesian_steps: int = 6  # waypoints of each straight lift/approach
    clearance_margin_m: float = 0.01  # required scene clearance (sphere cover)
    self_margin_m: float = 0.0  # required self clearance (sphere cover)
    contact_band_m: float = 0.03  # points this close to a contact plane …
    contact_pad_m: float = 0.04  # … and within the footprint + pad are exempt
    resolution_rad: float = 0.02  # edge collision-check step (≤ 1.2 cm at 0.6 m)
    step_rad: float = 0.3  # RRT-Connect range (largest extension)
    max_iterations: int = 1500  # per RRT-Connect attempt
    attempts: int = 4  # RRT-Connect restarts
    ik_seeds: int = 48
    ik_retries: int = 3  # fresh seed batches when a target has no usable IK solution
    max_goals: int = 6  # IK solutions used as goal-tree roots
    shortcut_iterations: int = 100  # OMPL vertex-reduction steps
    accel_rad_s2: float = 2.0
    dt_s: float = 0.02
    speed_scale: float = 0.9  # plan at 90 % of the joint speed limits
    standing_patch_m: tuple[tuple[float, float], tuple[float, float]] = ((-0.75, 0.13), (-0.2, 0.2))
    patch_spacing_m: float = 0.01
    second_foot_distances_m: tuple[float, ...] = (0.5, 0.42, 0.34, 0.26, 0.22)
    max_second_foot_candidates: int = 12  # landing spots tried for foot 2
    second_foot_angles_deg: tuple[float, ...] = tuple(float(a) for a in range(0, 360, 30))
    use_conv: bool = True  # go through P_conv first (seed); False: plan from lift-off
    try_flipped: bool = True  # also try each foothold turned 180° about its normal
    # Also try each foothold slid inwards (towards the plane centroid, −x of
    # Alg. 2's pose) by these distances when it stays on the seen surface: a
    # rectangle anchored on an edge where the plane meets another surface
    # (a wall on a floor) puts the foot against that surface.
    inward_shifts_m: tuple[float, ...] = (0.0, 0.03, 0.06)
    # Seed foot 2's landing IK with the mobile configuration too: a foot 2
    # landing exactly one foot spacing ahead of foot 1 is the straight arm,
    # a singular pose that damped least squares from random seeds does not
    # converge to (inspection jumps, which land in the mobile configuration).
    mobile_ik_seed: bool = False
    seed: int = 0


@dataclass
class JumpRobot:
    """What the planner needs from a robot (``from_model`` reads a RobotModel).

    ``fk_all(Q (B,n)) → (B,L,4,4)`` link frames in the chain base (L links,
    first the base foot, last the free foot's sole); ``ik(T, q0, seed) →
    (K,n)`` distinct solutions; ``ik_track(T (B,4,4) path, q0) → (B,n) | None``
    follows a Cartesian path from q0.
    """

    fk_all: Callable[[np.ndarray], np.ndarray]
    ik: Callable[..., np.ndarray]
    ik_track: Callable[[np.ndarray, np.ndarray], np.ndarray | None]
    joint_limits: np.ndarray
    max_speed: np.ndarray
    link_names: list[str]
    cover: SphereCover  # fine cover: scene clearance
    self_cover: SphereCover  # coarse cover: self clearance (cheaper pairs)
    foot: tuple[float, float]
    q_mobile: np.ndarray
    q_conv: np.ndarray
    base_foot_links: tuple[int, ...]  # links that move with foot 2 (chain base)
    end_foot_links: tuple[int, ...]  # links that move with foot 1 (chain end)
    # ``ik_track_batch(T (B,4,4) path, Q0 (K,n)) → [ (B,n) | None ] * K``: the
    # same tracks as ``ik_track`` row by row, all rows iterated at once.
    ik_track_batch: Callable[[np.ndarray, np.ndarray], list[np.ndarray | None]] | None = None

    @staticmethod
    def from_model(model: Any, *, ik_seeds: int = 48, cell_m: float = 0.025) -> JumpRobot:
        """Adapter for :class:`robots.ara.AraModel` (or any model with
        ``fk_all``, ``ik_solutions``, ``ik_batch``, ``collision_shapes``,
        ``link_names``, ``joint_limits``, ``max_speed``, ``q_mobile``,
        ``q_conv`` and ``params['foot']``)."""
        names = list(model.link_names)

        def ik(T: np.ndarray, q0: np.ndarray | None = None, seed: int = 0) -> np.ndarray:
            return model.ik_solutions(T, q0=q0, n_seeds=ik_seeds, seed=seed)

        def ik_track(Ts: np.ndarray, q0: np.ndarray) -> np.ndarray | None:
            # Follow a Cartesian path, each waypoint seeded by the last.  Near
            # the flat (mobile) pose a straight lift is nearly singular (only a
            # sideways fold of joints 3/4 can absorb the arc of joints 2/5), so
            # intermediate waypoints are accepted within 2 mm / 0.02 rad.
            out, q = [], np.asarray(q0, float)
            for T in Ts:
                sol, _ = model.ik_batch(T, q[None], max_iter=100)
                E = model.fk(sol[0])
                pos = float(np.linalg.norm(E[:3, 3] - T[:3, 3]))
                rot = float(np.arccos(np.clip((np.trace(E[:3, :3].T @ T[:3, :3]) - 1) / 2, -1, 1)))
                if pos > 2e-3 or rot > 0.02 or np.max(np.abs(sol[0] - q)) > 0.5:
                    return None
                q = sol[0]
                out.append(q)
            return np.array(out)

        def ik_track_batch(Ts: np.ndarray, Q0: np.ndarray) -> list[np.ndarray | None]:
            # ik_track for every row of Q0 at once (DLS rows are independent);
            # the same acceptance test, the end pose by batched FK.
            Q0 = np.atleast_2d(np.asarray(Q0, float))
            alive = np.ones(len(Q0), dtype=bool)
            q = Q0.copy()
            steps = np.empty((len(Ts), *Q0.shape))
            for k, T in enumerate(Ts):
                idx = np.nonzero(alive)[0]
                if len(idx) == 0:
                    break
                sol, _ = model.ik_batch(T, q[idx], max_iter=100)
                E = model.fk_all(sol)[:, -1]
                pos = np.linalg.norm(E[:, :3, 3] - T[:3, 3], axis=1)
                tr = np.einsum("bij,ij->b", E[:, :3, :3], T[:3, :3])
                rot = np.arccos(np.clip((tr - 1) / 2, -1, 1))
                jump = np.max(np.abs(sol - q[idx]), axis=1)
                ok = (pos <= 2e-3) & (rot <= 0.02) & (jump <= 0.5)
                alive[idx[~ok]] = False
                q[idx[ok]] = sol[ok]
                steps[k, idx[ok]] = sol[ok]
            return [steps[:, r].copy() if alive[r] else None for r in range(len(Q0))]

        foot = model.params["foot"]
        return JumpRobot(
            fk_all=model.fk_all,
            ik=ik,
            ik_track=ik_track,
            joint_limits=np.asarray(model.joint_limits, float),
            max_speed=np.asarray(model.max_speed, float),
            link_names=names,
            cover=sphere_cover(model.collision_shapes, names, cell_m),
            self_cover=sphere_cover(model.collision_shapes, names, 0.04),
            foot=(float(foot["length_m"]), float(foot["width_m"])),
            q_mobile=np.asarray(model.q_mobile, float),
            q_conv=np.asarray(model.q_conv, float),
            base_foot_links=(0,),
            end_foot_links=(len(names) - 2, len(names) - 1),
            ik_track_batch=ik_track_batch,
        )


@dataclass
class JumpPhase:
    """One phase of the jump: samples ``[start, stop)`` of the trajectory."""

    name: str
    description: str
    anchor: str  # "foot2" | "foot1"
    magnets: dict[str, str]  # {"foot1": state, "foot2": state} during the phase
    start: int
    stop: int
    t_start_s: float
    t_end_s: float


@dataclass
class JumpPlan:
    """Timed joint trajectory of an inch-worm jump, with magnet commands."""

    times: np.ndarray  # (T,)
    joint_trajectory: np.ndarray  # (T, n)
    anchor: np.ndarray  # (T,) 0 = foot 2 anchored, 1 = foot 1 anchored
    clearance: np.ndarray  # (T,) scene clearance of the moving parts (m)
    self_clearance: np.ndarray  # (T,)
    phases: list[JumpPhase]
    magnet_commands: list[dict[str, Any]]  # {"t_s", "foot", "state"}
    foot1_target: np.ndarray  # 4×4 base frame (as reached by IK)
    foot1_requested: np.ndarray  # the foothold option that was used
    foot2_target: np.ndarray  # 4×4 base frame
    foot2_target_inside: bool  # second footprint inside the seen surface
    waypoints: list[np.ndarray]  # smoothed joint waypoints per planned phase
    attempts_used: int
    planning_time_s: float
    timings_s: dict[str, float] = field(default_factory=dict)

    def link_frames(self, robot: JumpRobot, stride: int = 1) -> np.ndarray:
        """World (base-frame) link frames along the trajectory (T', L, 4, 4)."""
        Q = self.joint_trajectory[::stride]
        F = robot.fk_all(Q)
        a = self.anchor[::stride].astype(bool)
        out = F.copy()
        if a.any():
            # Foot 1 anchored at its target: world = W1 · F_end⁻¹ · F.
            rel = np.linalg.inv(F[a, -1])
            out[a] = np.einsum("ij,bjk,blkm->blim", self.foot1_target, rel, F[a])
        return out

    def metrics(self, robot: JumpRobot) -> dict[str, float]:
        dq = np.diff(self.joint_trajectory, axis=0)
        dt = np.diff(self.times)[:, None]
        speed = np.abs(dq) / np.maximum(dt, 1e-12) if len(dq) else np.zeros((1, 1))
        lo, hi = robot.joint_limits[:, 0], robot.joint_limits[:, 1]
        return {
            "duration_s": float(self.times[-1]) if len(self.times) else 0.0,
            "min_clearance_m": float(self.clearance.min()),
            "min_self_clearance_m": float(self.self_clearance.min()),
            "max_speed_ratio": float((speed / robot.max_speed).max()),
            "max_limit_violation_rad": float(
                np.maximum(
                    0, np.maximum(lo - self.joint_trajectory, self.joint_trajectory - hi)
                ).max()
            ),
            "planning_time_s": self.planning_time_s,
            "attempts_used": float(self.attempts_used),
            "samples": float(len(self.times)),
        }


# --------------------------------------------------------------------------- helpers


def _translate(T: np.ndarray, offset: np.ndarray) -> np.ndarray:
    out = T.copy()
    out[:3, 3] = T[:3, 3] + offset
    return out


def _foothold_options(
    footholds: list[np.ndarray],
    foot: tuple[float, float],
    surface: tuple[np.ndarray, np.ndarray, np.ndarray, BaseGeometry] | None,
    tolerance: float,
    params: JumpParams,
) -> list[np.ndarray]:
    """Foothold poses to try, in order: each given pose, slid inwards by
    ``inward_shifts_m`` (kept only when the footprint stays inside the seen
    surface, if one is given), each also flipped 180° about its normal."""
    out = []
    for W in footholds:
        for shift in params.inward_shifts_m:
            T = _translate(W, -W[:3, 0] * shift)
            if shift > 0 and surface is not None:
                origin, ex, ey, hull = surface
                c = _footprint(T, foot) - origin
                if not hull.buffer(tolerance).covers(
                    shapely.Polygon(np.column_stack([c @ ex, c @ ey]))
                ):
                    continue
            out.append(T)
            if params.try_flipped:
                out.append(_flip(T))
    return out


def _flip(T: np.ndarray) -> np.ndarray:
    """Pose turned 180° about its own z axis."""
    out = T.copy()
    out[:3, :2] *= -1.0
    return out


def _cartesian_line(T0: np.ndarray, T1: np.ndarray, n: int) -> np.ndarray:
    """Poses from T0 to T1 moving the position only (orientation of T1)."""
    s = np.linspace(0, 1, n + 1)[1:]
    out = np.repeat(T1[None], n, axis=0)
    out[:, :3, 3] = T0[:3, 3] + s[:, None] * (T1[:3, 3] - T0[:3, 3])
    return out


def _footprint(T: np.ndarray, foot: tuple[float, float], pad: float = 0.0) -> np.ndarray:
    """Footprint corners (4, 3) of a foot at sole pose T."""
    hl, hw = foot[0] / 2 + pad, foot[1] / 2 + pad
    local = np.array([[hl, hw, 0], [-hl, hw, 0], [-hl, -hw, 0], [hl, -hw, 0]])
    return local @ T[:3, :3].T + T[:3, 3]


def _contact_zone(
    points: np.ndarray, T: np.ndarray, foot: tuple[float, float], band: float, pad: float
) -> np.ndarray:
    """Mask of points near the sole plane of a foot at T, inside footprint + pad."""
    rel = (points - T[:3, 3]) @ T[:3, :3]
    return (
        (np.abs(rel[:, 2]) <= band)
        & (np.abs(rel[:, 0]) <= foot[0] / 2 + pad)
        & (np.abs(rel[:, 1]) <= foot[1] / 2 + pad)
    )


def _self_pairs(rob: JumpRobot) -> list[tuple[int, int, bool, np.ndarray, np.ndarray]]:
    """Self-clearance blocks (link a, link b, fine?, sphere i, sphere j): fine
    spheres for links two apart in the chain (they sit centimetres from each
    other), the coarse cover for links further apart."""
    n = len(rob.link_names)
    blocks = []
    for a in range(n):
        for b in range(a + 2, n):
            fine = b == a + 2
            i, j = self_pairs(rob.cover if fine else rob.self_cover, [(a, b)])
            if len(i):
                blocks.append((a, b, fine, i, j))
    return blocks


_CAP = 0.1  # clearances above this are only known to be ≥ it (culling bound)
_EPS = 1e-9  # validity culls just above the margin (rounding of the bounds)
_CHUNK = 128  # configurations per batch in :meth:`_Checker.clearances`


@dataclass(frozen=True)
class _Culling:
    """What culls a robot's clearance checks, the same for every checker of
    one plan (built once in :func:`_jump_context`): the self-pair blocks and
    the scene's sphere groups — per group its link, bounding centre (link
    frame) and radius, the group of every sphere, and one sphere of each
    group (``first``)."""

    self_arrays: _SelfArrays
    scene: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
    first: np.ndarray

    @staticmethod
    def build(
        robot: JumpRobot, pairs: list[tuple[int, int, bool, np.ndarray, np.ndarray]]
    ) -> _Culling:
        cov = robot.cover
        groups = [
            g
            for k in np.unique(cov.link)
            for g in _sphere_groups(cov, np.flatnonzero(cov.link == k))
        ]
        s_group = np.empty(len(cov.link), dtype=int)
        for gi, g in enumerate(groups):
            s_group[g[0]] = gi
        first = np.array([g[0][0] for g in groups], dtype=int)
        scene = (
            cov.link[first],
            np.array([g[1] for g in groups]).reshape(-1, 3),
            np.array([g[2] for g in groups], dtype=float),
            s_group,
        )
        return _Culling(_SelfArrays.build(robot, pairs), scene, first)


def _points_in(F: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Points ``c`` (G,3), each in its own frame ``F`` (B,G,4,4) → (B,G,3).
    Written out per column: ~4× faster than the einsum at these sizes."""
    return (
        F[..., :3, 0] * c[:, 0, None]
        + F[..., :3, 1] * c[:, 1, None]
        + F[..., :3, 2] * c[:, 2, None]
        + F[..., :3, 3]
    )


class _Checker:
    """Batched validity of configurations for one phase (anchor + obstacles)."""

    def __init__(
        self,
        robot: JumpRobot,
        anchor: int,
        anchor_pose: np.ndarray,
        obstacles: PointObstacles,
        contact: PointObstacles | None,
        pairs: list[tuple[int, int, bool, np.ndarray, np.ndarray]],
        params: JumpParams,
        culling: _Culling | None = None,
    ) -> None:
        self.robot, self.anchor, self.W = robot, anchor, anchor_pose
        self.obstacles, self.contact, self.pairs, self.params = obstacles, contact, pairs, params
        cov = robot.cover
        anchored = robot.base_foot_links if anchor == 0 else robot.end_foot_links
        moving_foot = robot.end_foot_links if anchor == 0 else robot.base_foot_links
        self.check = ~np.isin(cov.link, anchored)
        self.foot = np.isin(cov.link, moving_foot) & self.check
        self.rest = self.check & ~self.foot
        c = culling if culling is not None else _Culling.build(robot, pairs)
        self._W_is_identity = bool(np.array_equal(anchor_pose, np.eye(4)))
        self.self_arrays, self.scene_groups, self._group_first = c.self_arrays, c.scene, c.first

    def world(self, Q: np.ndarray) -> np.ndarray:
        F = self.robot.fk_all(np.atleast_2d(Q))
        if self.anchor == 0:
            return F if self._W_is_identity else self.W @ F
        rel = np.linalg.inv(F[:, -1])
        return (self.W @ rel)[:, None] @ F

    def _scene(
        self,
        F: np.ndarray,
        C: np.ndarray,
        subset: np.ndarray,
        obs: PointObstacles,
        cap: float = _CAP,
    ) -> np.ndarray:
        """Min scene clearance over the spheres in ``subset`` (whole links),
        capped at ``cap``; sphere groups (:func:`_sphere_groups`) whose
        bounding sphere is ≥ ``cap`` away are not queried sphere by sphere
        (their spheres are at least as far)."""
        cov = self.robot.cover
        if not subset.any():
            return np.full(len(C), np.inf)
        g_link, g_centre, g_radius, s_group = self.scene_groups
        gs = np.flatnonzero(subset[self._group_first])  # groups lie within one link
        gc = _points_in(F[:, g_link[gs]], g_centre[gs])
        need_group = np.zeros((len(C), len(g_link)), dtype=bool)
        # A group's spheres can be within cap only if its bounding sphere is.
        need_group[:, gs] = obs.maybe_within(gc, cap + g_radius[gs])
        need = need_group[:, s_group] & subset[None, :]
        out = np.full(C.shape[:2], cap)
        if need.any():
            b_idx, s_idx = np.nonzero(need)
            out[b_idx, s_idx] = obs.clearance(C[b_idx, s_idx], cov.radius[s_idx], upper=cap)
        return np.where(subset[None, :], out, np.inf).min(axis=1)

    def _scene_all(self, F: np.ndarray, C: np.ndarray) -> np.ndarray:
        """Scene clearance of every checked sphere: the moving foot against
        the contact-zone points when there is a zone, all against the scene
        (one query when there is none: the same set)."""
        if self.contact is None:
            return self._scene(F, C, self.check, self.obstacles)
        scene = self._scene(F, C, self.rest, self.obstacles)
        return np.minimum(scene, self._scene(F, C, self.foot, self.contact))

    def _self(self, F: np.ndarray, C: np.ndarray, cap: float = _CAP) -> np.ndarray:
        """Self clearance per configuration, all link pairs at once.

        The pairs come in blocks: a sphere group of one link against a group
        of the other (:class:`_SelfArrays`).  A block whose group bounding
        spheres are ≥ ``cap`` apart contributes that bound; in the others a
        sphere farther than ``cap`` from the other group's bounding sphere is
        dropped (every pair with it is at least that far: triangle
        inequality), and the block contributes the minimum over its remaining
        sphere pairs (closed form), or ``cap`` when none remain.  So
        min(result, cap) equals min(exact, cap)."""
        sp = self.self_arrays
        B = len(F)
        if len(sp.a) == 0:
            return np.full(B, np.inf)
        wg = _points_in(F[:, sp.g_link], sp.g_centre)  # each group's centre once
        ca, cb = wg[:, sp.ga], wg[:, sp.gb]
        bound = np.linalg.norm(ca - cb, axis=2) - sp.rab  # (B, P) link-pair bounds
        close = bound < cap
        val = np.where(close, cap, bound)
        rows = np.nonzero(close.any(axis=1))[0]
        if len(rows) == 0:
            return val.min(axis=1)
        cr = close[rows]
        P = C[rows]
        if sp.any_coarse and cr[:, ~sp.fine].any():
            P = np.concatenate([P, self.robot.self_cover.world(F[rows])], axis=1)
        else:  # coarse spheres unused: placeholders keep the indices valid
            P = np.concatenate([P, np.zeros((len(rows), len(sp.r) - P.shape[1], 3))], axis=1)
        cut = cap + _EPS
        # Only the spheres of blocks close in some row (a handful of 73).
        near = cr.any(axis=0)
        colA = np.flatnonzero(near[sp.sa_block])
        colB = np.flatnonzero(near[sp.sb_block])
        sa, sa_blk, sb, sb_blk = sp.sa[colA], sp.sa_block[colA], sp.sb[colB], sp.sb_block[colB]
        eA = np.linalg.norm(P[:, sa] - cb[rows][:, sa_blk], axis=2) - sp.r[sa] - sp.rb[sa_blk]
        eB = np.linalg.norm(P[:, sb] - ca[rows][:, sb_blk], axis=2) - sp.r[sb] - sp.ra[sb_blk]
        needA = (eA < cut) & cr[:, sa_blk]
        needB = eB < cut
        r_idx, i, j, key = _needed_pairs(needA, needB, (sa, sa_blk), (sb, sb_blk), len(sp.a))
        if len(r_idx):
            Pf = P.reshape(-1, 3)
            n_s = P.shape[1]
            d = (
                np.linalg.norm(Pf[r_idx * n_s + i] - Pf[r_idx * n_s + j], axis=1)
                - sp.r[i]
                - sp.r[j]
            )
            starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
            mins = np.minimum.reduceat(d, starts)
            vr = val[rows].ravel()
            kk = key[starts]
            vr[kk] = np.minimum(vr[kk], mins)
            val[rows] = vr.reshape(len(rows), -1)
        return val.min(axis=1)

    def scene_clearances(self, Q: np.ndarray) -> np.ndarray:
        """:meth:`clearances`' scene part alone."""
        Q = np.atleast_2d(Q)
        if len(Q) > _CHUNK:
            return np.concatenate(
                [self.scene_clearances(Q[k : k + _CHUNK]) for k in range(0, len(Q), _CHUNK)]
            )
        F = self.world(Q)
        return self._scene_all(F, self.robot.cover.world(F))

    def self_clearances(self, Q: np.ndarray) -> np.ndarray:
        """:meth:`clearances`' self part alone."""
        Q = np.atleast_2d(Q)
        if len(Q) > _CHUNK:
            return np.concatenate(
                [self.self_clearances(Q[k : k + _CHUNK]) for k in range(0, len(Q), _CHUNK)]
            )
        F = self.world(Q)
        return self._self(F, self.robot.cover.world(F))

    def steps(self, Q: np.ndarray) -> np.ndarray:
        """How far any sphere centre of either cover moves between consecutive
        configurations (n−1,), measured (chunks of :data:`_CHUNK`)."""
        Q = np.atleast_2d(Q)
        out = np.zeros(max(len(Q) - 1, 0))
        for k in range(0, len(Q) - 1, _CHUNK):
            F = self.world(Q[k : k + _CHUNK + 1])
            for cov in (self.robot.cover, self.robot.self_cover):
                C = cov.world(F)
                moved = np.sqrt(((C[1:] - C[:-1]) ** 2).sum(axis=2)).max(axis=1)
                out[k : k + len(moved)] = np.maximum(out[k : k + len(moved)], moved)
        return out

    def self_steps(self, Q: np.ndarray) -> np.ndarray:
        """A bound on how much the self clearance changes between consecutive
        configurations (n−1,), measured: for every self pair of links (a, b),
        how far any sphere of b (either cover) moves in a's frame.  A pair's
        sphere distance changes by at most that (a's sphere is fixed in a's
        frame), so the minimum over pairs by at most the largest.  Far
        tighter than twice the spheres' motion in the anchor frame: links two
        apart move relative to each other by two joints only."""
        Q = np.atleast_2d(Q)
        out = np.zeros(max(len(Q) - 1, 0))
        links = sorted({(a, b) for a, b, *_ in self.pairs})
        covers = (self.robot.cover, self.robot.self_cover)
        centres = {  # b's spheres of both covers, in b's frame
            b: np.vstack([cov.centre[cov.link == b] for cov in covers]) for _, b in links
        }
        for k in range(0, len(Q) - 1, _CHUNK):
            F = self.robot.fk_all(Q[k : k + _CHUNK + 1])  # chain base: relative poses only
            for a, b in links:
                c = centres[b]
                if not len(c):
                    continue
                # b's frame in a's (rigid inverse of a's frame)
                RaT = np.swapaxes(F[:, a, :3, :3], -1, -2)
                R = RaT @ F[:, b, :3, :3]
                t = (RaT @ (F[:, b, :3, 3] - F[:, a, :3, 3])[..., None])[..., 0]
                C = c @ np.swapaxes(R, -1, -2) + t[:, None]
                moved = np.sqrt(((C[1:] - C[:-1]) ** 2).sum(axis=2)).max(axis=1)
                out[k : k + len(moved)] = np.maximum(out[k : k + len(moved)], moved)
        return out

    def clearances(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(scene clearance, self clearance) per configuration; values above
        0.1 m are lower bounds."""
        Q = np.atleast_2d(Q)
        if len(Q) > _CHUNK:  # bounded temporaries (the re-check passes whole phases)
            parts = [self.clearances(Q[k : k + _CHUNK]) for k in range(0, len(Q), _CHUNK)]
            return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])
        F = self.world(Q)
        C = self.robot.cover.world(F)  # (B, S, 3)
        return self._scene_all(F, C), self._self(F, C)

    def valid(self, Q: np.ndarray) -> np.ndarray:
        """Joint limits, scene clearance ≥ margin and self clearance ≥ margin.

        Decides exactly as thresholding :meth:`clearances`, but culls at the
        margins instead of at 0.1 m (``cap`` just above the margin): a value
        capped there is ≥ the margin iff the exact one is, and a link or link
        pair culled by its bounding sphere is at least the bound away.  So
        the KD-tree searches only ``margin + radius`` around each sphere and
        only for links within the margin."""
        Q = np.atleast_2d(Q)
        lo, hi = self.robot.joint_limits[:, 0], self.robot.joint_limits[:, 1]
        ok = np.all((lo - 1e-9 <= Q) & (hi + 1e-9 >= Q), axis=1)
        if not ok.any():
            return ok
        sm, cm = self.params.self_margin_m, self.params.clearance_margin_m
        F = self.world(Q)
        C = self.robot.cover.world(F)
        ok &= self._self(F, C, cap=sm + _EPS) >= sm
        idx = np.nonzero(ok)[0]
        if len(idx) == 0:
            return ok
        F, C = F[idx], C[idx]
        cap = cm + _EPS
        if self.contact is None:  # one obstacle set: one query for every link
            ok[idx] = self._scene(F, C, self.check, self.obstacles, cap) >= cm
            return ok
        good = self._scene(F, C, self.rest, self.obstacles, cap) >= cm
        if good.any():
            g = np.nonzero(good)[0]
            good[g] = self._scene(F[g], C[g], self.foot, self.contact, cap) >= cm
        ok[idx] = good
        return ok


#: Spheres per group at most in the self-clearance blocks (:func:`_sphere_groups`).
_GROUP = 16


def _sphere_groups(
    cover: SphereCover, idx: np.ndarray
) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """Split the spheres ``idx`` (one link) into groups of at most
    :data:`_GROUP` by halving at the median along the widest extent; per
    group (sphere indices, bounding-sphere centre in the link frame, radius
    enclosing every sphere)."""
    c = cover.centre[idx]
    if len(idx) > _GROUP:
        ax = int(np.argmax(np.ptp(c, axis=0)))
        order = np.argsort(c[:, ax], kind="stable")
        h = len(idx) // 2
        return _sphere_groups(cover, np.sort(idx[order[:h]])) + _sphere_groups(
            cover, np.sort(idx[order[h:]])
        )
    centre = c.mean(axis=0)
    radius = float(np.max(np.linalg.norm(c - centre, axis=1) + cover.radius[idx]))
    return [(idx, centre, radius)]


def _needed_pairs(
    needA: np.ndarray,
    needB: np.ndarray,
    side_a: tuple[np.ndarray, np.ndarray],
    side_b: tuple[np.ndarray, np.ndarray],
    n_blk: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The sphere pairs :meth:`_Checker._self` must evaluate: per row and
    block, every needed sphere of side a with every needed one of side b.
    ``side_a`` = (sphere, block) per column of ``needA``, blocks ascending
    (likewise b).  A block's pairs are the full product of its spheres, so
    this join on (row, block) lists them without a (rows × all sphere
    pairs) mask.  Returns row, sphere i, sphere j and the key
    row·n_blk + block, non-decreasing."""
    (sa, sa_block), (sb, sb_block) = side_a, side_b
    ra, ca = np.nonzero(needA)  # row-major, columns grouped by block: keys ascend
    rb, cb = np.nonzero(needB)
    ka = ra * n_blk + sa_block[ca]
    kb = rb * n_blk + sb_block[cb]
    lo = np.searchsorted(kb, ka, "left")
    cnt = np.searchsorted(kb, ka, "right") - lo
    total = int(cnt.sum())
    if total == 0:
        e = np.zeros(0, dtype=int)
        return e, e, e, e
    rep = np.repeat(np.arange(len(ka)), cnt)
    within = np.arange(total) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    return ra[rep], sa[ca[rep]], sb[cb[lo[rep] + within]], ka[rep]


@dataclass
class _SelfArrays:
    """Self-collision pairs flattened for :meth:`_Checker._self`.  Sphere
    groups (:func:`_sphere_groups`): link ``g_link`` and bounding-sphere
    centre ``g_centre`` in the link frame.  Per block (a group on link ``a``
    against a group on link ``b``, links of one self pair): groups ``ga``,
    ``gb``, their radii ``ra``/``rb`` (sum ``rab``), ``fine``.  Spheres
    index [fine cover, coarse cover] (radii ``r``); ``sa``/``sb`` list each
    block's spheres on link a / b (blocks ``sa_block``/``sb_block``); a
    block's sphere pairs are every sphere of ``sa`` with every one of ``sb``
    (:func:`_needed_pairs` relies on it)."""

    a: np.ndarray
    b: np.ndarray
    g_link: np.ndarray
    g_centre: np.ndarray
    ga: np.ndarray
    gb: np.ndarray
    ra: np.ndarray
    rb: np.ndarray
    rab: np.ndarray
    fine: np.ndarray
    r: np.ndarray
    sa: np.ndarray
    sa_block: np.ndarray
    sb: np.ndarray
    sb_block: np.ndarray
    any_coarse: bool

    @staticmethod
    def build(
        robot: JumpRobot,
        pairs: list[tuple[int, int, bool, np.ndarray, np.ndarray]],
    ) -> _SelfArrays:
        S = len(robot.cover.radius)
        # Per block: link a, link b, fine?, group a, group b, radius a, radius b.
        blocks: list[tuple[int, int, bool, int, int, float, float]] = []
        sa: list[np.ndarray] = []
        sb: list[np.ndarray] = []
        groups: dict[tuple[bool, int, bytes], int] = {}
        g_link: list[int] = []
        g_centre: list[np.ndarray] = []

        def group_id(f: bool, link: int, g: tuple[np.ndarray, np.ndarray, float]) -> int:
            key = (f, link, g[0].tobytes())
            if key not in groups:
                groups[key] = len(g_link)
                g_link.append(link)
                g_centre.append(g[1])
            return groups[key]

        for la, lb_, f, i, j in pairs:
            ua, ub = np.unique(np.asarray(i)), np.unique(np.asarray(j))
            if len(np.asarray(i)) != len(ua) * len(ub):
                raise InvalidInputError(f"self pairs of links {la}, {lb_} are not all sphere pairs")
            cov = robot.cover if f else robot.self_cover
            off = 0 if f else S
            # A block per pair of sphere groups: a group's own bounding sphere
            # culls far more tightly than its link's (a foot is 128 spheres).
            for g1 in _sphere_groups(cov, ua):
                for g2 in _sphere_groups(cov, ub):
                    blocks.append(
                        (la, lb_, f, group_id(f, la, g1), group_id(f, lb_, g2), g1[2], g2[2])
                    )
                    sa.append(g1[0] + off)
                    sb.append(g2[0] + off)
        cols = list(zip(*blocks, strict=True)) if blocks else [()] * 7
        a, b, ga, gb = (np.array(cols[k], dtype=int) for k in (0, 1, 3, 4))
        fine = np.array(cols[2], dtype=bool)
        ra, rb = np.array(cols[5], dtype=float), np.array(cols[6], dtype=float)

        def cat(x: list[np.ndarray]) -> np.ndarray:
            return np.concatenate(x).astype(int) if x else np.zeros(0, int)

        def owners(x: list[np.ndarray]) -> np.ndarray:
            return cat([np.full(len(v), k) for k, v in enumerate(x)])

        r = np.concatenate([robot.cover.radius, robot.self_cover.radius])
        return _SelfArrays(
            a, b, np.array(g_link, dtype=int), np.array(g_centre).reshape(-1, 3), ga, gb,
            ra, rb, ra + rb, fine, r, cat(sa), owners(sa), cat(sb), owners(sb),
            bool((~fine).any()),
        )  # fmt: skip


def _time_parameterise(
    waypoints: np.ndarray, vmax: np.ndarray, amax: float, dt: float
) -> tuple[np.ndarray, np.ndarray]:
    """Rest-to-rest trapezoidal profile on every segment, synchronised across
    joints so no joint exceeds its speed ``vmax`` or ``amax``; sampled at dt."""
    times, qs = [0.0], [waypoints[0]]
    t0 = 0.0
    for a, b in itertools.pairwise(waypoints):
        d = np.abs(b - a)
        if d.max() < 1e-12:
            continue
        # Normalised path s ∈ [0, 1]: joint speed |Δ_i|·ṡ ≤ v_i, accel |Δ_i|·s̈ ≤ a.
        vs = float(np.min(vmax[d > 0] / d[d > 0]))
        acc = float(amax / d.max())
        if vs * vs / acc >= 1.0:  # triangular profile
            ta = np.sqrt(1.0 / acc)
            vs, T = acc * ta, 2 * ta
        else:
            ta = vs / acc
            T = 1.0 / vs + ta
        n = max(1, int(np.ceil(T / dt)))
        t = np.linspace(0, T, n + 1)[1:]
        s = np.where(
            t < ta,
            0.5 * acc * t**2,
            np.where(t > T - ta, 1.0 - 0.5 * acc * (T - t) ** 2, 0.5 * acc * ta**2 + vs * (t - ta)),
        )
        s = np.clip(s, 0.0, 1.0)
        qs.extend(a + s[:, None] * (b - a))
        times.extend(t0 + t)
        t0 += T
    return np.array(times), np.array(qs)


# --------------------------------------------------------------------------- planner


def plan_path(
    start: np.ndarray,
    goals: np.ndarray,
    valid: Callable[[np.ndarray], np.ndarray],
    *,
    lower: np.ndarray,
    upper: np.ndarray,
    rng: np.random.Generator,
    params: JumpParams,
) -> np.ndarray | None:
    """One RRT-Connect attempt (Kuffner & LaValle 2000, the planner the seed
    used through MoveIt/OMPL, §5.2.2) from ``start`` to one of ``goals``
    through OMPL (:func:`planners.motion.plan_motion`): ``valid`` as state
    validity, the straight joint segment checked every ``resolution_rad`` as
    motion validator, range ``step_rad``, ``max_iterations`` iterations, then
    OMPL's simplifier (``shortcut_iterations`` vertex-reduction steps); the
    seed is drawn from ``rng``.  ``None`` when the budget runs out."""
    res = plan_motion(
        start, goals, valid, lower=lower, upper=upper,
        seed=int(rng.integers(2**31 - 1)), resolution=params.resolution_rad,
        range_=params.step_rad,
        # the iteration budget governs, not the clock
        max_time_s=600.0, max_iterations=params.max_iterations,
        simplify_steps=params.shortcut_iterations,
    )  # fmt: skip
    return res.path


def _plan_free(
    checker: _Checker,
    start: np.ndarray,
    goals: np.ndarray,
    params: JumpParams,
    rng: np.random.Generator,
) -> tuple[np.ndarray | None, int]:
    """RRT-Connect with restarts (:func:`plan_path`). Returns (path, attempts)."""
    lo, hi = checker.robot.joint_limits[:, 0], checker.robot.joint_limits[:, 1]
    for attempt in range(1, int(params.attempts) + 1):
        path = plan_path(start, goals, checker.valid, lower=lo, upper=hi, rng=rng, params=params)
        if path is not None:
            return path, attempt
    return None, int(params.attempts)


def _landing_configs(
    robot: JumpRobot,
    target_rel: np.ndarray,
    hover_rel: np.ndarray,
    checker_free: _Checker,
    checker_contact: _Checker,
    params: JumpParams,
    seed: int,
    prefer: Callable[[np.ndarray], np.ndarray] | None = None,
    post: Callable[[np.ndarray], bool] | None = None,
    q0: np.ndarray | None = None,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(hover config, approach path hover→contact) pairs for a target.

    ``target_rel``/``hover_rel`` are the chain-end poses (in the chain base)
    at contact and hovering ``standoff_m`` off the surface.  Contact IK
    solutions are tracked straight back to the hover pose (so the approach is
    a straight line), and kept when every approach sample is valid and the
    hover pose is valid for free motion.  ``q0``: an extra IK seed (the
    solutions come sorted by their distance to it).
    """
    out: list[tuple[np.ndarray, np.ndarray]] = []
    up = _cartesian_line(target_rel, hover_rel, params.cartesian_steps)
    # IK retries: a fresh batch of random seeds while nothing usable is found.
    for retry in range(int(params.ik_retries)):
        sols = robot.ik(target_rel, q0, seed + 1000 * retry)
        if len(sols) == 0:
            continue
        if prefer is not None:
            sols = sols[np.argsort(prefer(sols), kind="stable")]
        # Every solution's track at once (batched DLS); the checks below run
        # in the same order as one track at a time.
        tracks = (
            robot.ik_track_batch(up, sols)
            if robot.ik_track_batch is not None
            else [robot.ik_track(up, q) for q in sols]
        )
        for q, track in zip(sols, tracks, strict=True):
            if track is None:
                continue
            approach = np.vstack([track[::-1], q[None]])  # hover → contact
            if (
                checker_contact.valid(approach).all()
                and checker_free.valid(track[-1:]).all()
                and (post is None or post(q))
            ):
                out.append((track[-1], approach))
            if len(out) >= params.max_goals:
                return out
        if out:
            break
    return out


def _second_foot_candidates(
    foot1: np.ndarray,
    foot: tuple[float, float],
    surface: tuple[np.ndarray, np.ndarray, np.ndarray, BaseGeometry] | None,
    params: JumpParams,
    tolerance: float,
) -> list[tuple[np.ndarray, bool, float]]:
    """Foot-2 landing poses beside foot 1 on its surface, best first.

    Candidates lie in foot 1's sole plane at the given distances/bearings,
    parallel to foot 1.  With a seen ``surface`` (origin, x, y, hull) a
    candidate is "inside" when its footprint is inside the hull grown by
    ``tolerance``; inside candidates come first, longer spacing first (a
    straighter arm), then by inside margin; outside ones by the area they
    leave the seen surface.
    """
    out = []
    x1, y1 = foot1[:3, 0], foot1[:3, 1]
    own = None
    for dist in params.second_foot_distances_m:
        for ang in params.second_foot_angles_deg:
            a = np.radians(ang)
            T = foot1.copy()
            T[:3, 3] = foot1[:3, 3] + dist * (np.cos(a) * x1 + np.sin(a) * y1)
            inside, margin = False, -np.inf
            if surface is not None:
                origin, ex, ey, hull = surface
                c = _footprint(T, foot) - origin
                poly = shapely.Polygon(np.column_stack([c @ ex, c @ ey]))
                if own is None:
                    c1 = _footprint(foot1, foot, 0.02) - origin
                    own = shapely.Polygon(np.column_stack([c1 @ ex, c1 @ ey]))
                if poly.intersects(own):
                    continue
                inside = bool(hull.buffer(tolerance).covers(poly))
                margin = (
                    float(shapely.distance(hull.boundary, poly))
                    if inside
                    else -float(shapely.area(shapely.difference(poly, hull)))
                )
            out.append((T, inside, dist, margin))

    # Inside first (longer spacing = straighter arm, then larger margin);
    # then the least footprint area off the seen surface (a spot just past
    # the edge of the view is likelier steel than one far from it).
    # Outside ones: along foot 1's long axis first (the straight-arm mobile
    # configuration), then by least footprint area off the seen surface.
    def key(c: tuple) -> tuple:
        T, inside, dist, margin = c
        if inside:
            return (0, 0, -dist, -margin)
        axial = abs(float((T[:3, 3] - foot1[:3, 3]) @ x1)) >= 0.99 * dist
        return (1, 0 if axial else 1, -margin, -dist)

    out.sort(key=key)
    return [(T, inside, margin) for T, inside, _, margin in out]


@dataclass
class _JumpContext:
    """What every phase of one jump shares: the adapted robot, its params,
    the scene (points + the standing patch), self-collision pairs, the mobile
    start configuration and the random stream of the whole plan."""

    rob: JumpRobot
    params: JumpParams
    footholds: list[np.ndarray]
    all_pts: np.ndarray
    full: PointObstacles
    pairs: list[tuple[int, int, bool, np.ndarray, np.ndarray]]
    q0: np.ndarray
    foot1_start: np.ndarray
    rng: np.random.Generator
    timings: dict[str, float] = field(default_factory=dict)
    attempts: int = 0
    foot2_start: np.ndarray = field(default_factory=lambda: np.eye(4))
    culling: _Culling | None = None

    def zone(self, T: np.ndarray) -> PointObstacles:
        """Scene points outside the contact zone of a foot at ``T`` (the
        moving foot may touch the surface only inside its own footprint)."""
        p = self.params
        keep = ~_contact_zone(self.all_pts, T, self.rob.foot, p.contact_band_m, p.contact_pad_m)
        return PointObstacles(self.all_pts[keep])

    def checker(self, anchor: int, W_anchor: np.ndarray, zone: PointObstacles | None) -> _Checker:
        """Validity checker with foot ``anchor`` standing at ``W_anchor``."""
        return _Checker(
            self.rob, anchor, W_anchor, self.full, zone, self.pairs, self.params, self.culling
        )

    def plan_free(
        self, checker: _Checker, start: np.ndarray, goals: np.ndarray
    ) -> np.ndarray | None:
        """:func:`_plan_free` on the plan's random stream, counting attempts."""
        path, used = _plan_free(checker, start, goals, self.params, self.rng)
        self.attempts += used
        return path


def _jump_context(
    robot: Any, foothold: np.ndarray, obstacles: np.ndarray, base_height: float, params: JumpParams
) -> _JumpContext:
    """Set-up: adapt the robot, check footholds (rigid 4×4) and obstacle
    points, add the known standing patch under the robot (the camera cannot
    see it) and seed the plan's random stream with ``params.seed``."""
    rob = (
        robot
        if isinstance(robot, JumpRobot)
        else JumpRobot.from_model(robot, ik_seeds=params.ik_seeds)
    )
    fh = np.asarray(foothold, dtype=float)
    fh = fh[None] if fh.ndim == 2 else fh
    if fh.ndim != 3 or len(fh) == 0:
        raise InvalidInputError(
            f"foothold must be a 4×4 pose or (K, 4, 4) poses, got shape {fh.shape}"
        )
    footholds = [check_rigid(T, f"foothold[{k}]") for k, T in enumerate(fh)]
    pts = np.asarray(obstacles, dtype=float).reshape(-1, 3)
    if not np.all(np.isfinite(pts)):
        raise InvalidInputError("obstacles has NaN/inf rows; drop them first")
    rng = np.random.default_rng(params.seed)

    # Known standing surface under the robot (the camera cannot see it).
    (x0, x1), (y0, y1) = params.standing_patch_m
    gx, gy = np.meshgrid(
        np.arange(x0, x1 + 1e-9, params.patch_spacing_m),
        np.arange(y0, y1 + 1e-9, params.patch_spacing_m),
    )
    patch = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, float(base_height))])
    all_pts = np.vstack([pts, patch])
    full = PointObstacles(all_pts)

    pairs = _self_pairs(rob)
    q0 = rob.q_mobile.copy()
    F0 = rob.fk_all(q0[None])[0]
    foot1_start = F0[-1]  # base frame (foot 2 = identity)
    return _JumpContext(
        rob, params, footholds, all_pts, full, pairs, q0, foot1_start, rng,
        culling=_Culling.build(rob, pairs),
    )  # fmt: skip


def _phase_b(cx: _JumpContext, free2: _Checker) -> tuple[list[np.ndarray], np.ndarray]:
    """Phase B (seed §3.2): foot 1 lifts straight off (Cartesian line of
    ``lift_m`` along its normal, tracked by IK), then to P_conv — a straight
    joint move when free, else planned.  Returns the segment's joint
    way-points and the configuration phase C starts from."""
    rob, params = cx.rob, cx.params
    lift1_zone = cx.checker(0, np.eye(4), cx.zone(cx.foot1_start))
    lift_pose = _translate(cx.foot1_start, cx.foot1_start[:3, 2] * params.lift_m)
    lift = rob.ik_track(_cartesian_line(cx.foot1_start, lift_pose, params.cartesian_steps), cx.q0)
    if lift is None or not lift1_zone.valid(lift).all():
        raise MotionPlanningError("foot 1 cannot lift straight off the standing surface")
    start_c = lift[-1]
    seg_b: list[np.ndarray] = [cx.q0[None], lift]
    if params.use_conv and free2.valid(rob.q_conv[None])[0]:
        # P_conv (seed §3.2) first; a straight joint move when free, else planned.
        path_b = cx.plan_free(free2, start_c, rob.q_conv[None])
        if path_b is not None:
            seg_b.append(path_b[1:])
            start_c = rob.q_conv.copy()
    return seg_b, start_c


class _Lift2:
    """Foot 2's straight lift-off once foot 1 stands at FK(q_contact): a
    foot-1 landing from which foot 2 cannot lift is useless."""

    def __init__(self, cx: _JumpContext) -> None:
        self.cx = cx
        self.zone2_start = cx.zone(cx.foot2_start)
        self.world = _cartesian_line(
            cx.foot2_start,
            _translate(cx.foot2_start, cx.foot2_start[:3, 2] * cx.params.lift_m),
            cx.params.cartesian_steps,
        )

    def __call__(self, q_contact: np.ndarray) -> np.ndarray | None:
        rob = self.cx.rob
        W = rob.fk_all(q_contact[None])[0, -1]
        rel = np.einsum("bij,jk->bik", np.linalg.inv(self.world), W)
        track = rob.ik_track(rel, q_contact)
        if track is None:
            return None
        chk = self.cx.checker(1, W, self.zone2_start)
        return track if chk.valid(track).all() else None


def _phase_c(
    cx: _JumpContext,
    free2: _Checker,
    start_c: np.ndarray,
    options: list[np.ndarray],
    lift2_from: _Lift2,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Phase C (seed §3.2): for each foothold option in turn, landing
    configurations (IK hovering ``standoff_m`` above it with a straight
    approach, kept only when foot 2 can lift afterwards), then RRT-Connect
    from ``start_c`` to any of them; the first option with a path wins.
    Returns (joint path, approach to contact, the foothold used)."""
    params, timings = cx.params, cx.timings
    timings["ik_foot1"] = timings["rrt_foot1"] = 0.0
    path_c, W1, goals1, unreachable = None, cx.footholds[0], [], 0
    for W in options:
        t0 = time.perf_counter()
        land1_zone = cx.checker(0, np.eye(4), cx.zone(W))
        hover1 = _translate(W, W[:3, 2] * params.standoff_m)
        goals1 = _landing_configs(
            cx.rob,
            W,
            hover1,
            free2,
            land1_zone,
            params,
            params.seed,
            post=lambda q: lift2_from(q) is not None,
        )
        timings["ik_foot1"] += time.perf_counter() - t0
        if not goals1:
            unreachable += 1
            continue
        t0 = time.perf_counter()
        path_c = cx.plan_free(free2, start_c, np.array([g for g, _ in goals1]))
        timings["rrt_foot1"] += time.perf_counter() - t0
        if path_c is not None:
            W1 = W
            break
    if path_c is None:
        if unreachable == len(options):
            raise UnreachableError(
                f"no collision-free IK solution lands foot 1 on any of {len(cx.footholds)} foothold(s) "
                f"(first at {np.round(cx.footholds[0][:3, 3], 3).tolist()} m in the base frame)"
            )
        raise MotionPlanningError(
            f"RRT-Connect found no collision-free path for foot 1 ({params.attempts} attempts "
            f"per foothold, {len(options)} foothold poses)"
        )
    goal_idx = int(np.argmin([np.abs(path_c[-1] - g).max() for g, _ in goals1]))
    return path_c, goals1[goal_idx][1], W1


def _flatness(S: np.ndarray) -> np.ndarray:
    # Mobile configuration: prefer the arm flat (joints 2, 5 near 0).
    return np.abs(S[:, 1]) + np.abs(S[:, 4])


def _phase_e(
    cx: _JumpContext,
    W1_actual: np.ndarray,
    lift2: np.ndarray,
    surface: tuple[np.ndarray, np.ndarray, np.ndarray, BaseGeometry] | None,
    surface_tolerance_m: float,
) -> tuple[np.ndarray, bool, np.ndarray, np.ndarray]:
    """Phase E (seed §3.2): foot 1 anchored at ``W1_actual``; foot 2 lifts
    off, swings by RRT-Connect and lands beside foot 1 — candidates from
    :func:`_second_foot_candidates`, best first; the first with a landing
    and a path wins.  Returns (foot-2 pose, inside the seen surface, joint
    path, approach to contact)."""
    params = cx.params
    t0 = time.perf_counter()
    free1 = cx.checker(1, W1_actual, None)
    cands = _second_foot_candidates(W1_actual, cx.rob.foot, surface, params, surface_tolerance_m)
    landing2 = None
    for T2, inside, _ in cands[: params.max_second_foot_candidates]:
        land2_zone = cx.checker(1, W1_actual, cx.zone(T2))
        target_rel = np.linalg.inv(T2) @ W1_actual
        # Foot 2 hovers above its spot: in foot 2's frame foot 1 is lower.
        hover_rel = np.linalg.inv(_translate(T2, T2[:3, 2] * params.standoff_m)) @ W1_actual
        goals2 = _landing_configs(
            cx.rob,
            target_rel,
            hover_rel,
            free1,
            land2_zone,
            params,
            params.seed + 1,
            _flatness,
            q0=cx.rob.q_mobile if params.mobile_ik_seed else None,
        )
        if not goals2:
            if _DEBUG:
                print("foot2 cand", np.round(T2[:3, 3], 3), inside, "no landing")
            continue
        tt = time.perf_counter()
        path_e = cx.plan_free(free1, lift2[-1], np.array([g for g, _ in goals2]))
        if _DEBUG:
            print(
                "foot2 cand",
                np.round(T2[:3, 3], 3),
                inside,
                len(goals2),
                path_e is not None,
                time.perf_counter() - tt,
            )
        if path_e is None:
            continue
        gi = int(np.argmin([np.abs(path_e[-1] - g).max() for g, _ in goals2]))
        landing2 = (T2, inside, path_e, goals2[gi][1])
        break
    cx.timings["foot2"] = time.perf_counter() - t0
    if landing2 is None:
        raise MotionPlanningError("no collision-free landing found for foot 2 beside foot 1")
    return landing2


def _assemble(
    segs: list[tuple[str, str, int, np.ndarray]], vmax: np.ndarray, params: JumpParams
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[JumpPhase], list[dict[str, Any]]]:
    """Phases A–F and magnet commands around the planned segments B, C, E,
    each time-parameterised rest to rest (:func:`_time_parameterise`:
    trapezoids under the joint speed and acceleration limits).  Returns
    (times, joint trajectory, anchor per sample, phases, magnet commands)."""
    times_all: list[np.ndarray] = []
    q_all: list[np.ndarray] = []
    anchor_all: list[np.ndarray] = []
    phases: list[JumpPhase] = []
    magnets = [
        {"t_s": 0.0, "foot": "foot2", "state": "touched"},
    ]
    t_off, idx = 0.0, 0
    phases.append(
        JumpPhase(
            "A",
            "magnet 2 touched",
            "foot2",
            {"foot1": "untouched", "foot2": "touched"},
            0,
            0,
            0.0,
            0.0,
        )
    )
    for name, text, anchor, wp in segs:
        if name == "E":
            magnets += [
                {"t_s": t_off, "foot": "foot1", "state": "touched"},
                {"t_s": t_off, "foot": "foot2", "state": "untouched"},
            ]
            phases.append(
                JumpPhase(
                    "D",
                    "magnets swap: 1 touched, 2 untouched",
                    "foot1",
                    {"foot1": "touched", "foot2": "untouched"},
                    idx,
                    idx,
                    t_off,
                    t_off,
                )
            )
        t, q = _time_parameterise(wp, vmax, params.accel_rad_s2, params.dt_s)
        if times_all:
            t, q = t[1:], q[1:]  # the first sample repeats the previous end
        times_all.append(t + t_off)
        q_all.append(q)
        anchor_all.append(np.full(len(t), anchor))
        mags = (
            {"foot1": "untouched", "foot2": "touched"}
            if anchor == 0
            else {"foot1": "touched", "foot2": "untouched"}
        )
        phases.append(
            JumpPhase(
                name,
                text,
                "foot2" if anchor == 0 else "foot1",
                mags,
                idx,
                idx + len(t),
                float(t_off + t[0]),
                float(t_off + t[-1]),
            )
        )
        idx += len(t)
        t_off = float(t_off + t[-1])
    magnets.append({"t_s": t_off, "foot": "foot1", "state": "untouched"})
    phases.append(
        JumpPhase(
            "F",
            "both arrays untouched: mobile configuration",
            "none",
            {"foot1": "untouched", "foot2": "untouched"},
            idx,
            idx,
            t_off,
            t_off,
        )
    )
    return np.concatenate(times_all), np.vstack(q_all), np.concatenate(anchor_all), phases, magnets


def _rows(
    f: Callable[[np.ndarray], np.ndarray], Q: np.ndarray
) -> Callable[[np.ndarray], np.ndarray]:
    """``f`` on the rows of ``Q`` picked by an index array."""
    return lambda idx: f(Q[idx])


def _recheck(
    cx: _JumpContext, Q: np.ndarray, anchor: np.ndarray, W1_actual: np.ndarray, T2: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Clearance along the whole motion, with the contact exemptions used in
    planning: the moving foot may touch the surface only inside its
    footprint, and only while within lift/standoff of that contact.
    Returns (scene clearance, self clearance) per sample.

    Coarse-then-fine (:func:`planners.motion.lipschitz.lipschitz_minimum`):
    within a stretch of one anchor and one contact exemption the scene
    clearance changes between samples by at most how far a sphere moves
    (:meth:`_Checker.steps`), the self clearance by at most the smaller of
    twice that and how far a sphere moves relative to the link it is paired
    with (:meth:`_Checker.self_steps`), so only the samples that can come down to
    max(margin, minimum) are evaluated; the others hold a lower bound above
    it.  The minima and every sample at or below the margins are exact."""
    params = cx.params
    clear = np.empty(len(Q))
    selfc = np.empty(len(Q))
    for a_val, W_anchor, start_pose, land_pose in (
        (0, np.eye(4), cx.foot1_start, W1_actual),
        (1, W1_actual, cx.foot2_start, T2),
    ):
        sel = np.nonzero(anchor == a_val)[0]
        if len(sel) == 0:
            continue
        chk_full = cx.checker(a_val, W_anchor, None)
        checkers = {0: chk_full}
        poses = {1: land_pose, 2: start_pose}
        for run in np.split(sel, np.flatnonzero(np.diff(sel) > 1) + 1):
            Qs = Q[run]
            steps = chk_full.steps(Qs)
            foot_pos = chk_full.world(Qs)[:, -1 if a_val == 0 else 0, :3, 3]
            near_start = (
                np.linalg.norm(foot_pos - start_pose[:3, 3], axis=1) <= params.lift_m + 1e-3
            )
            near_land = (
                np.linalg.norm(foot_pos - land_pose[:3, 3], axis=1) <= params.standoff_m + 1e-3
            )
            zone = np.where(near_start, 2, np.where(near_land, 1, 0))
            selfc[run] = lipschitz_minimum(
                _rows(chk_full.self_clearances, Qs),
                # both bound the change: the links' relative motion is the
                # tighter one except where a link turns far from its partner
                np.minimum(chk_full.self_steps(Qs), 2.0 * steps),
                params.self_margin_m,
            )[0]
            # The exemption changes the obstacles: a stretch per exemption state.
            cuts = np.flatnonzero(np.diff(zone) != 0) + 1
            for part in np.split(np.arange(len(run)), cuts):
                z = int(zone[part[0]])
                if z not in checkers:
                    checkers[z] = cx.checker(a_val, W_anchor, cx.zone(poses[z]))
                chk = checkers[z]
                Qp = Qs[part]
                clear[run[part]] = lipschitz_minimum(
                    _rows(chk.scene_clearances, Qp),
                    steps[part[:-1]],
                    params.clearance_margin_m,
                )[0]
    return clear, selfc


def plan_inchworm_jump(
    robot: Any,
    foothold: np.ndarray,
    *,
    obstacles: np.ndarray,
    base_height: float = 0.0,
    surface: tuple[np.ndarray, np.ndarray, np.ndarray, BaseGeometry] | None = None,
    surface_tolerance_m: float = 0.01,
    params: JumpParams | dict[str, Any] | None = None,
    progress: Progress | None = None,
) -> JumpPlan:
    """Plan the inch-worm jump (seed §3.2) onto ``foothold``.

    ``robot`` a :class:`JumpRobot` or a RobotModel (adapted by
    :meth:`JumpRobot.from_model`); ``foothold`` the 4×4 target sole pose of
    foot 1 in the base frame (z = surface normal towards the robot; Alg. 2's
    pose); ``obstacles`` (N,3) scene points in the base frame; ``surface`` =
    (origin, x_axis, y_axis, hull polygon) of the target plane, used to keep
    the second foot on seen steel.  Raises :class:`UnreachableError` when no
    IK solution lands foot 1, :class:`MotionPlanningError` when no
    collision-free path is found within ``params.attempts``.

    Steps: :func:`_jump_context` (set-up) → :func:`_phase_b` (lift, P_conv)
    → :func:`_phase_c` (foot 1 to the target) → :func:`_phase_e` (foot 2
    beside it) → :func:`_assemble` (phases A–F, time parameterisation) →
    :func:`_recheck` (clearance at every sample).
    """
    t_all = time.perf_counter()
    if params is None:
        params = JumpParams()
    elif isinstance(params, dict):
        params = replace(JumpParams(), **params)
    cx = _jump_context(robot, foothold, obstacles, base_height, params)
    rob = cx.rob

    # ---- phase B/C: anchor foot 2 (chain base, identity pose) --------------
    free2 = cx.checker(0, np.eye(4), None)
    seg_b, start_c = _phase_b(cx, free2)
    if progress:
        progress(0.1, "foot 1")
    # Footholds in the caller's order, each also turned 180° about its
    # normal (the foot rectangle is symmetric): the first one that lands.
    options = _foothold_options(cx.footholds, rob.foot, surface, surface_tolerance_m, params)
    lift2_from = _Lift2(cx)
    path_c, approach1, W1 = _phase_c(cx, free2, start_c, options, lift2_from)
    q_land1 = approach1[-1]
    if progress:
        progress(0.5, "foot 2")

    # ---- phase E: anchor foot 1 at W1; foot 2 swings ------------------------
    W1_actual = rob.fk_all(q_land1[None])[0, -1]
    lift2 = lift2_from(q_land1)
    if lift2 is None:  # pragma: no cover - landings are filtered on this
        raise MotionPlanningError("foot 2 cannot lift straight off the standing surface")
    T2, inside2, path_e, approach2 = _phase_e(cx, W1_actual, lift2, surface, surface_tolerance_m)

    # ---- assemble, time-parameterise, re-check every sample ------------------
    t0 = time.perf_counter()
    vmax = rob.max_speed * params.speed_scale
    segs = [
        ("B", "foot 1 lifts off and moves to P_conv", 0, np.vstack(seg_b)),
        ("C", "foot 1 swings to the target and lands", 0, np.vstack([path_c, approach1])),
        (
            "E",
            "foot 2 lifts off, swings and lands beside foot 1",
            1,
            np.vstack([q_land1[None], lift2, path_e, approach2]),
        ),
    ]
    times, Q, anchor, phases, magnets = _assemble(segs, vmax, params)
    clear, selfc = _recheck(cx, Q, anchor, W1_actual, T2)
    cx.timings["time_parameterise"] = time.perf_counter() - t0
    plan = JumpPlan(
        times=times,
        joint_trajectory=Q,
        anchor=anchor,
        clearance=clear,
        self_clearance=selfc,
        phases=phases,
        magnet_commands=magnets,
        foot1_target=W1_actual,
        foot1_requested=W1,
        foot2_target=T2,
        foot2_target_inside=bool(inside2) if surface is not None else False,
        waypoints=[w for _, _, _, w in segs],
        attempts_used=cx.attempts,
        planning_time_s=time.perf_counter() - t_all,
        timings_s=cx.timings,
    )
    if progress:
        progress(1.0, "done")
    return plan


def jump_clearance(
    robot: Any,
    plan: JumpPlan,
    obstacles: np.ndarray,
    *,
    base_height: float = 0.0,
    params: JumpParams | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(scene clearance, self clearance) per sample of ``plan``'s trajectory
    against other ``obstacles`` (N,3, base frame): the re-check that ends
    :func:`plan_inchworm_jump` (:func:`_recheck`, the same contact
    exemptions), for a planned jump placed in another scene — e.g. one
    inspection jump shared by several joints of the same geometry."""
    if params is None:
        params = JumpParams()
    cx = _jump_context(robot, plan.foot1_target, obstacles, base_height, params)
    return _recheck(cx, plan.joint_trajectory, plan.anchor, plan.foot1_target, plan.foot2_target)


def wrist_distance(foothold: np.ndarray, robot: Any = None) -> float:
    """Distance (m) between the two wrist points of a jump onto ``foothold``
    (4×4, foot 1's sole in the standing base frame): the ARA's joint 2 sits
    ``j1_above_sole + j2_above_j1`` (0.1 m) along foot 2's normal, joint 5
    ``j6_below_j5 + sole_below_j6`` (0.1 m) along foot 1's normal, and
    between them the arm is three straight links (link2 + link3 + link4 =
    0.5 m, ara.urdf), so a foothold farther than that is out of reach for
    every joint value (seed §3.2: the six-DoF arm, joints 2 and 5 pitch).
    ``robot`` (a RobotModel with ``params['arm']``) overrides the ARA
    numbers."""
    a = (robot.params["arm"] if robot is not None and hasattr(robot, "params") else None) or {}
    up2 = float(a.get("j1_above_sole_m", 0.05)) + float(a.get("j2_above_j1_m", 0.05))
    up5 = float(a.get("j6_below_j5_m", 0.05)) + float(a.get("sole_below_j6_m", 0.05))
    W = np.asarray(foothold, float)
    j5 = W[:3, 3] + up5 * W[:3, 2]
    return float(np.linalg.norm(j5 - np.array([0.0, 0.0, up2])))


def arm_length(robot: Any = None) -> float:
    """link2 + link3 + link4 (m): the most the wrist points of
    :func:`wrist_distance` can be apart (0.5 m for the ARA)."""
    a = (robot.params["arm"] if robot is not None and hasattr(robot, "params") else None) or {}
    return (
        float(a.get("link2_m", 0.15)) + float(a.get("link3_m", 0.2)) + float(a.get("link4_m", 0.15))
    )


def landing_configurations(
    robot: Any,
    foothold: np.ndarray,
    *,
    obstacles: np.ndarray,
    base_height: float = 0.0,
    params: JumpParams | None = None,
    limit: int | None = None,
) -> np.ndarray:
    """Foot-1 landing configurations of a jump onto ``foothold`` (4×4, base
    frame) that phase C (seed §3.2: foot 1 to the target) would accept,
    without planning the swing: IK solutions whose straight approach from
    ``standoff_m`` off the face is clear of the scene (contact zone exempt),
    whose hover pose is clear, and from which foot 2 can lift straight off
    (:class:`_Lift2`).  (K, n), K ≤ ``limit`` (default ``params.max_goals``);
    empty when the foothold cannot be landed on — the cheap reachability
    test of a candidate placement (no RRT)."""
    p = params or JumpParams()
    if limit is not None:
        p = replace(p, max_goals=int(limit))
    cx = _jump_context(robot, foothold, obstacles, base_height, p)
    W = cx.footholds[0]
    free2 = cx.checker(0, np.eye(4), None)
    zone = cx.checker(0, np.eye(4), cx.zone(W))
    lift2 = _Lift2(cx)
    goals = _landing_configs(
        cx.rob,
        W,
        _translate(W, W[:3, 2] * p.standoff_m),
        free2,
        zone,
        p,
        p.seed,
        post=lambda q: lift2(q) is not None,
    )
    n = len(cx.rob.joint_limits)
    return np.array([a[-1] for _, a in goals]) if goals else np.zeros((0, n))
