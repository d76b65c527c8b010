"""Benchmark: a 250 MB cloud upload against a served SteelPath.

Starts ``steelpath serve`` (own data dir, loopback port, no emulators, no
scene), measures ``/health`` latency quiet, then uploads a generated file
(XYZ text by default, ``--format ply`` for binary PLY) while polling
``/health`` at 20 Hz and sampling memory from /proc: the server's resident
set growth over its quiet size and the upload parser child's peak
(``VmHWM``).  Prints the peak (server growth + parser) as a ratio to the file
size beside the bound 2 × size + 200 MB, and /health latency during the
upload as a ratio to the quiet figure measured in the same run.

    .venv/bin/python tests/benchmarks/bench_upload.py [--mb 250] [--format xyz|ply]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx
import numpy as np


def _kb(pid: int, key: str) -> int:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith(key + ":"):
                return int(line.split()[1])
    except OSError:
        pass
    return 0


def _children(pid: int) -> list[int]:
    out: list[int] = []
    for task in Path(f"/proc/{pid}/task").glob("*/children"):
        with contextlib.suppress(OSError):
            out += [int(c) for c in task.read_text().split()]
    return out


def make_file(path: Path, mb: int, fmt: str) -> None:
    rng = np.random.default_rng(0)
    target = mb * 2**20
    with open(path, "wb") as fh:
        if fmt == "ply":
            n = target // 12
            fh.write(
                f"ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\n"
                "property float y\nproperty float z\nend_header\n".encode()
            )
            block = 1 << 20
            for start in range(0, n, block):
                fh.write(rng.normal(size=(min(block, n - start), 3)).astype("<f4").tobytes())
        else:
            rows = rng.normal(size=(100_000, 3)) * 10
            text = "".join(f"{a:.4f} {b:.4f} {c:.4f}\n" for a, b, c in rows).encode()
            while fh.tell() < target:
                fh.write(text)


def pct(values: list[float], q: float) -> float:
    s = sorted(values)
    return s[min(len(s) - 1, int(q * len(s)))] if s else float("nan")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mb", type=int, default=250, help="size of the generated file (MiB)")
    ap.add_argument("--format", choices=("xyz", "ply"), default="xyz")
    args = ap.parse_args()

    tmp = Path(tempfile.mkdtemp(prefix="bench-upload-"))
    src = tmp / f"cloud.{args.format}"
    print(f"generating {args.mb} MiB {args.format} ...", flush=True)
    make_file(src, args.mb, args.format)
    size = src.stat().st_size
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = {
        **os.environ,
        "STEELPATH_DATA": str(tmp / "var"),
        "STEELPATH_PORT": str(port),
        "STEELPATH_SCENE_PORT": "0",
        "STEELPATH_EMULATORS": "false",
        "STEELPATH_MAX_UPLOAD_MB": str(args.mb + 64),
        "STEELPATH_TOKEN_FILE": str(tmp / "admin.token"),
        "STEELPATH_LOG_LEVEL": "warning",
    }
    exe = Path(sys.executable).with_name("steelpath")
    server = subprocess.Popen([str(exe), "serve"], env=env, stderr=subprocess.DEVNULL)
    base = f"http://127.0.0.1:{port}/api/v1"
    try:
        client = httpx.Client(timeout=120)
        deadline = time.monotonic() + 120
        while True:
            try:
                if client.get(f"{base}/health").status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            if time.monotonic() > deadline or server.poll() is not None:
                raise SystemExit("server did not start")
            time.sleep(0.2)
        auth = {"Authorization": f"Bearer {(tmp / 'admin.token').read_text().strip()}"}

        def health_once() -> float:
            t0 = time.perf_counter()
            client.get(f"{base}/health").raise_for_status()
            return (time.perf_counter() - t0) * 1000

        quiet = [health_once() for _ in range(60)]
        rss0 = _kb(server.pid, "VmRSS")
        result: dict = {}

        def upload() -> None:
            t0 = time.perf_counter()
            with open(src, "rb") as fh, httpx.Client(timeout=1800) as up:
                result["r"] = up.post(
                    f"{base}/clouds", files={"file": (src.name, fh)}, headers=auth
                )
            result["s"] = time.perf_counter() - t0

        t = threading.Thread(target=upload)
        busy: list[float] = []
        server_peak = parser_peak = 0
        t.start()
        while t.is_alive():
            busy.append(health_once())
            server_peak = max(server_peak, _kb(server.pid, "VmRSS"))
            for c in _children(server.pid):
                with contextlib.suppress(OSError):
                    if b"server.cloud_io" in Path(f"/proc/{c}/cmdline").read_bytes():
                        parser_peak = max(parser_peak, _kb(c, "VmHWM"))
            time.sleep(0.05)
        t.join()
        r = result["r"]
        if r.status_code != 201:
            raise SystemExit(f"upload failed: {r.status_code} {r.text[:300]}")
        peak = (server_peak - rss0 + parser_peak) * 1024
        bound = 2 * size + 200 * 2**20
        mib = 2**20
        print(f"file: {size / mib:.0f} MiB {args.format}, {r.json()['n_points']} points, "
              f"upload+parse {result['s']:.1f} s")  # fmt: skip
        print(f"memory: server growth {(server_peak - rss0) / 1024:.0f} MiB + parser peak "
              f"{parser_peak / 1024:.0f} MiB = {peak / mib:.0f} MiB = {peak / size:.2f} x file size "
              f"(bound 2 x size + 200 MiB = {bound / mib:.0f} MiB: "
              f"{'within' if peak <= bound else 'EXCEEDED'})")  # fmt: skip
        q50, q95 = statistics.median(quiet), pct(quiet, 0.95)
        b50, b95, bmax = statistics.median(busy), pct(busy, 0.95), max(busy)
        print(f"/health quiet:  median {q50:.1f} ms, p95 {q95:.1f} ms ({len(quiet)} requests)")
        print(f"/health upload: median {b50:.1f} ms, p95 {b95:.1f} ms, max {bmax:.1f} ms "
              f"({len(busy)} requests) = {b50 / q50:.1f}x / {b95 / q95:.1f}x quiet")  # fmt: skip
        return 0
    finally:
        server.terminate()
        try:
            server.wait(15)
        except subprocess.TimeoutExpired:
            server.kill()
            server.wait()
        import shutil

        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
