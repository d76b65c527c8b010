"""``steelpath emulate``: run one robot emulator until interrupted.

    steelpath emulate --robot denso_vm6083 --listen tcp://127.0.0.1:5000 [--pty]
        [--time-scale 1] [--drop-after N] [--corrupt-rate R] [--delay S]
        [--nak-index I] [--fault-at-index I] ...

Prints the endpoints it serves (``socket://…`` and the pty path), one per line,
then runs until SIGINT/SIGTERM (or, with ``--exit-when-orphaned``, until no
controller has been connected for that long), saving ``--state-file`` on the
way out.  ``python -m robots.emulator`` is the same.

``--secret-file PATH`` is the robot's link secret (64 hex characters, mode
0600; created when missing — :func:`robots.protocol.auth.load_or_create_secret`):
only a host with the same secret can command the emulator.  Without it the
emulator makes up a random secret it tells nobody, so nobody can control it.

``--world PATH`` is what the robot's camera sees: an ``.npz`` with ``points``
(N, 3) float32 in the program's world frame and optionally ``intensity`` (N,)
uint8, at most 20 M points, reloaded whenever the file changes
(:mod:`robots.emulator.camera`).  Without it, or while the file is missing,
a ``capture`` command sends a frame of 0 points and the log says why.
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
import threading

from robots.background_io import log_through_a_queue
from robots.emulator.faults import FaultConfig
from robots.emulator.server import Emulator, parse_listen

log = logging.getLogger(__name__)


def build_parser(prog: str = "steelpath emulate") -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=prog, description="Robot emulator speaking the SteelPath protocol (docs/protocol.md)."
    )
    p.add_argument(
        "--robot", default="generic", help="robot name (ara, cmbot, denso_vm6083, sbg_climber)"
    )
    p.add_argument(
        "--listen",
        default=None,
        help="TCP endpoint tcp://HOST:PORT (port 0: any free port); default tcp://127.0.0.1:0 "
        "unless --pty is given alone",
    )
    p.add_argument(
        "--pty", action="store_true", help="also serve a pseudo-terminal (serial device)"
    )
    p.add_argument(
        "--time-scale", type=float, default=1.0, help="simulated seconds per wall second"
    )
    p.add_argument(
        "--nice",
        type=int,
        default=0,
        help="change the process priority by this much (os.nice; below 0 needs root): "
        "0 shares the CPU with the host fairly, < 0 runs the emulator ahead of it",
    )
    p.add_argument("--state-period", type=float, default=0.1, help="state report period, s")
    p.add_argument("--buffer", type=int, default=16, help="command buffer capacity")
    p.add_argument("--log-jsonl", default=None, help="append every executed command to this file")
    p.add_argument(
        "--secret-file",
        default=None,
        metavar="PATH",
        help="the robot's link secret (64 hex chars, mode 0600; created if missing); "
        "without it a random secret is used and no host can control the emulator",
    )
    c = p.add_argument_group("camera")
    c.add_argument(
        "--world",
        default=None,
        metavar="PATH",
        help="point cloud the camera sees: .npz with points (N,3) float32 in the program's "
        "world frame [and intensity (N,) uint8]; reloaded when it changes",
    )
    c.add_argument("--camera-seed", type=int, default=0, help="seed of the range noise")
    s = p.add_argument_group("surviving the server")
    s.add_argument(
        "--state-file",
        default=None,
        metavar="PATH",
        help="load the robot's state (pose, odometry, progress) from PATH at start if it "
        "exists; save it atomically whenever the robot comes to rest and on exit",
    )
    s.add_argument(
        "--port-file",
        default=None,
        metavar="PATH",
        help='after binding, write {"pid", "url", "robot"} to PATH (removed on exit)',
    )
    s.add_argument(
        "--exit-when-orphaned",
        type=float,
        default=None,
        metavar="SECONDS",
        help="exit (saving state) after SECONDS with no controller connected and nothing "
        "executing; default: never",
    )
    f = p.add_argument_group("fault injection")
    f.add_argument(
        "--drop-after",
        type=int,
        default=None,
        metavar="N",
        help="drop the link after N frames received on a connection",
    )
    f.add_argument("--drop-times", type=int, default=1, help="how many connections to drop")
    f.add_argument("--drop-mode", choices=("auto", "close", "silence"), default="auto")
    f.add_argument("--drop-for", type=float, default=1.0, metavar="S", help="silence length, s")
    f.add_argument(
        "--corrupt-rate",
        type=float,
        default=0.0,
        metavar="R",
        help="probability each byte is corrupted",
    )
    f.add_argument("--corrupt-direction", choices=("rx", "tx", "both"), default="both")
    f.add_argument("--delay", type=float, default=0.0, metavar="S", help="delay every frame by S s")
    f.add_argument("--delay-direction", choices=("rx", "tx", "both"), default="both")
    f.add_argument("--nak-index", type=int, default=None, metavar="I", help="NAK command index I")
    f.add_argument("--nak-times", type=int, default=1)
    f.add_argument("--nak-permanent", action="store_true", help="refuse (INVALID) instead of BUSY")
    f.add_argument(
        "--fault-at-index",
        type=int,
        default=None,
        metavar="I",
        help="raise a robot fault halfway through command I",
    )
    f.add_argument("--fault-code", type=int, default=1)
    f.add_argument("--seed", type=int, default=0, help="seed of the corruption RNG")
    return p


#: Signals that stop the emulator, taken synchronously by the main thread.
STOP_SIGNALS = frozenset({signal.SIGINT, signal.SIGTERM})


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``steelpath emulate``; returns the exit status."""
    args = build_parser().parse_args(argv)
    # Blocked before any thread starts (threads inherit the mask) and taken
    # with sigtimedwait: a handler calling Event.set() can deadlock on the lock
    # the main thread holds inside its own Event.wait().
    in_main = threading.current_thread() is threading.main_thread()
    old_mask = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS) if in_main else None
    try:
        return _run(args, in_main)
    finally:
        if old_mask is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)


