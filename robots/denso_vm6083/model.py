"""The denso_vm6083 robot description: model, kinematics and ``load()``
(see :mod:`robots.denso_vm6083` for the robot)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from robots.model import DHRobotModel, read_params

HERE = Path(__file__).resolve().parent
URDF_PATH = HERE / "denso_vm6083.urdf"
PARAMS_PATH = HERE / "params.toml"

JOINT_NAMES = [f"joint{i}" for i in range(1, 7)]
# URDF link names; "flange" is the D-H frame 6 (the default of ``fk``).
URDF_LINKS = ["base_link", "link1", "link2", "link3", "link4", "link5", "link6", "flange"]

# Below this |sin q5| the wrist is singular: only q4 + q6 is determined, so q4
# is kept at the reference value (least change) and q6 takes the rest.
_WRIST_SINGULAR = 1e-9


def _wrap(x: np.ndarray) -> np.ndarray:
    """Angles into [-π, π)."""
    return (x + np.pi) % (2.0 * np.pi) - np.pi


@dataclass
class DensoVM6083(DHRobotModel):
    """D-H model of the VM-6083 with the closed-form IK (seed §3.4.1.1)."""

    def fk(self, q: np.ndarray, link: str | None = None) -> np.ndarray:
        """Pose of a URDF link (default the flange) in the frame ``base`` is in.

        One configuration (``q`` (6,)) is evaluated by pinocchio on the URDF;
        a batch (``q`` (B,6), flange only) by the D-H chain.
        """
        if link is not None and link not in URDF_LINKS:
            raise ValueError(f"unknown link {link!r} for {self.name}; known: {URDF_LINKS}")
        q = np.asarray(q, dtype=float)
        if q.ndim != 1:
            if link not in (None, "flange"):
                raise ValueError("batched fk gives the flange only")
            return self.frames(q)[..., -1, :, :]
        return self.base @ self.urdf_chain.fk(q, link)

    def with_base(self, base: np.ndarray) -> DensoVM6083:
        """A copy whose base frame sits at ``base`` (4×4) in the world."""
        base = np.asarray(base, dtype=float)
        if base.shape != (4, 4) or not np.all(np.isfinite(base)):
            raise ValueError(f"base must be a finite 4×4 transform, got shape {base.shape}")
        return dataclasses.replace(self, base=base.copy())

    # -- closed-form IK -------------------------------------------------------
    def _position_branches(self, pc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Joint angles θ1..θ3 (D-H θ, offsets included) putting the wrist centre at
        ``pc`` (B,3, base frame): (B,4,3) and validity (B,4).  Branch order:
        (front, elbow +), (front, −), (back, +), (back, −)."""
        d1, a1, a2, a3, d4 = self.d[0], self.a[0], self.a[1], self.a[2], self.d[3]
        L3 = np.hypot(a3, d4)
        beta = np.arctan2(-d4, a3)  # angle of the elbow→wrist vector in frame 2
        B = pc.shape[0]
        th = np.zeros((B, 4, 3))
        ok = np.zeros((B, 4), dtype=bool)
        t1a = np.arctan2(pc[:, 1], pc[:, 0])
        for k, t1 in enumerate((t1a, t1a + np.pi)):
            c1, s1 = np.cos(t1), np.sin(t1)
            # wrist centre in frame 1 (x1 = (c1,s1,0), y1 = (0,0,-1))
            x = pc[:, 0] * c1 + pc[:, 1] * s1 - a1
            y = -(pc[:, 2] - d1)
            D = (x * x + y * y - a2 * a2 - L3 * L3) / (2.0 * a2 * L3)
            reach = np.abs(D) <= 1.0 + 1e-12
            g0 = np.arccos(np.clip(D, -1.0, 1.0))
            for j, g in enumerate((g0, -g0)):
                t2 = np.arctan2(y, x) - np.arctan2(L3 * np.sin(g), a2 + L3 * np.cos(g))
                t3 = g - beta
                th[:, 2 * k + j] = np.stack([t1, t2, t3], axis=-1)
                ok[:, 2 * k + j] = reach
        return th, ok

    def _r03(self, th: np.ndarray) -> np.ndarray:
        """Rotation of frame 3 for D-H angles θ1..θ3 (...,3) → (...,3,3)."""
        c1, s1 = np.cos(th[..., 0]), np.sin(th[..., 0])
        c23, s23 = np.cos(th[..., 1] + th[..., 2]), np.sin(th[..., 1] + th[..., 2])
        # R01 = Rz(θ1)Rx(-π/2); R12·R23 = Rz(θ2+θ3)·Rx(π/2) (α2 = 0, α3 = π/2)
        R = np.empty((*th.shape[:-1], 3, 3))
        R[..., 0, 0] = c1 * c23
        R[..., 0, 1] = -s1
        R[..., 0, 2] = c1 * s23
        R[..., 1, 0] = s1 * c23
        R[..., 1, 1] = c1
        R[..., 1, 2] = s1 * s23
        R[..., 2, 0] = -s23
        R[..., 2, 1] = 0.0
        R[..., 2, 2] = c23
        return R

    def _to_joints(self, th: np.ndarray, q_ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """D-H angles → joint values nearest ``q_ref`` (2π-equivalents) inside
        the limits; returns (q, inside-limits mask)."""
        lo, hi = self.joint_limits[:, 0], self.joint_limits[:, 1]
        q = th - self.offset
        q = q_ref + _wrap(q - q_ref)
        # The nearest equivalent may sit just outside a limit while the other
        # one (2π away) is inside: try both directions.
        for shift in (2.0 * np.pi, -2.0 * np.pi):
            alt = q + shift
            fix = ((q < lo - 1e-9) | (q > hi + 1e-9)) & (alt >= lo - 1e-9) & (alt <= hi + 1e-9)
            q = np.where(fix, alt, q)
        inside = np.all((q >= lo - 1e-9) & (q <= hi + 1e-9), axis=-1)
        return np.clip(q, lo, hi), inside

    def ik_all(
        self, T: np.ndarray, q_ref: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """All closed-form solutions of flange poses ``T`` ((4,4) or (B,4,4), in
        the frame ``base`` is expressed in): ``q`` (B,8,6) and ``valid`` (B,8)
        (reachable and inside the limits).  J4/J6 are the 2π-equivalents nearest
        ``q_ref`` (default zeros)."""
        T = np.asarray(T, dtype=float)
        single = T.ndim == 2
        T = T.reshape(-1, 4, 4)
        B = T.shape[0]
        Tb = np.linalg.solve(self.base, T) if not np.allclose(self.base, np.eye(4)) else T
        R = Tb[:, :3, :3]
        pc = Tb[:, :3, 3] - self.d[5] * R[:, :, 2]
        th123, ok = self._position_branches(pc)
        R03 = self._r03(th123)  # (B,4,3,3)
        R36 = np.einsum("bkji,bjl->bkil", R03, R)  # R03ᵀ R
        r13, r23, r33 = R36[..., 0, 2], R36[..., 1, 2], R36[..., 2, 2]
        r31, r32 = R36[..., 2, 0], R36[..., 2, 1]
        r11, r21 = R36[..., 0, 0], R36[..., 1, 0]
        s5 = np.hypot(r13, r23)
        if q_ref is None:
            q_ref = np.zeros(6)
        q_ref = np.broadcast_to(np.asarray(q_ref, dtype=float), (B, 6))
        th = np.zeros((B, 8, 6))
        valid = np.zeros((B, 8), dtype=bool)
        for w, sgn in enumerate((1.0, -1.0)):
            t5 = np.arctan2(sgn * s5, r33)
            t4 = np.arctan2(sgn * r23, sgn * r13)
            t6 = np.arctan2(sgn * r32, -sgn * r31)
            # singular wrist: keep q4 at the reference (θ4 = q4, offset 0)
            sing = s5 < _WRIST_SINGULAR
            t4s = q_ref[:, None, 3] + 0.0 * t4
            t6s = np.arctan2(r21, r11) - t4s
            t4 = np.where(sing, t4s, t4)
            t6 = np.where(sing, t6s, t6)
            idx = slice(w * 4, w * 4 + 4)
            th[:, idx, :3] = th123
            th[:, idx, 3] = t4
            th[:, idx, 4] = t5
            th[:, idx, 5] = t6
            valid[:, idx] = ok
        q, inside = self._to_joints(th, q_ref[:, None, :])
        valid &= inside
        if single:
            return q[0], valid[0]
        return q, valid

    def ik_axis(
        self,
        p: np.ndarray,
        z: np.ndarray,
        q_ref: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """IK for an axisymmetric tool: flange at ``p`` (B,3) with flange z axis
        along ``z`` (B,3), roll free.  q6 does not move the flange position or
        its z axis, so it is set to ``q_ref[5]`` (no J6 motion at all).
        Returns ``q`` (B,8,6) and ``valid`` (B,8) as :meth:`ik_all`."""
        p = np.atleast_2d(np.asarray(p, dtype=float))
        z = np.atleast_2d(np.asarray(z, dtype=float))
        z = z / np.linalg.norm(z, axis=1, keepdims=True)
        # Any x ⟂ z completes a pose; the roll is then replaced by q_ref[5].
        helper = np.where(np.abs(z[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        x = np.cross(helper, z)
        x /= np.linalg.norm(x, axis=1, keepdims=True)
        y = np.cross(z, x)
        T = np.zeros((p.shape[0], 4, 4))
        T[:, :3, 0], T[:, :3, 1], T[:, :3, 2], T[:, :3, 3] = x, y, z, p
        T[:, 3, 3] = 1.0
        if q_ref is None:
            q_ref = np.zeros(6)
        q, valid = self.ik_all(T, q_ref)
        q6 = np.broadcast_to(np.asarray(q_ref, dtype=float), (p.shape[0], 6))[:, 5]
        q[..., 5] = q6[:, None]
        return q, valid

    def ik(self, T: np.ndarray, q0: np.ndarray | None = None) -> np.ndarray | None:
        """Closed-form IK of one flange pose: the valid solution with the least
        joint change from ``q0`` (default zeros), or ``None`` when unreachable."""
        T = np.asarray(T, dtype=float)
        if T.shape != (4, 4):
            raise ValueError(f"T must be a 4×4 pose, got shape {T.shape}")
        q_ref = np.zeros(6) if q0 is None else np.asarray(q0, dtype=float)
        q, valid = self.ik_all(T, q_ref)
        if not valid.any():
            return None
        return q[select_least_change(q, valid, q_ref)]


def select_least_change(q: np.ndarray, valid: np.ndarray, q_ref: np.ndarray) -> int:
    """Index of the valid candidate with the smallest largest-joint move
    (ties broken by the Euclidean joint change)."""
    dq = np.abs(q - q_ref)
    score = dq.max(axis=-1) + 1e-3 * np.linalg.norm(dq, axis=-1)
    score = np.where(valid, score, np.inf)
    return int(np.argmin(score))


def load(base: np.ndarray | None = None) -> DensoVM6083:
    """The VM-6083 model from ``params.toml`` and the URDF; ``base`` (4×4)
    places the robot base in the world (default identity)."""
    params = read_params(PARAMS_PATH)
    dh, lim = params["dh"], params["limits"]
    limits = np.deg2rad(np.stack([lim["lower_deg"], lim["upper_deg"]], axis=1))
    return DensoVM6083(
        name="denso_vm6083",
        urdf_path=URDF_PATH,
        joint_names=list(JOINT_NAMES),
        joint_limits=limits,
        params=params,
        d=np.asarray(dh["d"], dtype=float),
        a=np.asarray(dh["a"], dtype=float),
        alpha=np.deg2rad(np.asarray(dh["alpha_deg"], dtype=float)),
        offset=np.deg2rad(np.asarray(dh["theta_offset_deg"], dtype=float)),
        base=np.eye(4) if base is None else np.asarray(base, dtype=float),
        link_names=list(URDF_LINKS[1:]),
    )
