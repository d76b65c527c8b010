"""CMBOT benchmark (seed 002 §4): the arm experiment with and without the
avoidance term, gait planning on a long guardrail, and GJK against a
brute-force distance — each baseline measured in the same run.

Run on demand::

    .venv/bin/python tests/benchmarks/bench_cmbot.py [--quick]

Sections:

1. §4 experiment (Eq. 21–26, 20 s, mrad/s reading) on the seed scene: max
   tracking error [mm] and min clearance [m] with and without Eq. 15–20,
   max tool speed, and the flip moment of the seed's climbing walk with and
   without the counterweight (Eq. 9–10).  The printed °/s reading is run too.
2. Gait planning time for a long walk (foothold search + trajectories +
   simulation gate) on a random guardrail.
3. Sphere–cuboid distance: GJK vs brute-force surface sampling (41×41 per
   face) and vs the closed form; ratio of times per query.
4. Simulation gate: the dense reference gate
   (``tests/cmbot/_reference_gate.py``) against the coarse-then-fine
   ``simulate_climb`` on the default climb and a 12 m guardrail climb —
   time (median of untraced runs), peak memory (a separate run under
   tracemalloc), clearance samples evaluated, ratios, and whether
   both reports agree.  ``--gate`` runs this section only.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import tracemalloc
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import robots
from planners.cmbot import ExperimentParams, Section4Trajectory, plan_climb, plan_manipulation
from planners.cmbot.distance import Cuboid, sphere_box_bruteforce, sphere_box_exact
from planners.cmbot.gait import GaitParams, build_trajectory, chain_limits, plan_footholds
from planners.cmbot.guardrail import make_guardrail
from planners.cmbot.simulate import simulate_climb
from tests.cmbot._reference_gate import simulate_climb_dense  # the dense gate
from tests.cmbot._reference_gjk import sphere_box_gjk  # the former GJK


def section_experiment(model) -> None:
    print("== 1. Seed §4 arm experiment (seed scene, rear foot at 8.0 m) ==")
    t0 = time.perf_counter()
    plan = plan_manipulation(model, compare=True, relocate=False)
    dt = time.perf_counter() - t0
    m = plan.metrics
    print(f"  planning + gate, both runs: {dt:.1f} s")
    print(
        f"  with avoidance:    max tracking error {m['max_tracking_error_mm']:.3f} mm, "
        f"min clearance {m['min_clearance_m']:.4f} m (required ≥ {plan.params.min_clearance_m} m, "
        f"Eq. 15 d_s = {plan.params.avoidance.d_s} m), gate {'PASS' if plan.gate.passed else 'FAIL'}"
    )
    print(
        f"  without avoidance: max tracking error {m['without_avoidance_max_tracking_error_mm']:.3f} mm, "
        f"min clearance {m['without_avoidance_min_clearance_m']:.4f} m, gate "
        f"{'PASS' if plan.comparison_gate.passed else 'FAIL'}: {plan.comparison_gate.summary()}"
    )
    print(
        f"  max tool speed {m['max_tool_speed_m_s']:.3f} m/s (§2.1: ≥ 0.3), "
        f"max joint speed / limit {m['max_joint_speed_ratio']:.3f}"
    )
    clr = plan.run.clearance
    clr0 = plan.comparison.clearance
    for t in (0.0, 2.5, 5.0, 10.0, 15.0, 20.0):
        k = round(t / plan.params.dt_s)
        print(
            f"    t = {t:4.1f} s  clearance with {clr[k]:+.3f} m, without {clr0[k]:+.3f} m, "
            f"tracking {plan.run.pos_error[k] * 1e3:.3f} mm"
        )
    deg = replace(ExperimentParams(), trajectory=Section4Trajectory(angular_unit="deg"))
    try:
        p2 = plan_manipulation(model, params=deg, relocate=False)
        print(
            f"  printed °/s reading: gate {'PASS' if p2.gate.passed else 'FAIL'}: {p2.gate.summary()}"
        )
    except Exception as exc:
        print(f"  printed °/s reading: not plannable: {exc}")
    t0 = time.perf_counter()
    cp = plan_climb(model)
    print(
        f"  seed climbing walk (S = 240 mm, H = 50 mm, Tb = 10 s, across the 10 cm gap): "
        f"{cp.metrics['phases']:.0f} phases, {time.perf_counter() - t0:.1f} s to plan + simulate, "
        f"gate {'PASS' if cp.gate.passed else 'FAIL'}"
    )
    print(
        f"    flip moment max {cp.metrics['max_flip_torque_Nm']:.1f} N·m with the counterweight, "
        f"{cp.metrics['max_flip_torque_without_counterweight_Nm']:.1f} N·m without; "
        f"magnet holds {cp.metrics['magnet_holding_moment_Nm']:.0f} N·m"
    )


def section_gait(model, quick: bool) -> None:
    length = 12.0 if quick else 30.0
    print(f"== 2. Gait planning on a {length:.0f} m random guardrail ==")
    g = make_guardrail(length, seed=5)
    p = GaitParams()
    lim = chain_limits(model, p)
    L = lim.foot_length
    xs = np.arange(g.x_min + 0.3, g.x_max - 0.5, 0.01)
    ok = g.valid_foothold(xs, L) & g.valid_foothold(xs + lim.d_work, L)
    start, goal = xs[ok][0], xs[ok][-1]
    t0 = time.perf_counter()
    moves = plan_footholds(g, start, goal, lim, p.grid_m)
    t1 = time.perf_counter()
    _phases, tr = build_trajectory(model, moves, start, p)
    t2 = time.perf_counter()
    rep = simulate_climb(model, g, tr)
    t3 = time.perf_counter()
    print(
        f"  walk {goal - start:.2f} m, {len(g.gaps)} gaps, {len(g.posts)} posts: {len(moves)} phases, "
        f"{tr.times[-1]:.0f} s of motion"
    )
    print(
        f"  footholds {t1 - t0:.3f} s, trajectories {t2 - t1:.2f} s, gate {t3 - t2:.2f} s "
        f"({rep.samples} samples, {'PASS' if rep.passed else 'FAIL: ' + rep.summary()})"
    )


def section_distance(quick: bool) -> None:
    n = 200 if quick else 1000
    print(f"== 3. Sphere–cuboid distance, {n} random pairs ==")
    rng = np.random.default_rng(0)
    boxes = [
        Cuboid(
            rng.normal(size=3),
            rng.uniform(0.05, 1.0, 3),
            Rotation.random(random_state=i).as_matrix(),
        )
        for i in range(n)
    ]
    C = rng.normal(size=(n, 3)) * 1.5
    r = rng.uniform(0.0, 0.2, n)
    t0 = time.perf_counter()
    d_gjk = np.array([sphere_box_gjk(C[i], r[i], boxes[i])[0] for i in range(n)])
    t1 = time.perf_counter()
    d_bf = np.array([sphere_box_bruteforce(C[i], r[i], boxes[i], n=41) for i in range(n)])
    t2 = time.perf_counter()
    d_ex = np.array(
        [sphere_box_exact(C[i][None], r[i : i + 1], [boxes[i]])[0][0, 0] for i in range(n)]
    )
    t3 = time.perf_counter()
    print(
        f"  GJK {1e6 * (t1 - t0) / n:.1f} µs/query, brute force {1e6 * (t2 - t1) / n:.1f} µs/query "
        f"(ratio brute/GJK {(t2 - t1) / (t1 - t0):.1f}×), closed form {1e6 * (t3 - t2) / n:.1f} µs/query"
    )
    print(
        f"  |GJK − closed form| max {np.abs(d_gjk - d_ex).max():.2e} m; "
        f"GJK − brute force ∈ [{(d_gjk - d_bf).min():.2e}, {(d_gjk - d_bf).max():.2e}] m"
    )


def _walk(model, length: float):
    """Guardrail and trajectory of the longest walk on a random guardrail."""
    g = make_guardrail(length, seed=5)
    p = GaitParams()
    lim = chain_limits(model, p)
    xs = np.arange(g.x_min + 0.3, g.x_max - 0.5, 0.01)
    ok = g.valid_foothold(xs, lim.foot_length) & g.valid_foothold(xs + lim.d_work, lim.foot_length)
    start, goal = xs[ok][0], xs[ok][-1]
    _phases, tr = build_trajectory(model, plan_footholds(g, start, goal, lim, p.grid_m), start, p)
    return g, tr


def _measure(f, *args, repeats: int = 1):
    """(report, median wall time of ``repeats`` untraced runs, peak MB of one
    run under tracemalloc).  Time and memory come from separate runs:
    tracing every allocation slows numpy-heavy code by ~30 %, so a time
    taken under it is not the time the gate takes."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        rep = f(*args)
        times.append(time.perf_counter() - t0)
    tracemalloc.start()
    f(*args)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return rep, statistics.median(times), peak / 1e6