def _run(args: argparse.Namespace, in_main: bool) -> int:
    listen = args.listen
    stop = threading.Event()  # set by SIGINT/SIGTERM, or when the emulator is orphaned
    if listen is None and not args.pty:
        listen = "tcp://127.0.0.1:0"
    try:
        if listen is not None:
            parse_listen(listen)
        faults = FaultConfig(
            drop_after_frames=args.drop_after,
            drop_times=args.drop_times,
            drop_mode=args.drop_mode,
            drop_for_s=args.drop_for,
            corrupt_rate=args.corrupt_rate,
            corrupt_direction=args.corrupt_direction,
            delay_s=args.delay,
            delay_direction=args.delay_direction,
            nak_index=args.nak_index,
            nak_times=args.nak_times,
            nak_permanent=args.nak_permanent,
            fault_at_index=args.fault_at_index,
            fault_code=args.fault_code,
            seed=args.seed,
        )
        emu = Emulator(
            args.robot,
            faults=faults,
            listen=listen,
            pty=args.pty,
            time_scale=args.time_scale,
            state_period_s=args.state_period,
            buffer_capacity=args.buffer,
            log_path=args.log_jsonl,
            secret=_secret(args.secret_file),
            state_file=args.state_file,
            port_file=args.port_file,
            exit_when_orphaned_s=args.exit_when_orphaned,
            on_orphaned=stop.set,
            world=args.world,
            camera_seed=args.camera_seed,
        )
    except ValueError as exc:
        print(f"steelpath emulate: {exc}", file=sys.stderr)
        return 2
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(message)s")
    log_through_a_queue()
    # The emulator plays a robot's own controller, which shares no CPU with
    # the host.  Neither priority is faithful on one machine: ahead of the host
    # (< 0) it takes CPU the web server would have had on real hardware (at a
    # time scale of 10, ten times a real robot's command rate); level with it,
    # the host's load can delay the robot.  Level is the default.
    if args.nice:
        try:
            os.nice(args.nice)
        except OSError:
            log.warning("cannot change the emulator's priority by %d (needs root)", args.nice)
    try:
        emu.start()
    except OSError as exc:
        print(f"steelpath emulate: cannot listen on {listen}: {exc}", file=sys.stderr)
        return 1
    try:
        p = emu.profile
        print(f"robot {p.name}: {p.n_joints} joints (limits from {p.source})", flush=True)
        if args.world is not None:
            w = emu.world
            what = (
                f"{len(w.cloud)} points"
                if w is not None and w.cloud is not None
                else "no such file yet"
            )
            print(f"world {args.world}: {what}", flush=True)
        if listen is not None:
            print(f"listening on {emu.url}", flush=True)
        if args.pty:
            print(f"pty {emu.pty_path}", flush=True)
        while not stop.is_set():
            if in_main:
                if signal.sigtimedwait(STOP_SIGNALS, 0.5) is not None:
                    break
            else:
                stop.wait(0.5)
    finally:
        emu.close()
    return 0


def _secret(path: str | None) -> bytes | None:
    """The secret from ``--secret-file`` (SecretFileError is a ValueError: exit 2)."""
    if path is None:
        print(
            "steelpath emulate: no --secret-file: using a random secret, "
            "so no host can control this emulator",
            file=sys.stderr,
        )
        return None
    from robots.protocol.auth import load_or_create_secret

    try:
        return load_or_create_secret(path)
    except OSError as exc:
        raise ValueError(f"--secret-file {path}: {exc}") from exc


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
