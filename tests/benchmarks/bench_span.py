"""Whole spans through the structure model in tiles (on demand, not a test).

A long synthetic span: copies of a 5 mm TLS scan of a Warren truss
(:func:`planners.structure.synthetic.make_scan`) laid end to end along its
chords, 3 m apart (more than ``max_gap_m``: each copy is its own truss).

Parts (``--part``, repeatable):

* ``crop`` — the first ~``--crop-points`` points along the span, modelled
  whole and in tiles (``--tile-m``): member counts, how many whole-cloud
  members have a tiled member with both ends within 1 cm, and whose line
  lies within 1 cm (perpendicular offset of its ends), recall / precision
  against the truth for both, times, ratio;
* ``span`` — ``--span-points`` points in tiles through a local process pool
  of ``--workers``: time, peak RSS of this process and its children
  (sampled with psutil every 0.2 s);
* ``dask`` — the same span through a Dask LocalCluster of 1 and of 2
  worker processes: times and their ratio.

Run: ``.venv/bin/python tests/benchmarks/bench_span.py --part crop``.
"""

from __future__ import annotations

import argparse
import contextlib
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import psutil  # type: ignore[import-untyped]

from planners.structure import StructureParams, model_structure
from planners.structure.synthetic import make_scan, match_members


def span(n_points: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points, true axes, true depths) of copies of one scan, ≥ ``n_points``
    points, cropped along the span to about that many."""
    base = make_scan("warren", seed, spacing_m=0.005)
    chord = next(t for t in base.members if t.role == "chord")
    u = chord.axis[1] - chord.axis[0]
    u[2] = 0.0
    length = float(np.linalg.norm(u))
    u /= length
    copies = max(1, -(-n_points // len(base.points)))
    shift = length + 3.0
    pts = np.concatenate([base.points + k * shift * u for k in range(copies)])
    axes = np.concatenate(
        [np.array([t.axis for t in base.members]) + k * shift * u for k in range(copies)]
    )
    depths = np.tile([t.section.h for t in base.members], copies)
    t = (pts - base.points[0]) @ u
    if len(pts) > n_points:
        cut = float(np.partition(t, n_points - 1)[n_points - 1])
        pts = pts[t <= cut]
        ta = (axes - base.points[0]) @ u
        keep = ta.max(axis=1) <= cut
        axes, depths = axes[keep], depths[keep]
    return pts, axes, depths


class PeakRSS:
    """Peak resident memory of this process and its children, sampled."""

    def __init__(self, every_s: float = 0.2) -> None:
        self.peak = 0
        self._stop = threading.Event()
        self._every = every_s
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        me = psutil.Process()
        while not self._stop.is_set():
            total = me.memory_info().rss
            for c in me.children(recursive=True):
                with contextlib.suppress(psutil.Error):
                    total += c.memory_info().rss
            self.peak = max(self.peak, total)
            self._stop.wait(self._every)

    def __enter__(self) -> PeakRSS:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join()


def _timed(fn: Callable[[], Any]) -> tuple[Any, float]:
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def _agreement(whole: Any, tiled: Any) -> tuple[int, int, float]:
    """Whole-cloud members with a tiled one whose ends are within 1 cm, those
    whose line is within 1 cm, and the largest end distance."""
    ends, lines, worst = 0, 0, 0.0
    for m in whole.members:
        best_end, best_line = np.inf, np.inf
        for n in tiled.members:
            a, b = m.axis, n.axis
            e = min(
                float(np.linalg.norm(a - b, axis=1).max()),
                float(np.linalg.norm(a - b[::-1], axis=1).max()),
            )
            best_end = min(best_end, e)
            if abs(float(m.direction @ n.direction)) > np.cos(np.radians(1.0)):
                rel = a - b[0]
                off = rel - np.outer(rel @ n.direction, n.direction)
                best_line = min(best_line, float(np.linalg.norm(off, axis=1).max()))
        ends += best_end <= 0.01
        lines += best_line <= 0.01
        worst = max(worst, best_end)
    return ends, lines, worst


def part_crop(args: argparse.Namespace) -> None:
    pts, axes, depths = span(args.crop_points)
    print(f"crop: {len(pts):,} points, {len(axes)} true members")
    whole, t_whole = _timed(lambda: model_structure(pts))
    prm = StructureParams(tile_above_points=10, tile_m=args.tile_m, overlap_m=args.overlap_m)
    tiled, t_tiled = _timed(lambda: model_structure(pts, params=prm))
    ends, lines, worst = _agreement(whole, tiled)
    mw = match_members(axes, depths, np.array([m.axis for m in whole.members]).reshape(-1, 2, 3))
    mt = match_members(axes, depths, np.array([m.axis for m in tiled.members]).reshape(-1, 2, 3))
    print(
        f"  whole: {len(whole.members)} members, {t_whole:.1f} s, "
        f"recall {mw.recall:.3f} precision {mw.precision:.3f}"
    )
    print(
        f"  tiled ({int(tiled.params['n_tiles'])} tiles of {args.tile_m} m, overlap "
        f"{args.overlap_m} m): {len(tiled.members)} members, {t_tiled:.1f} s "
        f"(x{t_tiled / t_whole:.2f}), recall {mt.recall:.3f} precision {mt.precision:.3f}"
    )
    print(
        f"  agreement: {ends}/{len(whole.members)} with both ends within 1 cm, "
        f"{lines}/{len(whole.members)} on a line within 1 cm; largest end distance "
        f"{worst * 100:.1f} cm"
    )


def part_span(args: argparse.Namespace) -> None:
    from server.structure_tiles import pool_mapper

    pts, axes, depths = span(args.span_points)
    print(f"span: {len(pts):,} points, {len(axes)} true members")
    with PeakRSS() as rss:
        model, t = _timed(
            lambda: model_structure(pts, mapper=pool_mapper(args.workers, args.workers + 1))
        )
    m = match_members(axes, depths, np.array([x.axis for x in model.members]).reshape(-1, 2, 3))
    print(
        f"  {int(model.params['n_tiles'])} tiles, {args.workers} pool workers: {t:.1f} s "
        f"({t / 300:.2f} of 5 min), peak RSS {rss.peak / 2**30:.2f} GiB "
        f"({rss.peak / 2**32:.2f} of 4 GiB); {len(model.members)} members, "
        f"recall {m.recall:.3f} precision {m.precision:.3f}"
    )


def part_dask(args: argparse.Namespace) -> None:
    import distributed

    from server.structure_tiles import dask_mapper

    pts, _, _ = span(args.span_points)
    times: dict[int, float] = {}

    def run(client: Any) -> Any:
        return model_structure(pts, mapper=dask_mapper(client))

    for n in (1, 2):
        with (
            distributed.LocalCluster(
                n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None
            ) as cluster,
            distributed.Client(cluster) as client,
        ):
            _, times[n] = _timed(lambda: run(client))
        print(f"  dask, {n} worker(s): {times[n]:.1f} s")
    print(f"  speed-up 2 vs 1 workers: x{times[1] / times[2]:.2f} (target 1.6)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--part", action="append", choices=["crop", "span", "dask"])
    ap.add_argument("--crop-points", type=int, default=2_000_000)
    ap.add_argument("--span-points", type=int, default=20_000_000)
    ap.add_argument("--tile-m", type=float, default=15.0)
    ap.add_argument("--overlap-m", type=float, default=5.0)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    for part in args.part or ["crop"]:
        {"crop": part_crop, "span": part_span, "dask": part_dask}[part](args)


if __name__ == "__main__":
    main()
