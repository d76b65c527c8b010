"""Inch-worm jump: today's kernels vs the batched ones, same run.

    .venv/bin/python tests/benchmarks/bench_motion.py [N] [scene,scene,...]
    .venv/bin/python tests/benchmarks/bench_motion.py --quick [scene,...]      (N = 5)
    .venv/bin/python tests/benchmarks/bench_motion.py --replay [R] [scene,...] [jump seeds]
    .venv/bin/python tests/benchmarks/bench_motion.py --blasting

For every scene of :mod:`planners.switching.scenes` whose switching decision
is an inch-worm jump (the others — mobile, no surface — plan no jump), and
every noise seed 0..N-1 (default 20), the full jump
(:func:`plan_inchworm_jump`, default parameters, ``seed`` = the scene seed)
is planned twice, interleaved: ``before`` — the kernels of commit 111f02a
patched back in from ``tests/switching/_reference_collision.py``
(``_Checker.clearances``/``valid`` with the per-link-pair Python loop and the
0.1 m KD-tree culling, ``AraModel.fk_all`` one 4×4 Rodrigues per joint,
``_landing_configs`` one IK track per solution) — and ``after`` (the code as
shipped).  Both plan with OMPL.  Success = a plan comes back; time = wall
time of the whole jump (IK, RRT, checks); checks = configurations passed to
``_Checker.valid``; same plan = identical joint trajectory.  Ratios are
after / before from this run.

``--replay`` isolates the planner (IK, the swing search and the checks
around it are the same for both and dominate the jump's time on easy
scenes): one legacy jump per scene and jump seed records every
joint-space problem the jump hands to ``_plan_free`` (checker, start, IK
goals, parameters: attempts restarts of ``max_iterations``), then each
backend solves each recorded problem with R planner seeds.  Success = a path
within the restarts; time = that ``_plan_free`` call.

``--blasting``: the whole-surface blasting plan with ``joint_planner="rrt"``
(every move that no via-point polyline certifies goes to RRT-Connect) on
Surface 1 in the I-beam channel, with the point obstacle, and with the rod
in the blast zone, and on Surface 2 in the channel: before (the former
hand-written RRT-Connect, ``tests/blasting/_reference_rrt.py``, patched into
``planners.blasting.motion.rrt_connect``) and after (OMPL), same run; the
plan's checks, skipped spots, RRT calls / failures and planning time.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import robots
from planners.errors import PlannerError
from planners.switching import jump as _jump
from planners.switching.decide import decide_mode
from planners.switching.jump import JumpParams, plan_inchworm_jump
from planners.switching.scenes import SCENES, make_scene
from robots.ara.model import AraModel
from tests.switching import _reference_collision as _ref
from tests.switching._reference_rrt import plan_path_legacy

ARA = robots.load_robot("ara")
FOOT = (float(ARA.params["foot"]["length_m"]), float(ARA.params["foot"]["width_m"]))
BACKENDS = ("legacy", "ompl")
VARIANTS = ("before", "after")
_COUNT = [0]
_AFTER = {
    "valid": _jump._Checker.valid,
    "clearances": _jump._Checker.clearances,
    "fk_all": AraModel.fk_all,
    "landing": _jump._landing_configs,
}
_BEFORE = {
    "valid": _ref.valid_reference,
    "clearances": _ref.clearances_reference,
    "fk_all": _ref.fk_all_reference,
    "landing": _ref.landing_configs_reference,
}
_KERNELS = dict(_AFTER)


def _counting_valid(self, Q):  # count configurations checked, same checker
    _COUNT[0] += len(np.atleast_2d(Q))
    return _KERNELS["valid"](self, Q)


_jump._Checker.valid = _counting_valid


def use_kernels(variant: str) -> None:
    """Patch the jump's kernels: ``before`` (111f02a) or ``after``."""
    k = _BEFORE if variant == "before" else _AFTER
    _KERNELS.update(k)
    _jump._Checker.clearances = k["clearances"]
    AraModel.fk_all = k["fk_all"]
    _jump._landing_configs = k["landing"]


_OMPL_PLAN_PATH = _jump.plan_path


def _legacy_plan_path(start, goals, valid, *, lower, upper, rng, params):
    return plan_path_legacy(
        start, goals, valid, lower=lower, upper=upper, rng=rng, step=params.step_rad,
        resolution=params.resolution_rad, max_iterations=params.max_iterations,
        shortcut_iterations=params.shortcut_iterations,
    )  # fmt: skip


