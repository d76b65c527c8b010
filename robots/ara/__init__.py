"""ARA bridge-inspection robot: two magnetic wheeled feet and a 6-DoF arm.

Seed 000 §3.2 / Fig. 3.2: in mobile mode both feet drive on differential
wheels with their magnet arrays untouched (≈1 mm gap); in inch-worm mode one
foot's array is touched (stuck to the steel) and the arm swings the other
foot to the next surface.  Joints 2 and 5 rotate about y, joints 1, 3, 4, 6
about z.  The model is read from ``ara.urdf``: ``fk``/``jacobian`` give the
sole frame of foot 1 (``foot1_sole``, the chain's last link) in ``base_link``
(the sole of foot 2), and ``ik`` solves numerically (batched damped least
squares from many seeds: the chain has no closed form because joints 3 and 4
are parallel but the wrist axes do not intersect).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from robots.model import RobotModel, read_params

HERE = Path(__file__).resolve().parent
URDF_PATH = HERE / "ara.urdf"
PARAMS_PATH = HERE / "params.toml"


def _rpy_matrix(rpy: np.ndarray) -> np.ndarray:
    """URDF fixed-axis roll-pitch-yaw: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def _origin(elem: ET.Element | None) -> np.ndarray:
    T = np.eye(4)
    if elem is not None:
        T[:3, 3] = [float(v) for v in elem.get("xyz", "0 0 0").split()]
        T[:3, :3] = _rpy_matrix(np.array([float(v) for v in elem.get("rpy", "0 0 0").split()]))
    return T


def _axis_rotation(axis: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Batched Rodrigues rotation (B,) angles about a unit axis → (B,4,4)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    s, c = np.sin(theta)[:, None, None], np.cos(theta)[:, None, None]
    out = np.zeros((len(theta), 4, 4))
    out[:, :3, :3] = np.eye(3) + s * k + (1.0 - c) * (k @ k)
    out[:, 3, 3] = 1.0
    return out


@dataclass
class CollisionShape:
    """One URDF collision primitive: ``kind`` box|cylinder|sphere, ``size``
    (box: full extents xyz; cylinder: radius, length along local z; sphere:
    radius), ``origin`` 4×4 in its link frame."""

    link: str
    kind: str
    size: tuple[float, ...]
    origin: np.ndarray


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
        """
        q = np.asarray(q, dtype=float)
        single = q.ndim == 1
        Q = np.atleast_2d(q)
        if Q.shape[1] != self.dof:
            raise ValueError(f"ara: expected {self.dof} joint values, got shape {q.shape}")
        B = len(Q)
        out = np.empty((B, len(self.link_names), 4, 4))
        out[:, 0] = np.eye(4)
        for i in range(self.dof):
            out[:, i + 1] = (
                out[:, i] @ self.joint_origins[i] @ _axis_rotation(self.joint_axes[i], Q[:, i])
            )
        out[:, -1] = out[:, -2] @ self.end_offset
        return out[0] if single else out

    def fk(self, q: np.ndarray, link: str | None = None) -> np.ndarray:
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
        axes = np.einsum("...ij,...j->...i", frames[..., 1 : self.dof + 1, :3, :3], self.joint_axes)
        return axes, frames[..., 1 : self.dof + 1, :3, 3]

    def jacobian(self, q: np.ndarray, link: str | None = None) -> np.ndarray:
        """6×n geometric Jacobian ``[v; ω]`` of ``link`` (default foot1_sole) in
        the base frame; batched for ``q`` (B,6) → (B,6,6)."""
        frames = self.fk_all(q)
        k = -1 if link is None else self.link_names.index(link)
        axes, origins = self._joint_frames(frames)
        p_end = frames[..., k, :3, 3]
        J = np.concatenate(
            [np.cross(axes, p_end[..., None, :] - origins), axes], axis=-1
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
            dw = 0.5 * np.cross(E[:, :3, :3], T[None, :3, :3], axis=1).sum(axis=2)
            err = np.concatenate([dp, dw], axis=1)
            ok = (np.linalg.norm(dp, axis=1) < tol) & (np.linalg.norm(dw, axis=1) < tol)
            idx = np.nonzero(active)[0]
            done[idx[ok]] = True
            if ok.all():
                break
            axes, origins = self._joint_frames(frames)
            J = np.swapaxes(
                np.concatenate([np.cross(axes, E[:, None, :3, 3] - origins), axes], axis=-1),
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


def _parse(urdf_path: Path) -> dict[str, Any]:
    root = ET.parse(urdf_path).getroot()
    joints = {j.get("name"): j for j in root.findall("joint")}
    by_child = {j.find("child").get("link"): j for j in joints.values()}  # type: ignore[union-attr]
    # Walk back from the chain's end link to the base.
    chain: list[ET.Element] = []
    link = "foot1_sole"
    while link in by_child:
        j = by_child[link]
        chain.append(j)
        link = j.find("parent").get("link")  # type: ignore[union-attr]
    chain.reverse()
    shapes: list[CollisionShape] = []
    for link_el in root.findall("link"):
        for col in link_el.findall("collision"):
            geo = col.find("geometry")
            assert geo is not None
            prim = next(iter(geo))
            if prim.tag == "box":
                size = tuple(float(v) for v in prim.get("size", "").split())
            elif prim.tag == "cylinder":
                size = (float(prim.get("radius", 0)), float(prim.get("length", 0)))
            elif prim.tag == "sphere":
                size = (float(prim.get("radius", 0)),)
            else:
                raise ValueError(f"ara.urdf: unsupported collision geometry {prim.tag}")
            shapes.append(
                CollisionShape(link_el.get("name", ""), prim.tag, size, _origin(col.find("origin")))
            )
    return {"root": link, "chain": chain, "joints": joints, "shapes": shapes}


def load() -> AraModel:
    """Build the ARA model from ``ara.urdf`` and ``params.toml``."""
    params = read_params(PARAMS_PATH)
    parsed = _parse(URDF_PATH)
    revolute = [j for j in parsed["chain"] if j.get("type") == "revolute"]
    fixed_end = [j for j in parsed["chain"] if j.get("type") == "fixed"]
    names = [j.get("name", "") for j in revolute]
    limits = np.array(
        [
            [float(j.find("limit").get("lower")), float(j.find("limit").get("upper"))]
            for j in revolute
        ]  # type: ignore[union-attr]
    )
    axes = np.array([[float(v) for v in j.find("axis").get("xyz").split()] for j in revolute])  # type: ignore[union-attr]
    links = [parsed["root"]] + [j.find("child").get("link") for j in parsed["chain"]]  # type: ignore[union-attr]
    cam = parsed["joints"]["camera_joint"]
    speeds = np.radians(np.array(params["joints"]["max_speed_deg_s"], dtype=float))
    return AraModel(
        name="ara",
        urdf_path=URDF_PATH,
        joint_names=names,
        joint_limits=limits,
        params=params,
        link_names=links,
        joint_origins=np.array([_origin(j.find("origin")) for j in revolute]),
        joint_axes=axes / np.linalg.norm(axes, axis=1, keepdims=True),
        end_offset=_origin(fixed_end[0].find("origin")) if fixed_end else np.eye(4),
        collision_shapes=parsed["shapes"],
        camera_to_base=_origin(cam.find("origin")),
        max_speed=speeds,
        q_mobile=np.radians(np.array(params["poses"]["mobile_deg"], dtype=float)),
        q_conv=np.radians(np.array(params["poses"]["conv_deg"], dtype=float)),
    )
