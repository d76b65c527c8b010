"""The cmbot robot description: model, kinematics and ``load()``
(see :mod:`robots.cmbot` for the robot)."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from robots.cmbot.kinematics import climber_ik_batch
from robots.kinematics import pose_error, solve_ik_dls
from robots.model import RobotModel, read_params
from robots.urdf_model import (
    Inertial,
    UrdfChain,
    collision_primitives,
    joint_origin,
    link_inertials,
    urdf_description,
    urdf_kinematics,
)

HERE = Path(__file__).resolve().parent
URDF_PATH = HERE / "cmbot.urdf"
PARAMS_PATH = HERE / "params.toml"

ARM_JOINTS = [f"J{i}" for i in range(6, 13)]
CLIMB_JOINTS = [f"J{i}" for i in range(1, 6)]


def rz(theta: np.ndarray) -> np.ndarray:
    """Batched rotation about z: (…,) → (…,4,4)."""
    theta = np.asarray(theta, dtype=float)
    c, s = np.cos(theta), np.sin(theta)
    T = np.zeros((*theta.shape, 4, 4))
    T[..., 0, 0] = c
    T[..., 0, 1] = -s
    T[..., 1, 0] = s
    T[..., 1, 1] = c
    T[..., 2, 2] = 1.0
    T[..., 3, 3] = 1.0
    return T


@dataclass(frozen=True)
class CollisionBox:
    """A URDF collision primitive as an oriented box in its link frame:
    ``half`` extents along the columns of ``origin[:3, :3]`` (a cylinder of
    radius r and length L becomes half extents (r, r, L/2))."""

    link: str
    half: np.ndarray
    origin: np.ndarray


def read_collision_boxes(path: Path) -> dict[str, list[CollisionBox]]:
    """Collision primitives of every link, as boxes (cylinders by their bounding box)."""
    out: dict[str, list[CollisionBox]] = {}
    for prim in collision_primitives(path):
        if prim.kind == "box":
            half = np.array(prim.size) / 2
        elif prim.kind == "cylinder":
            r, L = prim.size
            half = np.array([r, r, L / 2])
        else:
            continue
        out.setdefault(prim.link, []).append(CollisionBox(prim.link, half, prim.origin))
    return out


def _check_z_axes(path: Path) -> None:
    """The closed forms assume D-H frames: every moving joint turns about z."""
    for j in urdf_description(path).joint_map.values():
        if j.type != "fixed" and not np.allclose(j.axis, [0.0, 0.0, 1.0]):
            raise ValueError(f"cmbot.urdf: joint {j.name} must turn about z (D-H frames)")


@dataclass
class CmbotChain(RobotModel):
    """Serial chain of z-axis revolute joints read from the URDF.

    ``link_frames(q)`` (…,n+2,4,4): the chain base, the n joint (URDF link)
    frames and the end link (numpy, batched); ``fk(q)`` the end link;
    ``jacobian(q)`` its 6×n geometric Jacobian ``[v; ω]`` in the chain base
    frame.  One configuration goes to pinocchio (:mod:`robots.urdf_model`),
    a batch to :meth:`link_frames`.
    """

    joint_origins: np.ndarray = field(default_factory=lambda: np.zeros((0, 4, 4)))
    end_offset: np.ndarray = field(default_factory=lambda: np.eye(4))
    link_names: list[str] = field(default_factory=list)
    max_speed: np.ndarray = field(default_factory=lambda: np.zeros(0))
    link_masses: np.ndarray = field(default_factory=lambda: np.zeros(0))
    link_coms: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def link_frames(self, q: np.ndarray) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        if q.shape[-1] != self.dof:
            raise ValueError(f"{self.name}: expected {self.dof} joint values, got shape {q.shape}")
        out = np.empty((*q.shape[:-1], self.dof + 2, 4, 4))
        out[..., 0, :, :] = np.eye(4)
        for i in range(self.dof):
            out[..., i + 1, :, :] = out[..., i, :, :] @ self.joint_origins[i] @ rz(q[..., i])
        out[..., -1, :, :] = out[..., -2, :, :] @ self.end_offset
        return out

    @cached_property
    def urdf_chain(self) -> UrdfChain:
        """pinocchio chain ``joint_names`` from ``link_names[0]`` to the end link."""
        return urdf_kinematics(self.urdf_path).chain(
            self.joint_names, self.link_names[-1], base=self.link_names[0]
        )

    def fk(self, q: np.ndarray, link: str | None = None) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        if link is not None and link not in self.link_names:
            raise ValueError(f"unknown link {link!r} for {self.name}; known: {self.link_names}")
        if q.ndim == 1:
            if q.shape[0] != self.dof:
                raise ValueError(f"{self.name}: expected {self.dof} joint values, got {q.shape}")
            return self.urdf_chain.fk(q, link)
        frames = self.link_frames(q)
        if link is None:
            return frames[..., -1, :, :]
        try:
            return frames[..., self.link_names.index(link), :, :]
        except ValueError:
            raise ValueError(
                f"unknown link {link!r} for {self.name}; known: {self.link_names}"
            ) from None

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        if q.ndim == 1 and q.shape[0] == self.dof:
            return self.urdf_chain.jacobian(q)
        frames = self.link_frames(q)
        z = frames[..., 1:-1, :3, 2]
        o = frames[..., 1:-1, :3, 3]
        p = frames[..., -1, None, :3, 3]
        J = np.concatenate([np.cross(z, p - o), z], axis=-1)  # (…,n,6)
        return np.swapaxes(J, -1, -2)


@dataclass
class ClimberModel(CmbotChain):
    """J1…J5 from the rear-foot sole (B) to the front-foot sole (P); closed-form IK."""

    l1: float = 0.0
    l2: float = 0.0
    base_mass: tuple[float, np.ndarray] = (0.0, np.zeros(3))
    end_mass: tuple[float, np.ndarray] = (0.0, np.zeros(3))

    def ik(self, T: np.ndarray, q0: np.ndarray | None = None) -> np.ndarray | None:
        """Seed Eq. 8 (corrected): the knee-up solution for a sole pose with φy = 0
        (sole parallel to B's sole), else ``None``."""
        T = np.asarray(T, dtype=float)
        if abs(T[2, 2] - 1.0) > 1e-9:  # only yaw is reachable with φy = 0
            return None
        phi_z = float(np.arctan2(T[1, 0], T[0, 0]))
        q, ok = climber_ik_batch(T[:3, 3], phi_z, self.l1, self.l2, self.joint_limits)
        return q if bool(ok) else None


@dataclass
class CmbotModel(CmbotChain):
    """The 7-DoF arm (default chain, base frame (6)) plus the climbing chain and
    everything the planners need: the mount on link2, speeds, masses."""

    climber: ClimberModel | None = None
    arm_mount: np.ndarray = field(default_factory=lambda: np.eye(4))
    urdf_joint_names: list[str] = field(default_factory=list)
    base_mass: tuple[float, np.ndarray] = (0.0, np.zeros(3))
    collision_boxes: dict[str, list[CollisionBox]] = field(default_factory=dict)

    @property
    def dispatch_joint_limits(self) -> np.ndarray:
        """J1…J12: the climbing chain, then the arm (the order of ``urdf_joint_names``)."""
        assert self.climber is not None
        return np.vstack([self.climber.joint_limits, self.joint_limits])

    def stance_climber_q(self) -> np.ndarray:
        """J1…J5 with both soles down at the work distance (the manipulation stance)."""
        assert self.climber is not None
        c = self.params["climber"]
        q, ok = climber_ik_batch(
            np.array([[c["work_foot_distance_m"], 0.0, 0.0]]),
            0.0,
            c["l1"],
            c["l2"],
            self.climber.joint_limits,
        )
        if not bool(np.all(ok)):
            raise ValueError("the work stance is outside the climbing chain's joint limits")
        return np.asarray(q, dtype=float).reshape(-1)[:5]

    @property
    def total_mass(self) -> float:
        """Robot mass [kg] from the URDF inertials (payload excluded)."""
        assert self.climber is not None
        c = self.climber
        return float(
            self.link_masses.sum()
            + self.base_mass[0]
            + c.link_masses.sum()
            + c.base_mass[0]
            + c.end_mass[0]
        )

    def ik(self, T: np.ndarray, q0: np.ndarray | None = None) -> np.ndarray | None:
        """Damped-least-squares IK of the tool pose (7-DoF: the solution nearest ``q0``)."""
        q = solve_ik_dls(self, np.asarray(T, dtype=float), q0, restarts=24)
        if q is None:
            return None
        err = pose_error(np.asarray(T, dtype=float), self.fk(q))
        return q if np.linalg.norm(err[:3]) < 1e-6 and np.linalg.norm(err[3:]) < 1e-6 else None


def _chain(
    path: Path, inertials: dict[str, Inertial], names: list[str], end_joint: str
) -> dict[str, Any]:
    joints = urdf_description(path).joint_map
    js = [joints[n] for n in names]
    end = joints[end_joint]
    none = Inertial(0.0, np.zeros(3))
    return {
        "joint_names": names,
        "joint_limits": np.array([[j.limit.lower, j.limit.upper] for j in js], dtype=float),
        "joint_origins": np.array([joint_origin(path, n) for n in names]),
        "end_offset": joint_origin(path, end_joint),
        "link_names": [js[0].parent, *[j.child for j in js], end.child],
        "max_speed": np.array([j.limit.velocity for j in js], dtype=float),
        "link_masses": np.array([inertials.get(j.child, none).mass for j in js]),
        "link_coms": np.array([inertials.get(j.child, none).com for j in js]),
    }


def _mass(inertials: dict[str, Inertial], link: str) -> tuple[float, np.ndarray]:
    i = inertials[link]
    return i.mass, i.com


def load() -> CmbotModel:
    """The CMBOT model from ``cmbot.urdf`` and ``params.toml``."""
    params = read_params(PARAMS_PATH)
    _check_z_axes(URDF_PATH)
    masses = link_inertials(URDF_PATH)
    c = params["climber"]
    cl = _chain(URDF_PATH, masses, CLIMB_JOINTS, "foot_front_fixed")
    climber = ClimberModel(
        name="cmbot.climber",
        urdf_path=URDF_PATH,
        params=params,
        l1=c["l1"],
        l2=c["l2"],
        base_mass=_mass(masses, "foot_rear"),
        end_mass=_mass(masses, "foot_front"),
        **cl,
    )
    arm = _chain(URDF_PATH, masses, ARM_JOINTS, "tool_fixed")
    model = CmbotModel(
        name="cmbot",
        urdf_path=URDF_PATH,
        params=params,
        climber=climber,
        arm_mount=joint_origin(URDF_PATH, "arm_mount"),
        urdf_joint_names=[*CLIMB_JOINTS, *ARM_JOINTS],
        base_mass=_mass(masses, "arm_base"),
        collision_boxes=read_collision_boxes(URDF_PATH),
        **arm,
    )
    return model