PLAN_PATH = {"legacy": _legacy_plan_path, "ompl": _OMPL_PLAN_PATH}


def use_backend(backend: str) -> None:
    """The jump's ``plan_path`` (looked up at call time by ``_plan_free``)."""
    _jump.plan_path = PLAN_PATH[backend]


def run(d, seed: int, backend: str = "ompl", variant: str = "after"):
    """One jump; (ok, seconds, checks, error name, joint trajectory or None)."""
    c = d.chosen
    surface = (c.frame.origin, c.frame.x_axis, c.frame.y_axis, c.area.hull)
    _COUNT[0] = 0
    use_backend(backend)
    use_kernels(variant)
    t0 = time.perf_counter()
    Q = None
    try:
        plan = plan_inchworm_jump(
            ARA, d.foothold_candidates, obstacles=d.points, surface=surface,
            params=JumpParams(seed=seed),
        )  # fmt: skip
        ok, why, Q = True, "", plan.joint_trajectory
    except PlannerError as exc:
        ok, why = False, type(exc).__name__
    finally:
        use_backend("ompl")
        use_kernels("after")
    return ok, time.perf_counter() - t0, _COUNT[0], why, Q


def replay(r: int, names: list[str], jump_seeds: list[int]) -> None:
    orig = _jump._plan_free
    header = (f"{'scene':15s} {'legacy ok':>10s} {'ompl ok':>9s} {'legacy med s':>13s} "
              f"{'ompl med s':>11s} {'time ratio':>11s} {'checks ratio':>13s}")  # fmt: skip
    table = []
    for name in names:
        problems: list[tuple] = []

        def record(checker, start, goals, params, rng, _into=problems):
            _into.append((checker, start.copy(), np.array(goals), params))
            return orig(checker, start, goals, params, rng)

        _jump._plan_free = record
        for seed in jump_seeds:
            sc = make_scene(name, seed)
            d = decide_mode(sc.points, camera_to_base=sc.camera_to_base, base_height=0.0, foot=FOOT)
            if d.mode != "inchworm":
                print(f"{name:15s} seed {seed}: no inch-worm decision", flush=True)
                continue
            ok, t, _, why, _ = run(d, seed, "legacy")
            print(f"{name:15s} seed {seed}: recorded {len(problems)} problems "
                  f"(jump {'ok' if ok else why}, {t:.1f} s)", flush=True)  # fmt: skip
        _jump._plan_free = orig
        res: dict[str, list] = {b: [] for b in BACKENDS}
        for k, (checker, start, goals, params) in enumerate(problems):
            if np.abs(goals - start).max() < 1e-12:
                continue
            for s in range(r):
                for b in BACKENDS:
                    use_backend(b)
                    p = params
                    _COUNT[0] = 0
                    t0 = time.perf_counter()
                    path, _ = orig(checker, start, goals, p, np.random.default_rng(s))
                    res[b].append((path is not None, time.perf_counter() - t0, _COUNT[0]))
            line = "  ".join(
                f"{b}: {sum(x[0] for x in v[-r:])}/{r} ok, median "
                f"{np.median([x[1] for x in v[-r:]]):.2f} s, "
                f"{np.median([x[2] for x in v[-r:]]):.0f} chk" for b, v in res.items()
            )  # fmt: skip
            print(f"{name:15s} problem {k:2d} ({len(goals)} goals)  {line}", flush=True)
        if not res["legacy"]:
            continue
        (lo, oo) = (np.array([x[0] for x in res[b]]) for b in BACKENDS)
        lt, ot = (np.median([x[1] for x in res[b]]) for b in BACKENDS)
        lc, oc = (np.median([x[2] for x in res[b]]) for b in BACKENDS)
        table.append(
            f"{name:15s} {lo.sum():4d}/{len(lo):<5d} {oo.sum():4d}/{len(oo):<4d} {lt:13.3f} "
            f"{ot:11.3f} {ot / lt:11.2f} {oc / lc:13.2f}"
        )
        print(header + "\n" + table[-1], flush=True)
    print()
    print(header)
    print("\n".join(table))


