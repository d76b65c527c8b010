"""The ara robot description: model, kinematics and ``load()``
(see :mod:`robots.ara` for the robot)."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from robots.model import RobotModel, read_params
from robots.urdf_model import (
    CollisionPrimitive,
    UrdfChain,
    collision_primitives,
    joint_origin,
    urdf_description,
    urdf_kinematics,
)

HERE = Path(__file__).resolve().parent
URDF_PATH = HERE / "ara.urdf"
PARAMS_PATH = HERE / "params.toml"


def _axis_rotation(axis: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Batched Rodrigues rotation (B,) angles about a unit axis → (B,4,4)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    s, c = np.sin(theta)[:, None, None], np.cos(theta)[:, None, None]
    out = np.zeros((len(theta), 4, 4))
    out[:, :3, :3] = np.eye(3) + s * k + (1.0 - c) * (k @ k)
    out[:, 3, 3] = 1.0
    return out


#: One URDF collision primitive (``link``, ``kind``, ``size``, ``origin``).
CollisionShape = CollisionPrimitive


@dataclass
class AraModel(RobotModel):
    """URDF serial chain base_link → foot1_sole with batched FK and DLS IK."""

    link_names: list[str] = field(default_factory=list)
    joint_origins: np.ndarray = field(default_factory=lambda: np.zeros((0, 4, 4)))
    joint_axes: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    end_offset: np.ndarray = field(default_factory=lambda: np.eye(4))
    collision_shapes: list[CollisionShape] = field(default_factory=list)
    camera_to_base: np.ndarray = field(default_factory=lambda: np.eye(4))
    max_speed: np.ndarray = field(default_factory=lambda: np.zeros(0))
    q_mobile: np.ndarray = field(default_factory=lambda: np.zeros(0))
    q_conv: np.ndarray = field(default_factory=lambda: np.zeros(0))

    # ------------------------------------------------------------------ FK
    def fk_all(self, q: np.ndarray) -> np.ndarray:
        """Frames of every chain link in the base frame.

        ``q`` (6,) → (L,4,4), ``q`` (B,6) → (B,L,4,4) for the links in
        :attr:`link_names` order (base_link, link1 … link5, foot1, foot1_sole).
        All joint rotations are built at once (Rodrigues with the axis
        matrices precomputed) and the chain is composed on 3×3 rotations and
        translations; equal to the per-joint 4×4 product within rounding.
        """
        q = np.asarray(q, dtype=float)
        single = q.ndim == 1
        Q = np.atleast_2d(q)
        if Q.shape[1] != self.dof:
            raise ValueError(f"ara: expected {self.dof} joint values, got shape {q.shape}")
        K, K2, O_R, O_t, E = self._fk_consts
        B = len(Q)
        s, c = np.sin(Q)[..., None, None], np.cos(Q)[..., None, None]
        # Joint i's local rotation: O_R[i] · (I + sin K_i + (1 − cos) K_i²).
        A = O_R[None] + s * K[None] + (1.0 - c) * K2[None]  # (B, 6, 3, 3)
        out = np.zeros((B, len(self.link_names), 4, 4))
        out[:, :, 3, 3] = 1.0
        out[:, 0, 0, 0] = out[:, 0, 1, 1] = out[:, 0, 2, 2] = 1.0
        # The base is the identity, so the first joint's frame is its own
        # origin and rotation (I·x is exact: same values as the product).
        p = np.repeat(O_t[0][None], B, axis=0)
        R = A[:, 0]
        out[:, 1, :3, :3] = R
        out[:, 1, :3, 3] = p
        for i in range(1, self.dof):
            p = p + R @ O_t[i]
            R = R @ A[:, i]
            out[:, i + 1, :3, :3] = R
            out[:, i + 1, :3, 3] = p
        out[:, -1, :3, 3] = p + R @ E[:3, 3]
        out[:, -1, :3, :3] = R @ E[:3, :3]
        return out[0] if single else out

    @cached_property
    def _fk_consts(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per joint: O_R·K, O_R·K² (K the axis cross matrix), O_R, O_t; the end offset."""
        ks = []
        for a in self.joint_axes:
            ks.append(np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]]))
        K = np.array(ks)
        O_R = np.asarray(self.joint_origins, float)[:, :3, :3]
        O_t = np.asarray(self.joint_origins, float)[:, :3, 3]
        return O_R @ K, O_R @ K @ K, O_R, O_t.copy(), np.asarray(self.end_offset, float)

    @cached_property
    def urdf_chain(self) -> UrdfChain:
        """pinocchio chain of the URDF: the six joints to ``foot1_sole``."""
        return urdf_kinematics(self.urdf_path).chain(self.joint_names, self.link_names[-1])

    def fk(self, q: np.ndarray, link: str | None = None) -> np.ndarray:
        """Pose of ``link`` (default foot1_sole) in base_link; one
        configuration by pinocchio, a batch by :meth:`fk_all`."""
        q = np.asarray(q, dtype=float)
        if q.ndim == 1 and q.shape[0] == self.dof and link in (None, *self.link_names):
            return self.urdf_chain.fk(q, link)
        frames = self.fk_all(q)
        if link is None:
            return frames[..., -1, :, :]
        if link == "camera_optical":
            return np.broadcast_to(self.camera_to_base, (*frames.shape[:-3], 4, 4)).copy()
        try:
            return frames[..., self.link_names.index(link), :, :]
        except ValueError:
            raise ValueError(
                f"unknown link {link!r} for ara; known: {[*self.link_names, 'camera_optical']}"
            ) from None

    def _joint_frames(self, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World axes (…,6,3) and origins (…,6,3) of the joints."""
        R = frames[..., 1 : self.dof + 1, :3, :3]
        unit = self._unit_axes
        if unit is None:
            axes = np.einsum("...ij,...j->...i", R, self.joint_axes)
        else:
            # A joint axis along ±e_k is column k of its frame, up to sign:
            # exactly what the product gives, without the product.
            col, sign = unit
            axes = np.swapaxes(R, -1, -2)[..., np.arange(self.dof), col, :] * sign[:, None]
        return axes, frames[..., 1 : self.dof + 1, :3, 3]

    @cached_property
    def _unit_axes(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(column, sign) per joint when every axis is ±e_k, else ``None``."""
        A = np.asarray(self.joint_axes, float)
        col = np.argmax(np.abs(A), axis=1)
        sign = A[np.arange(len(A)), col]
        if not np.array_equal(np.abs(sign), np.ones(len(A))) or np.count_nonzero(A) != len(A):
            return None
        return col, sign

    def jacobian(self, q: np.ndarray, link: str | None = None) -> np.ndarray:
        """6×n geometric Jacobian ``[v; ω]`` of ``link`` (default foot1_sole) in
        the base frame; batched for ``q`` (B,6) → (B,6,6).  One configuration
        by pinocchio (joints after ``link`` give zero columns there too)."""
        q = np.asarray(q, dtype=float)
        if q.ndim == 1 and q.shape[0] == self.dof:
            return self.urdf_chain.jacobian(q, link)
        frames = self.fk_all(q)
        k = -1 if link is None else self.link_names.index(link)
        axes, origins = self._joint_frames(frames)
        p_end = frames[..., k, :3, 3]
        J = np.concatenate(
            [_cross(axes, p_end[..., None, :] - origins), axes], axis=-1
        )  # (…,6 joints, 6)
        J = np.swapaxes(J, -1, -2)
        if k != -1:
            # Joints after the link do not move it.
            J[..., :, max(0, k) :] = 0.0
        return J

    # ------------------------------------------------------------------ IK
    def ik_batch(
        self,
        T: np.ndarray,
        seeds: np.ndarray,
        *,
        max_iter: int = 150,
        tol: float = 1e-6,
        damping: float = 1e-2,
        max_step: float = 0.4,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Damped-least-squares IK run from every row of ``seeds`` (B,6) at once.

        Returns ``(q (B,6), converged (B,))``; iterates stay inside the joint
        limits (clipped), steps are capped at ``max_step`` rad so a far seed
        does not jump across the workspace.
        """
        T = np.asarray(T, dtype=float)
        lo, hi = self.joint_limits[:, 0], self.joint_limits[:, 1]
        # Joints with a full turn of range wrap instead of clipping, so an
        # iterate can cross ±180° instead of sticking at the limit.
        wrap = (hi - lo) >= 2 * np.pi - 1e-9

        def project(x: np.ndarray) -> np.ndarray:
            # Wrap only when past a limit, so iterates stay continuous.
            x = np.where(wrap & (x > hi), x - 2 * np.pi, x)
            x = np.where(wrap & (x < lo), x + 2 * np.pi, x)
            return np.clip(x, lo, hi)

        q = project(np.array(seeds, dtype=float, ndmin=2))
        done = np.zeros(len(q), dtype=bool)
        lam2 = damping**2 * np.eye(6)
        for _ in range(max_iter):
            active = ~done
            if not active.any():
                break
            qa = q[active]
            frames = self.fk_all(qa)
            E = frames[:, -1]
            dp = T[:3, 3] - E[:, :3, 3]
            # Orientation error ½ Σ_i r_i × r_d,i (Siciliano eq. 3.85): exact
            # zero at the goal, well behaved away from 180° errors.
            dw = 0.5 * _cross(E[:, :3, :3], T[None, :3, :3], axis=1).sum(axis=2)
            err = np.concatenate([dp, dw], axis=1)
            # ‖·‖ as np.linalg.norm computes it, without its dispatch.
            ok = (np.sqrt(np.add.reduce(dp * dp, axis=1)) < tol) & (
                np.sqrt(np.add.reduce(dw * dw, axis=1)) < tol
            )
            idx = np.nonzero(active)[0]
            done[idx[ok]] = True
            if ok.all():
                break
            axes, origins = self._joint_frames(frames)
            J = np.swapaxes(
                np.concatenate([_cross(axes, E[:, None, :3, 3] - origins), axes], axis=-1),
                -1,
                -2,
            )
            JJt = J @ np.swapaxes(J, -1, -2) + lam2
            step = np.einsum("bji,bj->bi", J, np.linalg.solve(JJt, err[..., None])[..., 0])
            norm = np.linalg.norm(step, axis=1, keepdims=True)
            step *= np.minimum(1.0, max_step / np.maximum(norm, 1e-12))
            step[ok] = 0.0
            q[active] = project(qa + step)
        return q, done

    def ik_solutions(
        self,
        T: np.ndarray,
        *,
        q0: np.ndarray | None = None,
        n_seeds: int = 48,
        seed: int = 0,
        distinct_tol: float = 1e-2,
    ) -> np.ndarray:
        """All distinct IK solutions found from ``n_seeds`` random seeds (plus
        ``q0``), sorted by distance to ``q0`` (or by seed order); (K,6)."""
        lo, hi = self.joint_limits[:, 0], self.joint_limits[:, 1]
        rng = np.random.default_rng(seed)
        seeds = rng.uniform(lo, hi, (n_seeds, self.dof))
        if q0 is not None:
            seeds = np.vstack([np.asarray(q0, dtype=float)[None], seeds])
        q, ok = self.ik_batch(T, seeds)
        sols = q[ok]
        if len(sols) == 0:
            return sols
        if q0 is not None:
            sols = sols[np.argsort(np.linalg.norm(sols - q0, axis=1), kind="stable")]
        keep: list[np.ndarray] = []
        for s in sols:  # tiny list (≤ n_seeds): de-duplicate
            if all(np.max(np.abs(s - k)) > distinct_tol for k in keep):
                keep.append(s)
        return np.array(keep)

    def ik(self, T: np.ndarray, q0: np.ndarray | None = None) -> np.ndarray | None:
        """A joint vector inside the limits reaching ``T`` (the solution
        closest to ``q0`` when given), or ``None``.  48 random seeds (seed 0)
        first; if none converges, 192 more (the basins of some poses are
        small: 1 in ~300 random reachable poses needs them)."""
        T = np.asarray(T, dtype=float)
        sols = self.ik_solutions(T, q0=q0)
        if len(sols) == 0:
            sols = self.ik_solutions(T, q0=q0, n_seeds=192, seed=1)
        return sols[0] if len(sols) else None


_NEXT = np.array([1, 2, 0])
_PREV = np.array([2, 0, 1])


def _cross(a: np.ndarray, b: np.ndarray, axis: int = -1) -> np.ndarray:
    """``np.cross(a, b, axis=axis)`` for 3-vectors along ``axis``, with the
    same products and differences (so the same values) but without
    ``np.cross``'s axis shuffling, which cost more than the arithmetic in
    the IK loop (measured: ~90 µs → ~15 µs per call at 49 × 6 vectors)."""
    if axis == -1 or axis == a.ndim - 1:
        return a[..., _NEXT] * b[..., _PREV] - a[..., _PREV] * b[..., _NEXT]
    if axis == 1:
        return a[:, _NEXT] * b[:, _PREV] - a[:, _PREV] * b[:, _NEXT]
    raise ValueError(f"_cross: axis {axis} not supported")


def _chain_joints(urdf_path: Path, end: str = "foot1_sole") -> tuple[str, list[Any]]:
    """Root link and the joints from it to ``end``, root first."""
    joints = urdf_description(urdf_path).joint_map.values()
    by_child = {j.child: j for j in joints}
    chain: list[Any] = []
    link = end
    while link in by_child:  # walk back from the chain's end link to the base
        j = by_child[link]
        chain.append(j)
        link = j.parent
    return link, chain[::-1]


def load() -> AraModel:
    """Build the ARA model from ``ara.urdf`` and ``params.toml``."""
    params = read_params(PARAMS_PATH)
    root, chain = _chain_joints(URDF_PATH)
    revolute = [j for j in chain if j.type == "revolute"]
    fixed_end = [j for j in chain if j.type == "fixed"]
    names = [str(j.name) for j in revolute]
    limits = np.array([[j.limit.lower, j.limit.upper] for j in revolute], dtype=float)
    axes = np.array([j.axis for j in revolute], dtype=float)
    links = [root, *[str(j.child) for j in chain]]
    speeds = np.radians(np.array(params["joints"]["max_speed_deg_s"], dtype=float))
    return AraModel(
        name="ara",
        urdf_path=URDF_PATH,
        joint_names=names,
        joint_limits=limits,
        params=params,
        link_names=links,
        joint_origins=np.array([joint_origin(URDF_PATH, n) for n in names]),
        joint_axes=axes / np.linalg.norm(axes, axis=1, keepdims=True),
        end_offset=joint_origin(URDF_PATH, fixed_end[0].name) if fixed_end else np.eye(4),
        collision_shapes=collision_primitives(URDF_PATH),
        camera_to_base=joint_origin(URDF_PATH, "camera_joint"),
        max_speed=speeds,
        q_mobile=np.radians(np.array(params["poses"]["mobile_deg"], dtype=float)),
        q_conv=np.radians(np.array(params["poses"]["conv_deg"], dtype=float)),
    )
