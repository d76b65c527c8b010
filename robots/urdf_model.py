"""The one URDF loading path of ``robots/``: description and pinocchio kinematics.

Every robot's URDF (the single source of truth, DESIGN §7) is read here and
nowhere else, once per path (cached):

* :func:`urdf_description` — the parsed description (``yourdfpy.URDF``, the
  same parser the viewer uses): joint origins as 4×4 transforms (URDF
  fixed-axis roll-pitch-yaw, R = Rz(yaw)·Ry(pitch)·Rx(roll), converted by the
  parser), limits, inertials and collision primitives;
* :func:`urdf_kinematics` — a pinocchio model built from the same file
  (``pinocchio.buildModelFromUrdf``) for single-configuration forward
  kinematics (``forwardKinematics`` + ``updateFramePlacement``) and frame
  Jacobians (``computeFrameJacobian`` in ``LOCAL_WORLD_ALIGNED``: the
  geometric Jacobian ``[v; ω]`` of the frame origin, Siciliano et al. §3.1).

Batched forward kinematics over many configurations stays with the robots'
numpy chains (as fast as pinocchio there, and vectorised); this module serves
the single-configuration calls and the damped-least-squares IK loop.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin


@cache
def _description(path: str) -> Any:
    # Imported here, not at the top: yourdfpy loads trimesh (0.9 s), and every
    # ``robots.*`` import runs this package's ``__init__`` — the robot-link
    # service, which imports only the protocol and adapters, would pay it at
    # every start and restart.
    import yourdfpy

    # Primitive geometry only: no meshes to load, no scene graph to build.
    return yourdfpy.URDF.load(
        path,
        build_scene_graph=False,
        load_meshes=False,
        build_collision_scene_graph=False,
        load_collision_meshes=False,
    )


def urdf_description(path: Path | str) -> Any:
    """The parsed URDF at ``path`` (``yourdfpy.URDF``; cached per path)."""
    return _description(str(Path(path).resolve()))


def joint_origin(path: Path | str, joint: str) -> np.ndarray:
    """4×4 origin of ``joint`` in its parent link frame (a copy)."""
    j = urdf_description(path).joint_map[joint]
    return np.eye(4) if j.origin is None else np.array(j.origin, dtype=float)


@dataclass(frozen=True)
class Inertial:
    """Mass [kg] and centre of mass (3,) in the link frame."""

    mass: float
    com: np.ndarray


def link_inertials(path: Path | str) -> dict[str, Inertial]:
    """Inertial of every link that declares one."""
    out: dict[str, Inertial] = {}
    for name, link in urdf_description(path).link_map.items():
        if link.inertial is not None:
            T = np.eye(4) if link.inertial.origin is None else np.asarray(link.inertial.origin)
            out[name] = Inertial(float(link.inertial.mass), np.array(T[:3, 3], dtype=float))
    return out


@dataclass(frozen=True)
class CollisionPrimitive:
    """One URDF collision primitive: ``kind`` box|cylinder|sphere, ``size``
    (box: full extents xyz; cylinder: radius, length along local z; sphere:
    radius), ``origin`` 4×4 in its ``link`` frame."""

    link: str
    kind: str
    size: tuple[float, ...]
    origin: np.ndarray


def collision_primitives(path: Path | str) -> list[CollisionPrimitive]:
    """Collision primitives of every link in file order; meshes are rejected
    (the project's robots are described by primitives only)."""
    out: list[CollisionPrimitive] = []
    for name, link in urdf_description(path).link_map.items():
        for col in link.collisions:
            g = col.geometry
            T = np.eye(4) if col.origin is None else np.array(col.origin, dtype=float)
            if g.box is not None:
                size: tuple[float, ...] = tuple(float(v) for v in g.box.size)
                kind = "box"
            elif g.cylinder is not None:
                size, kind = (float(g.cylinder.radius), float(g.cylinder.length)), "cylinder"
            elif g.sphere is not None:
                size, kind = (float(g.sphere.radius),), "sphere"
            else:
                raise ValueError(f"{Path(path).name}: link {name} has a non-primitive collision")
            out.append(CollisionPrimitive(name, kind, size, T))
    return out


class UrdfKinematics:
    """pinocchio model of one URDF with per-thread data.

    Joint values are given per *actuated joint name*; joints not named stay
    at zero.  Continuous joints (pinocchio ``nq = 2``: cos θ, sin θ) are
    written as (cos θ, sin θ), so callers always pass angles.
    """

    def __init__(self, path: Path | str) -> None:
        self.path = Path(path)
        self.model = pin.buildModelFromUrdf(str(self.path))
        self._local = threading.local()
        self.joint_names: list[str] = list(self.model.names)[1:]

    def __reduce__(self) -> tuple[Any, tuple[str]]:
        # Rebuilt from the path (cached) in another process: the pinocchio
        # model is derived data and the thread-local scratch cannot pickle.
        return (urdf_kinematics, (str(self.path),))

    @property
    def data(self) -> Any:
        # pinocchio Data is scratch space: one per thread so concurrent
        # callers cannot overwrite each other's placements.
        d = getattr(self._local, "data", None)
        if d is None:
            d = self._local.data = self.model.createData()
        return d

    def frame_id(self, link: str) -> int:
        if not self.model.existFrame(link):
            raise ValueError(f"{self.path.name}: unknown link {link!r}")
        return int(self.model.getFrameId(link))

    def chain(self, joints: Sequence[str], tip: str, base: str | None = None) -> UrdfChain:
        """A serial sub-chain: ``joints`` (angles in this order), tip link
        ``tip``, poses expressed in link ``base`` (default the URDF root)."""
        return UrdfChain(self, list(joints), tip, base)


class UrdfChain:
    """FK / Jacobian of one tip link over an ordered subset of joints."""

    def __init__(self, kin: UrdfKinematics, joints: list[str], tip: str, base: str | None) -> None:
        m = kin.model
        self.kin = kin
        self.joints = joints
        for j in joints:
            if not m.existJointName(j):
                raise ValueError(f"{kin.path.name}: unknown joint {j!r}")
        ids = [int(m.getJointId(j)) for j in joints]
        self._iq = np.array([m.joints[i].idx_q for i in ids], dtype=int)
        self._iv = np.array([m.joints[i].idx_v for i in ids], dtype=int)
        self._circle = np.array([m.joints[i].nq == 2 for i in ids], dtype=bool)
        self._any_circle = bool(self._circle.any())
        self._q = pin.neutral(m)
        self.tip = tip
        self.base = base
        self._tip = kin.frame_id(tip)
        self._base = None if base is None else kin.frame_id(base)
        if self._base is not None and m.frames[self._base].parentJoint == 0:
            # A base rigidly attached to the root moves with nothing: fold its
            # fixed placement in once instead of per call.
            self._base_fixed: Any = m.frames[self._base].placement.inverse()
        else:
            self._base_fixed = None
        # Contiguous angle-only joints are written with one slice (fancy
        # indexing costs more than the pinocchio call itself).
        n = len(ids)
        start = int(self._iq[0]) if n else 0
        contiguous = (
            n > 0 and not self._any_circle and np.array_equal(self._iq, start + np.arange(n))
        )
        self._slice = slice(start, start + n) if contiguous else None
        start_v = int(self._iv[0]) if n else 0
        contiguous_v = n > 0 and np.array_equal(self._iv, start_v + np.arange(n))
        self._vslice = slice(start_v, start_v + n) if contiguous_v else self._iv

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        return (UrdfChain, (self.kin, self.joints, self.tip, self.base))

    def _config(self, q: np.ndarray) -> np.ndarray:
        x = self._q.copy()  # per call: chains are shared between threads
        if self._slice is not None:
            x[self._slice] = q
        elif self._any_circle:
            c = self._circle
            x[self._iq[~c]] = q[~c]
            x[self._iq[c]] = np.cos(q[c])
            x[self._iq[c] + 1] = np.sin(q[c])
        else:
            x[self._iq] = q
        return x

    def _check(self, q: np.ndarray) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        if q.shape != (len(self.joints),):
            raise ValueError(
                f"{self.kin.path.name}: expected {len(self.joints)} joint values, got {q.shape}"
            )
        return q

    def _base_placement(self, data: Any) -> Any:
        """Inverse placement of the base (pinocchio SE3) or ``None`` for the root."""
        if self._base is None or self._base_fixed is not None:
            return self._base_fixed
        return pin.updateFramePlacement(self.kin.model, data, self._base).inverse()

    def fk(self, q: np.ndarray, link: str | None = None) -> np.ndarray:
        """4×4 pose of ``link`` (default the tip) in the base link."""
        q = self._check(q)
        m, data = self.kin.model, self.kin.data
        pin.forwardKinematics(m, data, self._config(q))
        fid = self._tip if link is None else self.kin.frame_id(link)
        T = pin.updateFramePlacement(m, data, fid)
        inv = self._base_placement(data)
        return np.array((T if inv is None else inv * T).homogeneous)

    def jacobian(self, q: np.ndarray, link: str | None = None) -> np.ndarray:
        """6×n geometric Jacobian ``[v; ω]`` of ``link``'s origin (default the
        tip) in the base link's axes, one column per chain joint.  The base
        does not move with the chain's joints, so re-expressing is a rotation."""
        q = self._check(q)
        m, data = self.kin.model, self.kin.data
        fid = self._tip if link is None else self.kin.frame_id(link)
        J = pin.computeFrameJacobian(m, data, self._config(q), fid, pin.LOCAL_WORLD_ALIGNED)
        J = J[:, self._vslice]
        inv = self._base_placement(data)
        if inv is None:
            return np.array(J)
        R = inv.rotation
        out = np.empty_like(J)
        out[:3] = R @ J[:3]
        out[3:] = R @ J[3:]
        return out


@cache
def _kinematics(path: str) -> UrdfKinematics:
    return UrdfKinematics(path)


def urdf_kinematics(path: Path | str) -> UrdfKinematics:
    """The pinocchio kinematics of the URDF at ``path`` (cached per path)."""
    return _kinematics(str(Path(path).resolve()))