def _same(a, b) -> bool:
    return (
        [(c.name, c.passed, c.message) for c in a.checks]
        == [(c.name, c.passed, c.message) for c in b.checks]
        and [(v.check, v.t_s, v.where) for v in a.violations]
        == [(v.check, v.t_s, v.where) for v in b.violations]
        and all(abs(c.value - d.value) <= 1e-12 for c, d in zip(a.checks, b.checks, strict=True))
    )


def section_gate(model, quick: bool) -> None:
    print("== 4. Simulation gate: dense reference vs coarse-then-fine (same run) ==")
    print("     time: median of untraced runs (3 for coarse-fine, 1 for dense); peak")
    print("     memory: one more run under tracemalloc; 'clearance evals' =")
    print("     samples evaluated by the two clearance checks (dense: 2 × samples)")
    cases = [("default climb (seed scene)", None)]
    cases.append(("12 m guardrail climb", 12.0) if not quick else ("4 m guardrail climb", 4.0))
    for label, length in cases:
        if length is None:
            cp = plan_climb(model, simulate=False)
            g, tr = cp.guardrail, cp.trajectory
        else:
            g, tr = _walk(model, length)
        ref, t_ref, m_ref = _measure(simulate_climb_dense, model, g, tr)
        new, t_new, m_new = _measure(simulate_climb, model, g, tr, repeats=3)
        ev = sum(new.clearance_samples.values())
        print(f"  {label}: {tr.times[-1]:.0f} s of motion, {new.samples} samples")
        print(f"    {'gate':<18}{'time [s]':>10}{'peak [MB]':>11}{'clearance evals':>17}")
        print(f"    {'dense (before)':<18}{t_ref:>10.2f}{m_ref:>11.0f}{2 * ref.samples:>17}")
        print(
            f"    {'coarse-fine':<18}{t_new:>10.2f}{m_new:>11.0f}{ev:>17}  {new.clearance_samples}"
        )
        print(
            f"    ratio before/after: time {t_ref / t_new:.1f}×, memory {m_ref / m_new:.1f}×, "
            f"clearance evals {2 * ref.samples / max(ev, 1):.1f}×; reports identical: "
            f"{_same(new, ref)}; verdict {'PASS' if new.passed else 'FAIL'}"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller walk and fewer distance queries")
    ap.add_argument("--gate", action="store_true", help="only section 4 (the simulation gate)")
    args = ap.parse_args()
    model = robots.load_robot("cmbot")
    if not args.gate:
        section_experiment(model)
        section_gait(model, args.quick)
        section_distance(args.quick)
    section_gate(model, args.quick)


if __name__ == "__main__":
    main()
