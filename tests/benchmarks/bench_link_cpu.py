"""Host CPU per streamed command on one robot link, before/after.

Run on demand::

    .venv/bin/python tests/benchmarks/bench_link_cpu.py [--commands 1000] [--time-scale 20]
        [--repeats 3]

A built-in emulator (``python -m robots.emulator``, its own process, so its
CPU is not counted) runs a generic 6-joint robot at ``--time-scale``; this
process holds one :class:`~robots.adapters.RobotLink` and streams a program of
``--commands`` 0.1 s joint way-points with a
:class:`~robots.adapters.Streamer`.  The figure is this process's CPU time
(``time.process_time``: the link's I/O thread and the streamer) from the
first command to completion, per command and as a share of a core.

Baseline, measured in the same run: the read the link used before, pyserial's
``port.read(1)`` then ``port.read(port.in_waiting)`` (on a ``socket://``
port ``in_waiting`` answers 0 or 1, so a frame came in two bytes per pass of
the I/O loop), patched into ``robots.adapters.link_io``.  Prints the ratio
before / after.  The link service runs one such link per robot, at nice −5:
every millisecond here is taken from the web server under load.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import robots.adapters.link_io as link_io  # noqa: E402
from robots.adapters import ExecState, RobotLink, Streamer  # noqa: E402
from robots.adapters.link_types import LinkConfig, _read_port  # noqa: E402
from robots.protocol import JointMove, Program  # noqa: E402


def pyserial_read(port: Any, sock: Any, timeout_s: float) -> bytes:
    """The link's former read on every port (the baseline): the port's own path."""
    return _read_port(port)


def stream_once(url: str, secret: bytes, n: int) -> tuple[float, float, str]:
    """(CPU s, wall s, final state) for streaming ``n`` way-points over a fresh link."""
    prog = Program(tuple(JointMove(q_rad=(0.01 * (i % 50),) * 6, duration_s=0.1) for i in range(n)))
    with RobotLink(url, LinkConfig(secret=secret)) as link:
        deadline = time.monotonic() + 20
        while not link.connected:
            if time.monotonic() > deadline:
                raise RuntimeError(f"no link to {url} within 20 s: {link.status().reason}")
            time.sleep(0.05)
        c0, w0 = time.process_time(), time.monotonic()
        with Streamer(prog, link, run_id=int(time.time()) & 0x7FFF) as s:
            state = s.wait(timeout=600)
        c1, w1 = time.process_time(), time.monotonic()
    return c1 - c0, w1 - w0, str(state.value if isinstance(state, ExecState) else state)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--commands", type=int, default=1000)
    ap.add_argument("--time-scale", type=float, default=20.0)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    if args.commands < 1 or args.repeats < 1 or args.time_scale <= 0:
        ap.error("--commands and --repeats must be at least 1, --time-scale positive")
    tmp = Path(tempfile.mkdtemp(prefix="bench_link_cpu-"))
    secret_file, port_file = tmp / "secret", tmp / "port.json"
    emu = subprocess.Popen(
        [sys.executable, "-m", "robots.emulator", "--robot", "generic"]
        + ["--listen", "tcp://127.0.0.1:0", "--time-scale", str(args.time_scale)]
        + ["--secret-file", str(secret_file), "--port-file", str(port_file)],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 30
        while not port_file.exists():
            if emu.poll() is not None or time.monotonic() > deadline:
                print("the emulator did not start", file=sys.stderr)
                return 2
            time.sleep(0.05)
        url = json.loads(port_file.read_text())["url"]
        secret = bytes.fromhex(secret_file.read_text().strip())
        after_read = link_io._read_some
        rows: dict[str, list[tuple[float, float, str]]] = {"before": [], "after": []}
        for _ in range(args.repeats):  # interleaved, so drift hits both alike
            for label, read in (("before", pyserial_read), ("after", after_read)):
                link_io._read_some = read
                try:
                    rows[label].append(stream_once(url, secret, args.commands))
                finally:
                    link_io._read_some = after_read
    finally:
        emu.terminate()
        emu.wait(10)
    print(
        f"bench_link_cpu: {args.commands} joint way-points of 0.1 s at time scale "
        f"{args.time_scale:g} ({args.commands * 0.1 / args.time_scale:.1f} s of wall time), "
        f"{args.repeats} runs each, interleaved"
    )
    print(f"{'read':<8}{'ms CPU/command':>16}{'% of a core':>13}  states")
    med: dict[str, float] = {}
    for label, runs in rows.items():
        per_cmd = [c / args.commands * 1e3 for c, _, _ in runs]
        share = [c / w * 100 for c, w, _ in runs]
        med[label] = statistics.median(per_cmd)
        states = ",".join(sorted({s for _, _, s in runs}))
        print(f"{label:<8}{med[label]:>16.2f}{statistics.median(share):>13.0f}  {states}")
    print(f"ratio before/after: {med['before'] / med['after']:.1f}x less host CPU per command")
    ok = all(s == ExecState.COMPLETED.value for runs in rows.values() for _, _, s in runs)
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
