"""Primitive distance kernels before/after the closed forms, measured in one run.

Run on demand::

    .venv/bin/python tests/benchmarks/bench_collision.py [--quick] [--sections 1,2,3,4]

Sections (ratios are before / after, both measured here, now):

1. Blasting spheroid–box, per pair: the former alternating-projection kernel
   (``tests/blasting/_reference_collision.py``, batched as production ran it,
   and one pair per call) vs coal (``planners/blasting/collision.py``);
   agreement with the converged reference where separated, and the overlap
   depth (coal: true penetration depth; former: probe depth).
2. Blasting clearance per configuration: DENSO VM-6083 random joint vectors
   in the Fig. 4.4 environment (I-beam channel + point obstacle), in the
   three modes the planner uses (exact report, planning bound with horizon
   and 5 % relative tolerance, sign-only at the safety margin).
3. CMBOT sphere–cuboid: the former GJK (``tests/cmbot/_reference_gjk.py``)
   vs coal vs the closed form (one query per call, and batched per pair).
4. Whole surface with collision avoidance (``plan_blasting`` on Surfaces 1–3
   in the I-beam channel, and Surface 1 with the rod in the blast zone):
   before (the reference kernel patched into ``clearance``) and after.
5. CMBOT §4 arm experiment (seed 002 Eq. 15–26, with avoidance and the
   without-avoidance comparison run, simulation gate): before (the former
   per-pair GJK patched into ``experiment.pair_distances``) and after (the
   batched closed form), same scene and parameters.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import coal
import numpy as np
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import planners.blasting.collision as col
import planners.cmbot.experiment as cmbot_experiment
from planners.blasting import (
    CLEAR_HORIZON_M,
    CLEAR_REL_TOL,
    FOCI,
    KP,
    SAFETY_M,
    plan_blasting,
    scenes,
)
from planners.blasting import arm as A
from planners.blasting.collision import Box, Obstacles, Spheroids
from planners.cmbot.distance import Cuboid, sphere_box_exact
from planners.cmbot.manipulation import plan_manipulation
from robots import load_robot
from tests.blasting import _reference_collision as ref
from tests.cmbot._reference_gjk import sphere_box_gjk


def _timed(f: Callable[[], object], repeat: int = 3) -> tuple[float, object]:
    """Median wall time of ``repeat`` calls and the last result."""
    ts, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = f()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts), out


def _random_pairs(n: int, rng: np.random.Generator) -> Spheroids:
    f1 = rng.normal(size=(n, 3)) * 0.3
    f2 = f1 + rng.normal(size=(n, 3)) * 0.3
    cf = np.linalg.norm(f2 - f1, axis=1) * rng.uniform(1.03, 1.3, n)
    return Spheroids(f1, f2, cf)


def section_pairs(quick: bool) -> None:
    n_box, per = (4, 250) if quick else (10, 500)
    n = n_box * per
    print(f"\n== 1. Blasting spheroid–box per pair ({n_box} boxes × {per} spheroids) ==")
    rng = np.random.default_rng(0)
    boxes = [
        Box(rng.normal(size=3) * 0.4, rng.uniform(0.02, 0.3, 3), Rotation.random(random_state=k).as_matrix())
        for k in range(n_box)
    ]  # fmt: skip
    S = [_random_pairs(per, rng) for _ in boxes]
    with np.errstate(all="ignore"):
        t_ref, d_ref = _timed(
            lambda: [ref.spheroid_box_distance(s, b) for s, b in zip(S, boxes, strict=True)]
        )
        t_new, d_new = _timed(
            lambda: [col.spheroid_box_distance(s, b) for s, b in zip(S, boxes, strict=True)]
        )
        m = 200  # one pair per call (how a single configuration check sees it)
        t_ref1, _ = _timed(
            lambda: [ref.spheroid_box_distance(S[0][i : i + 1], boxes[0]) for i in range(m)]
        )
        t_new1, _ = _timed(
            lambda: [col.spheroid_box_distance(S[0][i : i + 1], boxes[0]) for i in range(m)]
        )
        exact = np.concatenate(
            [
                ref.spheroid_box_distance(s, b, tol=1e-12, max_iter=20_000)
                for s, b in zip(S, boxes, strict=True)
            ]
        )
    d_ref, d_new = np.concatenate(d_ref), np.concatenate(d_new)  # type: ignore[arg-type]
    print(f"  batched: former {1e6 * t_ref / n:7.1f} µs/pair, coal {1e6 * t_new / n:6.1f} µs/pair "
          f"→ ratio {t_ref / t_new:5.1f}×")  # fmt: skip
    print(f"  1 pair/call: former {1e6 * t_ref1 / m:7.1f} µs/pair, coal {1e6 * t_new1 / m:6.1f} µs/pair "
          f"→ ratio {t_ref1 / t_new1:5.1f}×")  # fmt: skip
    sep = exact > 1e-6
    ov = (exact < -1e-6) & (d_new < 0)
    print(f"  separated ({sep.sum()}): max |coal − converged| {np.abs(d_new - exact)[sep].max():.1e} m, "
          f"max |former(tol 1e-5) − converged| {np.abs(d_ref - exact)[sep].max():.1e} m")  # fmt: skip
    deeper = np.mean(d_new[ov] <= exact[ov] + 2e-6) * 100
    ratio = np.median(d_new[ov] / np.minimum(exact[ov], -1e-6))
    print(f"  overlapping ({ov.sum()}): coal depth / former probe depth median "
          f"{ratio:.2f}; coal at least as deep (EPA tol 2e-6) on {deeper:.1f} %; "
          f"signs agree on {np.mean((d_new > 0) == (exact > 0)) * 100:.2f} %")  # fmt: skip


def _scene() -> tuple[object, Obstacles]:
    robot = load_robot("denso_vm6083").with_base(scenes.robot_base())
    return robot, Obstacles.coerce((*scenes.bridge_obstacles(), scenes.obstacle_points()))


def section_configs(quick: bool) -> None:
    n = 200 if quick else 600
    print(
        f"\n== 2. Blasting clearance per configuration ({n} DENSO joint vectors, channel + point obstacle) =="
    )
    robot, obst = _scene()
    rng = np.random.default_rng(1)
    lim = np.asarray(robot.joint_limits)
    lo, hi = lim[:, 0], lim[:, 1]
    q = lo + (hi - lo) * rng.uniform(size=(n, 6))
    S = A.link_spheroids(robot, q, 0.1, KP, FOCI)
    modes = {
        "exact report": {},
        "planning bound": {"horizon": CLEAR_HORIZON_M, "rel_tol": CLEAR_REL_TOL},
        "sign-only": {"sign_only": True, "margin": SAFETY_M},
    }
    with np.errstate(all="ignore"):
        for label, kw in modes.items():
            t_ref, c_ref = _timed(lambda kw=kw: ref.clearance(S, obst, **kw))
            t_new, c_new = _timed(lambda kw=kw: col.clearance(S, obst, **kw))
            c_ref, c_new = np.asarray(c_ref), np.asarray(c_new)
            free_ref, free_new = c_ref > SAFETY_M, c_new > SAFETY_M
            line = (f"  {label:15s}: former {1e6 * t_ref / n:7.1f} µs/config, coal {1e6 * t_new / n:7.1f} µs/config "
                    f"→ ratio {t_ref / t_new:5.1f}×; free (> {SAFETY_M * 1e3:.0f} mm) former {free_ref.sum()}, "
                    f"coal {free_new.sum()}, disagree {np.sum(free_ref != free_new)}")  # fmt: skip
            if label == "exact report":
                both = (c_ref > 1e-6) & (c_new > 1e-6)
                line += f"; max |Δ| where clear {np.abs(c_ref - c_new)[both].max():.1e} m"
            print(line)


def section_cmbot(quick: bool) -> None:
    n = 300 if quick else 2000
    print(f"\n== 3. CMBOT sphere–cuboid, {n} random pairs ==")
    rng = np.random.default_rng(0)
    boxes = [
        Cuboid(rng.normal(size=3), rng.uniform(0.05, 1.0, 3), Rotation.random(random_state=i).as_matrix())
        for i in range(n)
    ]  # fmt: skip
    C = rng.normal(size=(n, 3)) * 1.5
    r = rng.uniform(0.0, 0.2, n)

    def gjk() -> np.ndarray:
        return np.array([sphere_box_gjk(C[i], r[i], boxes[i])[0] for i in range(n)])

    cshapes = [(coal.Box(*(2 * b.half)), coal.Transform3s(b.rotation, b.center)) for b in boxes]
    req = coal.DistanceRequest()
    req.gjk_tolerance = 1e-9
    res = coal.DistanceResult()
    Cl = list(C)

    def coal_q() -> np.ndarray:
        tf = coal.Transform3s()
        out = np.empty(n)
        for i in range(n):
            tf.setTranslation(Cl[i])
            res.clear()
            out[i] = coal.distance(coal.Sphere(max(r[i], 1e-9)), tf, *cshapes[i], req, res)
            # coal.Sphere(0) is degenerate; a 1e-9 m sphere stands in for a point
        return out

    def closed1() -> np.ndarray:
        return np.array(
            [sphere_box_exact(C[i][None], r[i : i + 1], [boxes[i]])[0][0, 0] for i in range(n)]
        )

    # batched: all N spheres against all M boxes (how the simulation gate and
    # the §4 experiment call it); per pair = time / (N·M)
    Cb, rb, bb = C[:50], r[:50], boxes[:50]

    def closed_b() -> np.ndarray:
        return sphere_box_exact(Cb, rb, bb)[0]

    t_g, d_g = _timed(gjk)
    t_c, d_c = _timed(coal_q)
    t_e, d_e = _timed(closed1)
    t_b, _ = _timed(closed_b)
    per_b = t_b / (len(Cb) * len(bb))
    print(f"  former GJK {1e6 * t_g / n:6.1f} µs/query, coal {1e6 * t_c / n:6.1f} µs/query, "
          f"closed form {1e6 * t_e / n:6.1f} µs/query, closed form batched {1e6 * per_b:6.3f} µs/pair")  # fmt: skip
    print(f"  ratios: GJK/closed batched {t_g / n / per_b:6.1f}×, coal/closed batched {t_c / n / per_b:6.1f}×, "
          f"GJK/coal {t_g / t_c:4.1f}×, GJK/closed 1-query {t_g / t_e:4.1f}×")  # fmt: skip
    d_g, d_c, d_e = np.asarray(d_g), np.asarray(d_c), np.asarray(d_e)
    print(f"  |GJK − closed| max {np.abs(d_g - d_e).max():.1e} m, |coal − closed| max "
          f"{np.abs(d_c - d_e - np.where(r > 0, 0, -1e-9)).max():.1e} m")  # fmt: skip


def section_whole(quick: bool) -> None:
    print(
        "\n== 4. Whole surface with collision avoidance, before (former kernel) / after (coal) =="
    )
    robot = load_robot("denso_vm6083").with_base(scenes.robot_base())
    obst = scenes.bridge_obstacles()
    rod = scenes.obstacle_points(xy=(0.40, 0.62), z_low=1.30)
    cases = [(k, "I-beam channel", obst) for k in ((1,) if quick else (1, 2, 3))]
    cases.append((1, "channel + rod in blast zone", (*obst, rod)))
    kernel = col.spheroid_box_distance
    print(f"{'case':38s} {'':6s} {'N':>4s} {'skip':>4s} {'cov %':>6s} {'over %':>6s} {'clr mm':>7s} "
          f"{'checks':>8s} {'plan s':>6s}")  # fmt: skip
    for k, label, ob in cases:
        times = {}
        for tag, fn in (("before", ref.spheroid_box_distance), ("after", kernel)):
            col.spheroid_box_distance = fn  # clearance() looks the kernel up at call time
            try:
                with np.errstate(all="ignore"):
                    t, p = _timed(
                        lambda ob=ob, k=k: plan_blasting(
                            scenes.bridge_surface(k),
                            disc_radius_m=scenes.DISC_RADIUS_M,
                            robot=robot,
                            obstacles=ob,
                        ),
                        repeat=1,
                    )
            finally:
                col.spheroid_box_distance = kernel
            times[tag] = t
            failed = [c["name"] for c in p.checks() if not c["passed"]]  # type: ignore[attr-defined]
            clr = p.min_clearance_m * 1000  # type: ignore[attr-defined]
            print(f"Surface {k} {label:28s} {tag:6s} {len(p.centers):4d} {len(p.skipped):4d} "  # type: ignore[attr-defined]
                  f"{p.coverage * 100:6.2f} {p.overspray * 100:6.3f} {clr:7.1f} "  # type: ignore[attr-defined]
                  f"{'ok' if not failed else ','.join(failed):>8s} {t:6.2f}")  # fmt: skip
        print(f"{'':38s} ratio before/after {times['before'] / times['after']:.2f}×")


def _gjk_pair_distances(
    centers: np.ndarray,
    radii: np.ndarray,
    boxes: list[Cuboid],
    arrays: object,
    mask: np.ndarray,
    cutoff: float,
) -> tuple[list[tuple[int, int, float, np.ndarray]], tuple[float, int, int]]:
    """``experiment.pair_distances`` as it ran before #13: one GJK per masked pair."""
    near: list[tuple[int, int, float, np.ndarray]] = []
    best = (np.inf, -1, -1)
    for i, j in zip(*np.nonzero(mask), strict=True):
        d, u = sphere_box_gjk(centers[i], float(radii[i]), boxes[j])
        if d <= cutoff:
            near.append((int(i), int(j), float(d), u))
        if d < best[0]:
            best = (float(d), int(i), int(j))
    return near, best


