"""Inch-worm jump planning over random reachable target surfaces (on demand).

    .venv/bin/python tests/benchmarks/bench_switching.py [N] [seed] [steelpath,baseline,plain_rrt]

Each trial draws a 0.5 m square steel plate in front of the ARA robot (random
distance 0.25-0.5 m, bearing ±60°, height -0.15…0.35 m, normal tilted
towards the robot), scanned as points at 1 cm with 2 mm noise, with the
foothold at its centre.  A target counts as reachable when the plate keeps
clear of the robot's mobile pose and a collision-free landing of foot 1
exists (256 IK seeds, both headings, straight approach valid) from which
foot 2 can lift off.  Both
planners run on the same targets:

* SteelPath: multi-seed IK goals, goal-biased RRT-Connect with up to 4
  restarts, flipped/shifted footholds, up to 12 landing spots for foot 2;
* baseline: one RRT-Connect attempt towards one IK goal, no goal bias, no
  alternatives — the seed's MoveIt setup, which "needed to redo sometimes";
* plain_rrt: SteelPath with only the RRT made plain (one attempt, no goal
  bias), to show what the retries alone buy.

A run succeeds when a plan comes back and passes every check: joint limits,
joint speeds, clearance ≥ 1 cm along the path, self clearance ≥ 0, feet at
their targets.

Plans run with one BLAS thread, as the server's planning workers run them
(``server/jobs.py``); ``BENCH_BLAS_THREADS=N`` changes that (on this 2-core
machine two threads make the small solves of the IK slower, ~2.05 s against
~1.80 s median).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import robots
from planners.errors import PlannerError
from planners.switching.collision import PointObstacles
from planners.switching.jump import (
    JumpParams,
    JumpRobot,
    _cartesian_line,
    _Checker,
    _contact_zone,
    _flip,
    _landing_configs,
    _self_pairs,
    _translate,
    plan_inchworm_jump,
)

ARA = robots.load_robot("ara")
ROB = JumpRobot.from_model(ARA)
ROB_EXHAUSTIVE = JumpRobot.from_model(ARA, ik_seeds=256)
# Only the RRT made plain (one attempt); every other robustness measure
# kept: isolates what the retries buy.
RRT_ONLY = JumpParams(attempts=1)
BASELINE = JumpParams(
    attempts=1,
    max_goals=1,
    try_flipped=False,
    inward_shifts_m=(0.0,),
    max_second_foot_candidates=1,
)


def random_target(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray] | None:
    r, az, z = rng.uniform(0.25, 0.5), np.radians(rng.uniform(-60, 60)), rng.uniform(-0.15, 0.35)
    c = np.array([r * np.cos(az), r * np.sin(az), z])
    towards = np.array([0.0, 0.0, 0.1]) - c
    towards /= np.linalg.norm(towards)
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    n = n + 2.0 * towards
    n /= np.linalg.norm(n)
    if n @ towards < 0.3:
        return None
    x = np.cross(n, rng.normal(size=3))
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, np.cross(n, x), n])
    T[:3, 3] = c
    g = np.arange(-0.25, 0.25 + 1e-9, 0.01)
    u, v = np.meshgrid(g, g)
    pts = c + u.reshape(-1, 1) * x + v.reshape(-1, 1) * np.cross(n, x)
    pts = pts + rng.normal(0, 0.002, pts.shape)
    # Keep clear of the robot in its mobile pose and of the standing surface.
    sph = ROB.cover.world(ARA.fk_all(ARA.q_mobile))
    if np.min(np.linalg.norm(sph[:, None] - pts[None], axis=2) - ROB.cover.radius[:, None]) < 0.05:
        return None
    under = (pts[:, 0] < 0.2) & (np.abs(pts[:, 1]) < 0.25)
    if np.any(pts[under, 2] < 0.03):
        return None
    if not landing_exists(T, pts):
        return None
    return T, pts


def landing_exists(T: np.ndarray, pts: np.ndarray) -> bool:
    """Reachable = some collision-free landing of foot 1 exists: 256 IK seeds,
    both headings, contact and straight approach valid (independent of the
    planner's 48-seed search)."""
    p = JumpParams(max_goals=1, ik_retries=1)  # one valid landing is enough
    g = np.arange(-0.75, 0.13 + 1e-9, 0.01)
    gx, gy = np.meshgrid(g, np.arange(-0.2, 0.2 + 1e-9, 0.01))
    allp = np.vstack([pts, np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])])
    pairs = _self_pairs(ROB)
    free = _Checker(ROB, 0, np.eye(4), PointObstacles(allp), None, pairs, p)
    z2 = ~_contact_zone(allp, np.eye(4), ROB.foot, p.contact_band_m, p.contact_pad_m)
    lift = _cartesian_line(
        np.eye(4), _translate(np.eye(4), np.array([0, 0, p.lift_m])), p.cartesian_steps
    )

    def foot2_lifts(q: np.ndarray) -> bool:
        # The jump needs foot 2 to lift off once foot 1 has landed.
        W1 = ARA.fk(q)
        track = ROB.ik_track(np.einsum("bij,jk->bik", np.linalg.inv(lift), W1), q)
        chk = _Checker(ROB, 1, W1, PointObstacles(allp), PointObstacles(allp[z2]), pairs, p)
        return track is not None and bool(chk.valid(track).all())

    for W in (T, _flip(T)):
        keep = ~_contact_zone(allp, W, ROB.foot, p.contact_band_m, p.contact_pad_m)
        contact = _Checker(
            ROB, 0, np.eye(4), PointObstacles(allp), PointObstacles(allp[keep]), pairs, p
        )
        hover = _translate(W, W[:3, 2] * p.standoff_m)

        if _landing_configs(ROB_EXHAUSTIVE, W, hover, free, contact, p, 7, post=foot2_lifts):
            return True
    return False


