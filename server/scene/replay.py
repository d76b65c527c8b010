"""Replay of a recorded run: its timeline, and the robot's
recorded state shown in the scene at a chosen time.

Everything comes from stored rows: the state reports mirrored while the run
was active (``Store.execution_states``, about 2 Hz), the acknowledgement
times (``Store.ack_times``) and the audit trail of the execution and its
plan.  Times in the timeline are seconds after the execution was created
(``ExecutionRecord.created_at``, the start the MCAP export uses too).

In the scene the *replay robot* is a URDF of the execution's robot tinted
blue (the live one is orange), named ``<planned robot node>/replay``
(``/plan/robot/replay`` for most drawers) so that, like the live robot, it
rides on the planned robot's base: a state report holds joints and wheel
odometry but no base pose, so the replay places what the live robot places
— the reported ``q_rad`` — linearly interpolated between the two reports
around ``t``, while the planned robot (and the plan's other animations)
stands where the plan was at ``t`` by the acknowledgements (within a
command, in proportion to the time between its neighbours' acks).

What the robot's camera saw (:mod:`server.captures`) is on the timeline too
(``captures``: each at the time the host received it), and the replay shows
the latest capture received at or before ``t`` over the model
(:func:`server.scene.captures.show_at`).
"""

from __future__ import annotations

import bisect
import functools
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from server.captures.store import CaptureStore
from server.recording.channels import iso_ns, robot_frames
from server.scene import captures as scene_captures

if TYPE_CHECKING:
    from server.recording.channels import RobotFrames
    from server.scene.service import SceneService
    from server.store import Store

#: At most this many state samples are returned (every ``stride``-th above it).
MAX_SAMPLES = 20_000
#: Replay robot colour (RGBA): blue, unlike the orange live robot.
REPLAY_RGBA = (0.15, 0.45, 1.0, 0.7)
#: Execution states a finished run ends in.
FINISHED = ("completed", "aborted", "faulted", "interrupted")


class ReplayError(Exception):
    """The replay cannot be shown (HTTP 409 with this message)."""


def _secs(ts: str) -> float:
    return iso_ns(ts) / 1e9


def timeline(store: Store, execution_id: str, max_samples: int = MAX_SAMPLES) -> dict[str, Any]:
    """The recorded run of ``execution_id`` (``NotFoundError`` if unknown).

    ``samples``: the stored state reports with ``t_s`` after the start; above
    ``max_samples`` every ``stride``-th is kept, and the last (``thinning``
    says so).  ``acks``: each acknowledged command (index, op, ``t_s``), in
    index order.  ``operator``: the audit events of the execution and of its
    plan, in time order (``t_s`` may be negative: the approval came before).
    """
    ex = store.get_execution(execution_id)
    plan = store.get_plan(ex.plan_id)
    program = list(plan.program or [])
    start = _secs(ex.created_at)
    states = store.execution_states(ex.id)
    stride = max(1, math.ceil(len(states) / max(1, max_samples)))
    kept = list(range(0, len(states), stride))
    if states and kept[-1] != len(states) - 1:
        if len(kept) >= max_samples:
            kept[-1] = len(states) - 1
        else:
            kept.append(len(states) - 1)
    samples = [{"t_s": states[i][0] - start, "state": states[i][1]} for i in kept]
    acks = []
    for idx, ts in store.ack_times(ex.id):
        cmd = program[idx] if 0 <= idx < len(program) else {}
        acks.append({"index": idx, "op": cmd.get("op"), "ts": ts, "t_s": _secs(ts) - start})
    audit = store.list_audit("execution", ex.id, limit=10_000) + store.list_audit(
        "plan", plan.id, limit=10_000
    )
    operator = [
        {
            "t_s": _secs(e.ts) - start,
            "ts": e.ts,
            "actor": e.actor,
            "entity": e.entity,
            "action": e.action,
            "from_state": e.from_state,
            "to_state": e.to_state,
            "reason": e.reason,
        }
        for e in sorted(audit, key=lambda e: (e.ts, e.id))
    ]
    ack_s = [_secs(ts) - start for _, ts in store.ack_times(ex.id)]
    captures = [
        {
            "capture_id": c.capture_id,
            "t_s": c.received_at - start,
            "command_index": c.command_index,
            "n_points": c.n_points,
            "complete": c.complete,
        }
        for c in CaptureStore(store).list(ex.id)
    ]
    ends = [states[-1][0] - start] if states else []
    ends += ack_s[-1:]
    ends += [c["t_s"] for c in captures[-1:]]
    if ex.state in FINISHED:
        ends.append(_secs(ex.updated_at) - start)
    ends += [_secs(e.ts) - start for e in audit if e.entity == "execution"]
    return {
        "execution_id": ex.id,
        "plan_id": plan.id,
        "kind": plan.kind,
        "robot": ex.robot,
        "state": ex.state,
        "finished": ex.state in FINISHED,
        "started_at": ex.created_at,
        "duration_s": max([0.0, *ends]),
        "total": ex.total,
        "acked": ex.acked,
        "program_ops": [c.get("op") for c in program],
        "samples": samples,
        "acks": acks,
        "operator": operator,
        "captures": captures,
        "thinning": {
            "stored_samples": len(states),
            "returned_samples": len(samples),
            "stride": stride,
            "max_samples": max_samples,
            "note": (
                f"all {len(states)} stored state reports"
                if stride == 1
                else f"every {stride}. of {len(states)} stored state reports, and the last "
                f"(at most {max_samples})"
            ),
        },
    }