def section_cmbot_experiment(quick: bool) -> None:
    print("\n== 5. CMBOT §4 arm experiment, before (per-pair GJK) / after (closed form) ==")
    model = load_robot("cmbot")
    current = cmbot_experiment.pair_distances
    print(
        f"{'':7s} {'err mm':>7s} {'clr m':>7s} {'err0 mm':>7s} {'clr0 m':>7s} {'gate':>5s} {'s':>6s}"
    )
    times = {}
    for tag, fn in (("before", _gjk_pair_distances), ("after", current)):
        cmbot_experiment.pair_distances = fn  # track() looks it up at call time
        try:
            t, plan = _timed(
                lambda: plan_manipulation(model, compare=not quick, relocate=False), repeat=1
            )
        finally:
            cmbot_experiment.pair_distances = current
        times[tag] = t
        m = plan.metrics  # type: ignore[attr-defined]
        err0 = m.get("without_avoidance_max_tracking_error_mm", float("nan"))
        clr0 = m.get("without_avoidance_min_clearance_m", float("nan"))
        gate = "PASS" if plan.gate.passed else "FAIL"  # type: ignore[attr-defined]
        print(f"{tag:7s} {m['max_tracking_error_mm']:7.3f} {m['min_clearance_m']:7.4f} "
              f"{err0:7.3f} {clr0:7.4f} {gate:>5s} {t:6.2f}")  # fmt: skip
    print(f"{'':7s} ratio before/after {times['before'] / times['after']:.2f}×")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "--quick", action="store_true", help="fewer pairs and configurations, Surface 1 only"
    )
    ap.add_argument(
        "--sections", default="1,2,3,4,5", help="comma-separated section numbers, in run order"
    )
    args = ap.parse_args()
    sections = {
        "1": section_pairs,
        "2": section_configs,
        "3": section_cmbot,
        "4": section_whole,
        "5": section_cmbot_experiment,
    }
    for k in args.sections.split(","):
        if k not in sections:
            ap.error(f"unknown section {k!r}; sections are 1-5")
        sections[k](args.quick)


if __name__ == "__main__":
    main()