def checks_pass(plan, margin: float = 0.01) -> bool:
    Q, t = plan.joint_trajectory, plan.times
    lo, hi = ARA.joint_limits[:, 0], ARA.joint_limits[:, 1]
    speed = np.abs(np.diff(Q, axis=0)) / np.diff(t)[:, None]
    c = next(p for p in plan.phases if p.name == "C")
    return bool(
        np.all(lo - 1e-9 <= Q)
        and np.all(hi + 1e-9 >= Q)
        and np.all(speed <= ARA.max_speed * (1 + 1e-6))
        and plan.clearance.min() >= margin - 1e-9
        and plan.self_clearance.min() >= 0.0
        and np.allclose(ARA.fk(Q[c.stop - 1]), plan.foot1_target, atol=1e-5)
        and np.allclose(
            plan.foot1_target @ np.linalg.inv(ARA.fk(Q[-1])), plan.foot2_target, atol=1e-4
        )
    )


def run(params: JumpParams, target, pts) -> tuple[bool, bool, float, str]:
    t0 = time.perf_counter()
    try:
        plan = plan_inchworm_jump(ROB, target, obstacles=pts, params=params)
    except PlannerError as exc:
        return False, False, time.perf_counter() - t0, f"{type(exc).__name__}: {exc}"[:90]
    return True, checks_pass(plan), time.perf_counter() - t0, ""


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 30
    seed = int(sys.argv[2]) if len(sys.argv) > 2 else 0
    rng = np.random.default_rng(seed)
    targets = []
    while len(targets) < n:
        t = random_target(rng)
        if t is not None:
            targets.append(t)
    which = sys.argv[3].split(",") if len(sys.argv) > 3 else ["steelpath", "baseline", "plain_rrt"]
    configs = {"steelpath": JumpParams(), "baseline": BASELINE, "plain_rrt": RRT_ONLY}
    rows: dict[str, list] = {name: [] for name in which}
    blas = int(os.environ.get("BENCH_BLAS_THREADS", "1"))
    threadpool_limits(blas, user_api="blas")
    print(f"BLAS threads per plan: {blas}", flush=True)
    for k, (T, pts) in enumerate(targets):
        for name in which:
            params = JumpParams(**{**configs[name].__dict__, "seed": k})
            rows[name].append(run(params, T, pts))
        line = "  ".join(
            f"{nm}: {'ok ' if r[-1][0] else 'FAIL'} {r[-1][2]:6.2f}s" for nm, r in rows.items()
        )
        why = "; ".join(f"{nm}: {r[-1][3]}" for nm, r in rows.items() if r[-1][3])
        print(f"{k:3d} {line}  {why}", flush=True)
    print()
    for name, r in rows.items():
        ok = np.array([x[0] for x in r])
        checked = np.array([x[1] for x in r])
        dt = np.array([x[2] for x in r])
        print(
            f"{name:10s} success {ok.mean() * 100:5.1f} % ({ok.sum()}/{len(ok)}), "
            f"checks pass on {checked.sum()}/{ok.sum()} returned, "
            f"median planning time {np.median(dt[ok]) if ok.any() else float('nan'):.2f} s "
            f"(all runs {np.median(dt):.2f} s)"
        )
    if "steelpath" in rows and "baseline" in rows:
        s, b = (np.mean([x[0] for x in rows[k]]) for k in ("steelpath", "baseline"))
        print(f"success ratio steelpath / baseline = {s / b if b else float('inf'):.2f}")


if __name__ == "__main__":
    main()
