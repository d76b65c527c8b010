"""Single-configuration FK / Jacobian and DLS IK: the former numpy kernels vs
pinocchio from the URDF, in the same run.

Old: DENSO's D-H chain (``dh_chain_transforms`` + ``geometric_jacobian``) and
CMBOT's joint-origin chain (``CmbotChain.link_frames`` and its cross-product
Jacobian), i.e. what ``fk``/``jacobian`` evaluated for one configuration
before.  New: ``model.fk`` / ``model.jacobian`` (pinocchio).  DLS IK is
``robots.kinematics.solve_ik_dls`` (CMBOT's arm IK, 24 restarts) driven by
either pair on the same random reachable poses.

Run: ``.venv/bin/python tests/benchmarks/bench_kinematics.py``.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from robots import load_robot
from robots.kinematics import dh_chain_transforms, geometric_jacobian, pose_error, solve_ik_dls


def per_call(fn: Callable[[np.ndarray], object], qs: np.ndarray, repeat: int = 5) -> float:
    """Best-of-``repeat`` mean seconds per call over the configurations ``qs``."""
    best = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        for q in qs:
            fn(q)
        best = min(best, (time.perf_counter() - t) / len(qs))
    return best


def main() -> None:
    rng = np.random.default_rng(0)
    denso = load_robot("denso_vm6083")
    cmbot = load_robot("cmbot")

    def denso_old_fk(q: np.ndarray) -> np.ndarray:
        return dh_chain_transforms(q, denso.d, denso.a, denso.alpha, denso.offset, denso.base)[-1]

    def denso_old_jac(q: np.ndarray) -> np.ndarray:
        F = dh_chain_transforms(q, denso.d, denso.a, denso.alpha, denso.offset, denso.base)
        return geometric_jacobian(F)

    def cmbot_old_fk(q: np.ndarray) -> np.ndarray:
        return cmbot.link_frames(q)[-1]

    def cmbot_old_jac(q: np.ndarray) -> np.ndarray:
        F = cmbot.link_frames(q)
        z, o, p = F[1:-1, :3, 2], F[1:-1, :3, 3], F[-1, None, :3, 3]
        return np.concatenate([np.cross(z, p - o), z], axis=-1).T

    def sample(model: object, n: int) -> np.ndarray:
        lim = model.joint_limits  # type: ignore[attr-defined]
        lo, hi = np.maximum(lim[:, 0], -np.pi), np.minimum(lim[:, 1], np.pi)
        return rng.uniform(lo, hi, (n, len(lo)))

    qd, qc = sample(denso, 2000), sample(cmbot, 2000)
    # Same answers before timing: a faster wrong kernel is no result.
    for q in qd[:50]:
        assert np.allclose(denso.fk(q), denso_old_fk(q), atol=1e-9)
        assert np.allclose(denso.jacobian(q), denso_old_jac(q), atol=1e-9)
    for q in qc[:50]:
        assert np.allclose(cmbot.fk(q), cmbot_old_fk(q), atol=1e-9)
        assert np.allclose(cmbot.jacobian(q), cmbot_old_jac(q), atol=1e-9)

    rows = [
        ("DENSO FK", per_call(denso_old_fk, qd), per_call(denso.fk, qd)),
        ("DENSO Jacobian", per_call(denso_old_jac, qd), per_call(denso.jacobian, qd)),
        ("CMBOT arm FK", per_call(cmbot_old_fk, qc), per_call(cmbot.fk, qc)),
        ("CMBOT arm Jacobian", per_call(cmbot_old_jac, qc), per_call(cmbot.jacobian, qc)),
    ]

    # DLS IK of CMBOT's arm (CmbotModel.ik's call) on reachable poses.
    old_model = SimpleNamespace(
        joint_limits=cmbot.joint_limits,
        fk=lambda q, link=None: cmbot_old_fk(q),
        jacobian=cmbot_old_jac,
    )
    targets = [cmbot.fk(q) for q in sample(cmbot, 20)]
    times: dict[str, float] = {}
    found: dict[str, list[np.ndarray | None]] = {}
    for label, model in (("old", old_model), ("pinocchio", cmbot)):
        t = time.perf_counter()
        found[label] = [solve_ik_dls(model, T, None, restarts=24) for T in targets]  # type: ignore[arg-type]
        times[label] = (time.perf_counter() - t) / len(targets)
    ok_old = sum(s is not None for s in found["old"])
    ok_new = sum(s is not None for s in found["pinocchio"])
    # Round-off differences can steer a redundant 7-DoF iteration to another
    # solution of the same pose: count equal solutions and check every one reaches its pose.
    same = sum(
        a is not None and b is not None and bool(np.allclose(a, b, atol=1e-6))
        for a, b in zip(found["old"], found["pinocchio"], strict=True)
    )
    reach = max(
        float(np.linalg.norm(pose_error(T, cmbot.fk(s))))
        for label in found
        for T, s in zip(targets, found[label], strict=True)
        if s is not None
    )
    rows.append(("CMBOT DLS IK per pose", times["old"], times["pinocchio"]))

    print(f"{'call':<24}{'old [µs]':>12}{'pinocchio [µs]':>16}{'old/new':>10}")
    for name, old, new in rows:
        print(f"{name:<24}{old * 1e6:>12.1f}{new * 1e6:>16.1f}{old / new:>9.1f}×")
    print(
        f"DLS IK solved: old {ok_old}/{len(targets)}, pinocchio {ok_new}/{len(targets)}; "
        f"same solution (≤1e-6 rad) on {same}/{len(targets)}; worst pose error {reach:.1e}"
    )


if __name__ == "__main__":
    main()
