"""E-stop latency across two servers sharing one store.

Run on demand::

    .venv/bin/python tests/benchmarks/bench_estop_servers.py [--trials 50]

Two real ``steelpath serve`` processes on loopback share one data directory:
A runs the embedded emulators and owns every robot, B runs none.  Each trial
clears the latch, then sends ``POST /api/v1/estop`` (every robot, as the
console's button does) either to A (same server: the baseline) or to B, which
stops nothing itself and forwards to A.  The latency is the ARA emulator's
own stop instant minus the instant the request was sent (both
``time.monotonic()``, system-wide on Linux).  Same-server and cross-server
trials alternate, so both see the same machine load.  Target: every
cross-server trial under 100 ms.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from robots import ROBOT_NAMES
from tests.support.serve import ServeProcess, emulator, stop_emulators
from tests.support.waiting import wait_for


def pct(xs: list[float], q: float) -> float:
    s = sorted(xs)
    return s[min(len(s) - 1, max(0, round(q * len(s)) - 1))]


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--trials", type=int, default=50, help="E-stops per path")
    args = ap.parse_args()
    data = Path(tempfile.mkdtemp()) / "var"
    a = ServeProcess(data, "a")
    b = ServeProcess(data, "b", token=a.token, emulators="false")
    try:
        for name in ROBOT_NAMES:
            wait_for(
                lambda n=name: a.get(f"/robots/{n}/state")["state"] == "ready", 30, f"{name} up"
            )
        emu = emulator(data, "ara")
        lat: dict[str, list[float]] = {"same": [], "cross": []}
        answer: dict[str, list[float]] = {"same": [], "cross": []}
        for trial in range(2 * args.trials):
            path = "same" if trial % 2 == 0 else "cross"
            target = a if path == "same" else b
            for name in ROBOT_NAMES:
                a.post(f"/robots/{name}/clear-estop")
            n_before = len(emu.stop_events())
            t0 = time.monotonic()
            body = target.post("/estop", {"reason": f"bench {path} {trial}"})
            answer[path].append((time.monotonic() - t0) * 1e3)
            assert body["unreached"] == [], body
            stops = wait_for(lambda n=n_before: emu.stop_events()[n:], 5, "the stop record")
            stop = next(s for s in stops if s["reason"] == "estop")
            lat[path].append((stop["t"] - t0) * 1e3)
        print(f"E-stop → ARA emulator motion stop, {args.trials} trials per path (ms):")
        for path, label in (("same", "same server (A owns it)"), ("cross", "via B → A")):
            xs = lat[path]
            print(
                f"  {label:24s} median {statistics.median(xs):6.1f}  p95 {pct(xs, 0.95):6.1f}  "
                f"max {max(xs):6.1f}   (HTTP answer: median {statistics.median(answer[path]):.1f})"
            )
        ratio = statistics.median(lat["cross"]) / statistics.median(lat["same"])
        print(f"ratio cross / same (median): {ratio:.2f}")
        ok = max(lat["cross"]) < 100
        print(f"target < 100 ms on every cross-server trial: {'met' if ok else 'MISSED'}")
        return 0 if ok else 1
    finally:
        b.stop()
        a.stop()
        stop_emulators(data)


if __name__ == "__main__":
    raise SystemExit(main())
