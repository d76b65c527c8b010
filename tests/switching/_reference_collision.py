"""Reference copies of the inch-worm jump's validity / IK kernels as of
commit 111f02a (before the batching), kept as the oracle of the
equivalence tests and as the "before" column of
``tests/benchmarks/bench_motion.py`` (which patches them in):

* :func:`clearances_reference`, :func:`valid_reference` — the former
  ``_Checker.clearances`` / ``_Checker.valid``: exact clearances (capped at
  ``_CAP``), self clearance by a Python loop over link pairs;
* :func:`fk_all_reference` — the former ``AraModel.fk_all`` (one Rodrigues
  4×4 per joint and call);
* :func:`landing_configs_reference` — the former ``_landing_configs``, one
  IK track per solution.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from planners.switching.collision import PointObstacles

_CAP = 0.1


def _axis_rotation(axis: np.ndarray, theta: np.ndarray) -> np.ndarray:
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    s, c = np.sin(theta)[:, None, None], np.cos(theta)[:, None, None]
    out = np.zeros((len(theta), 4, 4))
    out[:, :3, :3] = np.eye(3) + s * k + (1.0 - c) * (k @ k)
    out[:, 3, 3] = 1.0
    return out


def fk_all_reference(self: Any, q: np.ndarray) -> np.ndarray:
    """The former ``AraModel.fk_all``."""
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


def _scene_reference(
    self: Any, F: np.ndarray, C: np.ndarray, subset: np.ndarray, obs: PointObstacles
) -> np.ndarray:
    cov = self.robot.cover
    if not subset.any():
        return np.full(len(C), np.inf)
    bc, br = self.robot.cover.link_bounds(len(self.robot.link_names))
    links = np.unique(cov.link[subset])
    FL = F[:, links]
    lc = np.einsum("blij,lj->bli", FL[..., :3, :3], bc[links]) + FL[..., :3, 3]
    lb = obs.clearance(lc, br[links], upper=_CAP)
    need_link = np.zeros((len(C), len(self.robot.link_names)), dtype=bool)
    need_link[:, links] = lb < _CAP
    need = need_link[:, cov.link] & subset[None, :]
    out = np.full(C.shape[:2], _CAP)
    if need.any():
        b_idx, s_idx = np.nonzero(need)
        out[b_idx, s_idx] = obs.clearance(C[b_idx, s_idx], cov.radius[s_idx], upper=_CAP)
    return np.where(subset[None, :], out, np.inf).min(axis=1)


def clearances_reference(self: Any, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The former ``_Checker.clearances``: (scene, self) clearance per configuration."""
    cov = self.robot.cover
    F = self.world(Q)
    C = cov.world(F)
    scene = _scene_reference(self, F, C, self.rest, self.obstacles)
    obs = self.contact if self.contact is not None else self.obstacles
    scene = np.minimum(scene, _scene_reference(self, F, C, self.foot, obs))
    selfc = np.full(len(C), np.inf)
    D = None
    for a, b, fine, i, j in self.pairs:
        n = len(self.robot.link_names)
        bc, br = (self.robot.cover if fine else self.robot.self_cover).link_bounds(n)
        ca = F[:, a, :3, :3] @ bc[a] + F[:, a, :3, 3]
        cb = F[:, b, :3, :3] @ bc[b] + F[:, b, :3, 3]
        bound = np.linalg.norm(ca - cb, axis=1) - br[a] - br[b]
        close = bound < _CAP
        selfc = np.minimum(selfc, np.where(close, np.inf, np.maximum(bound, _CAP)))
        if not close.any():
            continue
        if fine:
            P, r = C[close], cov.radius
        else:
            if D is None:
                D = self.robot.self_cover.world(F)
            P, r = D[close], self.robot.self_cover.radius
        d = np.linalg.norm(P[:, i] - P[:, j], axis=2) - r[i] - r[j]
        sub = selfc[close]
        selfc[close] = np.minimum(sub, d.min(axis=1))
    return scene, selfc


def valid_reference(self: Any, Q: np.ndarray) -> np.ndarray:
    """The former ``_Checker.valid``."""
    Q = np.atleast_2d(Q)
    lo, hi = self.robot.joint_limits[:, 0], self.robot.joint_limits[:, 1]
    inside = np.all((lo - 1e-9 <= Q) & (hi + 1e-9 >= Q), axis=1)
    scene, selfc = clearances_reference(self, Q)
    return inside & (scene >= self.params.clearance_margin_m) & (selfc >= self.params.self_margin_m)


def landing_configs_reference(
    robot: Any,
    target_rel: np.ndarray,
    hover_rel: np.ndarray,
    checker_free: Any,
    checker_contact: Any,
    params: Any,
    seed: int,
    prefer: Callable[[np.ndarray], np.ndarray] | None = None,
    post: Callable[[np.ndarray], bool] | None = None,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """The former ``_landing_configs``: one ``ik_track`` per IK solution."""
    from planners.switching.jump import _cartesian_line

    out: list[tuple[np.ndarray, np.ndarray]] = []
    up = _cartesian_line(target_rel, hover_rel, params.cartesian_steps)
    for retry in range(int(params.ik_retries)):
        sols = robot.ik(target_rel, None, seed + 1000 * retry)
        if len(sols) == 0:
            continue
        if prefer is not None:
            sols = sols[np.argsort(prefer(sols), kind="stable")]
        for q in sols:
            track = robot.ik_track(up, q)
            if track is None:
                continue
            approach = np.vstack([track[::-1], q[None]])
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