def joints_at(samples: list[tuple[float, list[float]]], t: float) -> tuple[np.ndarray, int]:
    """The joints at ``t`` (s) from ``(t_s, q)`` samples sorted by time:
    linear between the two around ``t`` (of the same length), held before
    the first and after the last; and the index of the sample at or before
    ``t`` (0 before the first)."""
    times = [s[0] for s in samples]
    i = bisect.bisect_right(times, t) - 1
    if i < 0:
        return np.asarray(samples[0][1], dtype=float), 0
    q0 = np.asarray(samples[i][1], dtype=float)
    if i + 1 >= len(samples):
        return q0, i
    t1, q1 = samples[i + 1][0], np.asarray(samples[i + 1][1], dtype=float)
    t0 = samples[i][0]
    if len(q1) != len(q0) or t1 <= t0:
        return q0, i
    return q0 + (q1 - q0) * ((t - t0) / (t1 - t0)), i


def planned_time_at(tl: np.ndarray, acks: list[float], t: float) -> tuple[float, int]:
    """Planned time (s) of the plan at run time ``t`` and the commands done by then.

    ``tl`` is the program's cumulative planned time (``len + 1`` values),
    ``acks`` the run times of the acknowledgements in index order.  Command
    ``k`` runs from the ack of ``k - 1`` (or the start) to its own ack; in
    between, the plan moves in proportion."""
    done = bisect.bisect_right(acks, t)
    n = len(tl) - 1
    if done >= min(n, len(acks)):
        return float(tl[min(done, n)]), done
    prev = acks[done - 1] if done > 0 else 0.0
    span = acks[done] - prev
    frac = min(max((t - prev) / span, 0.0), 1.0) if span > 0 else 0.0
    return float(tl[done] + (tl[done + 1] - tl[done]) * frac), done


@functools.lru_cache(maxsize=8)
def _frames(robot: str) -> RobotFrames | None:
    return robot_frames(robot)[0]