def blasting() -> None:
    import planners.blasting.motion as bm
    from planners.blasting import plan_blasting, scenes
    from tests.blasting._reference_rrt import rrt_connect_legacy

    robot = robots.load_robot("denso_vm6083").with_base(scenes.robot_base())
    obst = scenes.bridge_obstacles()
    cases = [
        (1, "I-beam channel", obst),
        (1, "channel + point obstacle", (*obst, scenes.obstacle_points())),
        (1, "channel + rod in blast zone", (*obst, scenes.obstacle_points(xy=(0.40, 0.62), z_low=1.30))),
        (2, "I-beam channel", obst),
    ]  # fmt: skip
    after = bm.rrt_connect
    print(f"{'case':38s} {'':6s} {'N':>4s} {'skip':>4s} {'clr mm':>7s} {'rrt':>4s} {'fail':>4s} "
          f"{'checks failed':24s} {'plan s':>7s}")  # fmt: skip
    for k, label, ob in cases:
        times = {}
        for tag, fn in (("before", rrt_connect_legacy), ("after", after)):
            bm.rrt_connect = fn  # trajectory.py looks it up at call time
            try:
                t0 = time.perf_counter()
                with np.errstate(all="ignore"):
                    p = plan_blasting(
                        scenes.bridge_surface(k), disc_radius_m=scenes.DISC_RADIUS_M,
                        robot=robot, obstacles=ob, joint_planner="rrt",
                    )  # fmt: skip
                times[tag] = time.perf_counter() - t0
            finally:
                bm.rrt_connect = after
            failed = ",".join(c["name"] for c in p.checks() if not c["passed"]) or "none"
            st = p.motion
            print(f"Surface {k} {label:28s} {tag:6s} {len(p.centers):4d} {len(p.skipped):4d} "
                  f"{p.min_clearance_m * 1000:7.1f} {st['rrt_calls']:4d} {st['rrt_failures']:4d} "
                  f"{failed:24s} {times[tag]:7.2f}", flush=True)  # fmt: skip
        print(f"{'':38s} ratio after/before {times['after'] / times['before']:.2f}×")


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--blasting":
        blasting()
        return
    if len(sys.argv) > 1 and sys.argv[1] == "--replay":
        r = int(sys.argv[2]) if len(sys.argv) > 2 else 20
        names = sys.argv[3].split(",") if len(sys.argv) > 3 else list(SCENES)
        seeds = [int(x) for x in sys.argv[4].split(",")] if len(sys.argv) > 4 else [0]
        replay(r, names, seeds)
        return
    args = sys.argv[1:]
    if args and args[0] == "--quick":
        n, names = 5, (args[1].split(",") if len(args) > 1 else list(SCENES))
    else:
        n = int(args[0]) if args else 20
        names = args[1].split(",") if len(args) > 1 else list(SCENES)
    summary = []
    for name in names:
        rows: dict[str, list] = {v: [] for v in VARIANTS}
        same = 0
        for seed in range(n):
            sc = make_scene(name, seed)
            d = decide_mode(sc.points, camera_to_base=sc.camera_to_base, base_height=0.0, foot=FOOT)
            if d.mode != "inchworm":
                continue
            # Interleaved, alternating which goes first (machine load drifts).
            order = VARIANTS if seed % 2 == 0 else VARIANTS[::-1]
            for v in order:
                rows[v].append(run(d, seed, "ompl", v))
            qb, qa = rows["before"][-1][4], rows["after"][-1][4]
            same += int(qb is not None and qa is not None and np.array_equal(qb, qa))
            print(
                f"{name:15s} seed {seed:2d}  "
                + "  ".join(
                    f"{v}: {'ok ' if r[-1][0] else 'FAIL'} {r[-1][1]:6.2f}s {r[-1][2]:7d} chk {r[-1][3]}"
                    for v, r in rows.items()
                ),
                flush=True,
            )
        if not rows["before"]:
            print(f"{name:15s} no inch-worm decision on any seed: no jump to plan")
            continue
        stats = {}
        for v, r in rows.items():
            ok = np.array([x[0] for x in r])
            t = np.array([x[1] for x in r])
            chk = np.array([x[2] for x in r])
            stats[v] = (ok.sum(), len(ok), np.median(t[ok]) if ok.any() else np.nan, np.median(chk))
        summary.append((name, stats, same))
    print()
    print(f"{'scene':15s} {'before ok':>10s} {'after ok':>9s} {'before med s':>13s} "
          f"{'after med s':>12s} {'time ratio':>11s} {'checks ratio':>13s} {'same plan':>10s}")  # fmt: skip
    for name, s, same in summary:
        (bk, bn, bt, bc), (ak, an, at, ac) = s["before"], s["after"]
        print(
            f"{name:15s} {bk:4d}/{bn:<5d} {ak:4d}/{an:<4d} {bt:13.2f} {at:12.2f} "
            f"{at / bt:11.2f} {ac / bc:13.2f} {same:4d}/{bn:<5d}"
        )


if __name__ == "__main__":
    main()
