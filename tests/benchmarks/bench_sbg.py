"""Box-girder climber benchmark (seed 003 §4), run on demand:

    .venv/bin/python tests/benchmarks/bench_sbg.py [--seeds 8] [--quick] [--json out.json]

Prints, beside the seed's figures:
- Fig. 12: pitch while crossing a corner, Eq. 4 as printed vs the smooth
  profile (pitch-rate jumps at the stage boundaries);
- Fig. 14: Lx = 20 mm vs the baseline Lx = 0 over several seeds;
- the Lx sweep and the best Lx under the stated noise model;
- §4.3: yaw on reaching the roof after each U-turn, IMU yaw during turns
  (the seed's choice) vs the baseline encoder-only yaw (Eq. 11) and IMU
  throughout;
- whole-girder runs: checks, worst camera margin, final deviations and the
  wall-clock simulation time.
Everything comes from the simulator in this run; nothing is stored.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from planners.sbg import ControllerConfig, NoiseModel, plan_inspection, sample_girders
from planners.sbg import experiments as ex

DEG = math.pi / 180


def fmt(v: float, nd: int = 3) -> str:
    return "inf" if not math.isfinite(v) else f"{v:.{nd}f}"


def bench_fig12(out: dict) -> None:
    print("\n== Fig. 12: pitch while crossing a 90° concave corner (noise-free) ==")
    print("seed: 'the curve slope does not have an abrupt change'")
    figs = ex.fig12_pitch()
    print(
        f"{'profile':8} {'Δθ Eq.1':>8} {'time s':>7} {'max rate':>9} {'max jump':>9} {'max acc':>9}  jumps at lift/climb/landing (deg/s)"
    )
    for name, f in figs.items():
        j = f.boundary_jumps_deg_s
        print(
            f"{name:8} {math.degrees(f.delta_theta_rad):8.3f} {f.duration_s:7.2f} {f.max_rate_deg_s:9.2f} "
            f"{f.max_rate_jump_deg_s:9.3f} {f.max_accel_deg_s2:9.2f}  "
            f"{j['lift_start']:.3f} / {j['climb_start']:.3f} / {j['landing']:.3f}"
        )
        out.setdefault("fig12", {})[name] = {
            "delta_theta_deg": math.degrees(f.delta_theta_rad),
            "duration_s": f.duration_s,
            "max_rate_deg_s": f.max_rate_deg_s,
            "max_rate_jump_deg_s": f.max_rate_jump_deg_s,
            "max_accel_deg_s2": f.max_accel_deg_s2,
            "boundary_jumps_deg_s": j,
        }
    print("(rate jump = change of dθ/dt between consecutive 50 ms samples)")


def bench_fig14(seeds: list[int], out: dict) -> None:
    print(
        "\n== Fig. 14: centreline tracking from d0 = 10 mm, δ0 = 2° (Eq. 5–9 as printed, no yaw cap) =="
    )
    print("seed: Lx = 20 mm → final d 0.33 mm, δ 0.06°; Lx = 0 converges more slowly")
    rows = {}
    for lx in (0.020, 0.0):
        runs = [ex.fig14_tracking(preview_m=lx, seed=s) for s in seeds]
        st = np.array([r.settle_time_s for r in runs])
        sd = np.array([r.settle_distance_m for r in runs])
        fd = np.abs([r.final_d_m for r in runs]) * 1e3
        fa = np.degrees(np.abs([r.final_delta_rad for r in runs]))
        fin = np.mean([r.finished for r in runs])
        rows[lx] = st
        print(
            f"Lx = {lx * 1e3:4.0f} mm: lane finished {fin:.0%}; |d| < 1 mm after {fmt(st.mean(), 1)} s (max {fmt(st.max(), 1)}), "
            f"{fmt(sd.mean() * 1e3, 0)} mm along; final |d| mean {fd.mean():.3f} max {fd.max():.3f} mm, "
            f"|δ| mean {fa.mean():.3f} max {fa.max():.3f}°"
        )
        out.setdefault("fig14", {})[f"{lx * 1e3:.0f}mm"] = {
            "finished_fraction": float(fin),
            "settle_time_mean_s": float(st.mean()),
            "settle_time_max_s": float(st.max()),
            "settle_distance_mean_m": float(sd.mean()),
            "final_d_mean_mm": float(fd.mean()),
            "final_d_max_mm": float(fd.max()),
            "final_delta_mean_deg": float(fa.mean()),
            "final_delta_max_deg": float(fa.max()),
        }
    r = rows[0.0].mean() / rows[0.020].mean()
    print(f"baseline ratio: settling time Lx=0 / Lx=20 mm = {fmt(r, 2)}")


def bench_sweep(seeds: list[int], values: list[float], out: dict) -> None:
    print("\n== Lx sweep (Fig. 14 set-up, stated noise model) ==")
    t0 = time.perf_counter()
    sw = ex.lx_sweep(values, seeds)
    wall = time.perf_counter() - t0
    print(
        f"{'Lx mm':>6} {'done':>5} {'settle s':>9} {'max s':>7} {'settle mm':>9} {'|d| mean':>9} {'|d| max':>8} {'|δ| mean°':>9} {'|δ| max°':>8} {'episodes':>8}"
    )
    rows = []
    for r in sw.rows:
        print(
            f"{r.preview_m * 1e3:6.0f} {r.finished_fraction:5.0%} {fmt(r.settle_time_mean_s, 1):>9} {fmt(r.settle_time_max_s, 1):>7} "
            f"{fmt(r.settle_distance_mean_m * 1e3, 0):>9} {r.final_d_mean_m * 1e3:9.3f} {r.final_d_max_m * 1e3:8.3f} "
            f"{math.degrees(r.final_delta_mean_rad):9.3f} {math.degrees(r.final_delta_max_rad):8.3f} {r.episodes_mean:8.1f}"
        )
        rows.append({k: getattr(r, k) for k in r.__dataclass_fields__})
    best = sw.best_preview_m
    print(
        f"best Lx (shortest mean settling time, all runs finish, mean finals within 0.33 mm / 0.06°): "
        f"{'none' if best is None else f'{best * 1e3:.0f} mm'} (seed: 20 mm); {len(sw.runs)} runs in {wall:.1f} s"
    )
    out["lx_sweep"] = {"rows": rows, "best_preview_m": best, "seeds": seeds}


def bench_girder(seeds: list[int], out: dict, girders: list[str]) -> None:
    print("\n== Whole girder: §4.3 U-turn yaw, checks, camera margin, run time ==")
    print("seed §4.3: yaw deviation on reaching the roof < 0.1°")
    for gname in girders:
        g = sample_girders()[gname]
        res = {}
        for mode in ("imu_turns", "encoder", "imu"):
            sims, plans, wall = [], [], 0.0
            for s in seeds:
                t0 = time.perf_counter()
                p = plan_inspection(g, seed=s, config=ControllerConfig(dr_yaw=mode))
                wall += time.perf_counter() - t0
                plans.append(p)
                sims.append(p.sim)
            st = ex.uturn_yaw_stats(sims)
            passed = np.mean([p.passed for p in plans])
            margin = min(p.metrics["worst_camera_margin_mm"] for p in plans)
            fd = max(p.metrics["max_final_d_mm"] for p in plans)
            fa = max(p.metrics["max_final_delta_deg"] for p in plans)
            clear = min(p.metrics["min_rib_clearance_mm"] for p in plans)
            dur = np.mean([p.sim.duration_s for p in plans])
            res[mode] = st
            label = {
                "imu_turns": "IMU yaw in turns (seed)",
                "encoder": "encoder-only yaw (baseline)",
                "imu": "IMU yaw throughout",
            }[mode]
            print(
                f"[{gname}, {g.n_lanes} lanes] {label:28}: |yaw| at roof mean {st['yaw_mean_deg']:.3f} rms {st['yaw_rms_deg']:.3f} "
                f"max {st['yaw_max_deg']:.3f}°, under 0.1° {st['yaw_under_0p1_fraction']:.0%} of {st['n']:.0f}; "
                f"entry offset rms {st['entry_offset_rms_mm']:.2f} max {st['entry_offset_max_mm']:.2f} mm"
            )
            print(
                f"    plans passing all checks {passed:.0%}; worst camera margin {margin:.1f} mm; min rib clearance {clear:.1f} mm; "
                f"max final |d| {fd:.3f} mm, |δ| {fa:.3f}°; simulated {dur:.0f} s per run, wall {wall / len(seeds):.2f} s per run "
                f"({dur / (wall / len(seeds)):.0f}× real time)"
            )
            out.setdefault("girder", {}).setdefault(gname, {})[mode] = {
                **st,
                "plans_passing": float(passed),
                "worst_camera_margin_mm": margin,
                "min_rib_clearance_mm": clear,
                "max_final_d_mm": fd,
                "max_final_delta_deg": fa,
                "simulated_s_per_run": float(dur),
                "wall_s_per_run": wall / len(seeds),
            }
        ratio = res["encoder"]["yaw_rms_deg"] / res["imu_turns"]["yaw_rms_deg"]
        print(f"    baseline ratio: yaw RMS encoder-only / IMU-in-turns = {ratio:.0f}×")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument(
        "--quick", action="store_true", help="fewer Lx values and only the seed_lab girder"
    )
    ap.add_argument("--json", type=Path, default=None, help="also write the numbers to this file")
    args = ap.parse_args()
    seeds = list(range(args.seeds))
    values = (
        [0.0, 0.01, 0.02, 0.04, 0.08]
        if args.quick
        else [0.0, 0.005, 0.01, 0.015, 0.02, 0.03, 0.04, 0.06, 0.08, 0.12, 0.16]
    )
    girders = ["seed_lab"] if args.quick else ["seed_lab", "deck_bay"]
    print(f"noise model: {NoiseModel()}")
    print(f"controller: {ControllerConfig()}")
    out: dict = {"seeds": seeds}
    t0 = time.perf_counter()
    bench_fig12(out)
    bench_fig14(seeds, out)
    bench_sweep(seeds, values, out)
    bench_girder(seeds, out, girders)
    print(f"\ntotal {time.perf_counter() - t0:.1f} s")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1, default=float))


if __name__ == "__main__":
    main()