def show(scene: SceneService, execution_id: str, t_s: float) -> dict[str, Any]:
    """Show the execution's plan (unless shown) and the replay robot at ``t_s``."""
    from server.scene.service import _timeline

    if not scene.running:
        raise ReplayError("the 3D scene is not running")
    store = scene.store
    ex = store.get_execution(execution_id)  # NotFoundError: 404
    start = _secs(ex.created_at)
    recorded = [
        (t - start, list(st["q_rad"]))
        for t, st in store.execution_states(ex.id)
        if isinstance(st.get("q_rad"), list) and st["q_rad"]
    ]
    if not recorded:
        raise ReplayError(f"execution {ex.id} has no recorded robot states to replay")
    frames = _frames(ex.robot)
    if frames is None:
        raise ReplayError(f"no robot description (URDF) for robot {ex.robot!r}")
    if scene.current.get("plan_id") != ex.plan_id:
        shown = scene.show_plan(ex.plan_id)
        if shown.get("shown") != ex.plan_id:
            raise ReplayError(f"the scene could not show plan {ex.plan_id}: {shown}")
    plan = store.get_plan(ex.plan_id)
    program = list(plan.program or [])
    ack_s = [_secs(ts) - start for _, ts in store.ack_times(ex.id)]
    t = float(t_s)
    q, i = joints_at(recorded, t)
    names = frames.joint_names(len(q))
    with scene._lock:
        handle = _replay_handle(scene, ex.robot)
        all_names = list(handle.get_actuated_joint_names())
        cfg = np.zeros(len(all_names))
        ghost = scene._ghost_cfg(all_names)
        if ghost is not None:
            cfg = ghost.copy()
        if len(q) == len(all_names):
            cfg = q.copy()
        elif names is not None and all(n in all_names for n in names):
            # A robot reports its own joints (CMBOT: 7 of 12): placed by name.
            cfg[[all_names.index(n) for n in names]] = q
        else:
            raise ReplayError(f"{len(q)} recorded joints do not fit the URDF of {ex.robot}")
        handle.update_cfg(cfg)
        # The planned robot and the plan's animations stand where the plan was at t.
        tl = _timeline(program)
        done = sum(1 for a in ack_s if a <= t)
        fraction = None
        if tl is not None and tl[-1] > 0:
            planned, done = planned_time_at(tl, ack_s, t)
            fraction = planned / float(tl[-1])
            scene._driven = ex.id
            scene._replay["execution_id"] = ex.id
            for a in list(scene._animations):
                try:
                    a.update(fraction * a.duration_s)
                except Exception:
                    scene._animations.remove(a)
        executing = program[done] if done < len(program) else None
        info = {
            "execution_id": ex.id,
            "plan_id": ex.plan_id,
            "robot": ex.robot,
            "t_s": t,
            "node": scene._replay["node"],
            "q_rad": [float(v) for v in q],
            "sample_index": i,
            "acked": done,
            "command": {"index": done, "op": executing.get("op")} if executing else None,
            "plan_fraction": None if fraction is None else round(fraction, 6),
        }
        scene.current["replay"] = info
    # What the camera saw by then (the latest capture at or before t), over the model.
    info["capture"] = scene_captures.show_at(scene, ex.id, t)
    with scene._lock:
        scene.current["replay"] = info
    return info


def _replay_handle(scene: SceneService, robot: str) -> Any:
    """The replay robot's ViserUrdf (made on first use, kept until cleared)."""
    from pathlib import Path

    from robots import load_robot

    held = scene._replay
    if held.get("robot") == robot and held.get("handle") is not None:
        return held["handle"]
    clear(scene)
    node, handle = scene.attach_urdf(
        robot, Path(load_robot(robot).urdf_path), "replay", REPLAY_RGBA
    )
    scene._replay = {"robot": robot, "node": node, "handle": handle}
    return handle


def clear(scene: SceneService) -> bool:
    """Remove the replay robot (True if there was one); the plan stays shown."""
    held = scene._replay
    scene._replay = {}
    if not held or not scene.running:
        return bool(held)
    with scene._lock:
        scene.server.scene.remove_by_name(held["node"])
        scene.current.pop("replay", None)
        scene_captures.clear(scene)
        if held.get("execution_id") is not None and scene._driven == held["execution_id"]:
            scene._driven = None  # the plan's animations loop again
    return True
