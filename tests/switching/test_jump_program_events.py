"""A timed trajectory sampled into way-points with magnet commands between
them (server.kinds.programs.sampled_joints_with_events): the way-point an
event belongs to is always sent before it, so a magnet is switched only once
the foot has reached the pose the plan switches it at."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from robots.protocol.commands import JointMove, SetMagnet, Stop
from server.kinds.programs import sampled_joints_with_events


@settings(max_examples=80, deadline=None)
@given(
    n=st.integers(5, 300),
    dt=st.sampled_from([0.004, 0.01, 0.033]),
    sample_s=st.sampled_from([0.05, 0.1, 0.25]),
    picks=st.lists(st.integers(0, 10_000), min_size=1, max_size=4),
)
def test_every_event_follows_the_way_point_at_its_time(n, dt, sample_s, picks) -> None:
    t = np.arange(n) * dt
    q = np.column_stack([t, -t, 2 * t])  # joint values name their time
    times = sorted(float(t[p % n]) for p in picks)  # events at trajectory samples
    events = [(te, SetMagnet(k % 2, k % 2 == 0)) for k, te in enumerate(times)]
    cmds = sampled_joints_with_events(t, q, events, sample_s=sample_s)
    assert isinstance(cmds[-1], Stop)
    clock, last_q, seen = 0.0, None, 0
    for c in cmds:
        if isinstance(c, JointMove):
            clock += c.duration_s
            last_q = c.q_rad
        elif isinstance(c, SetMagnet):
            te = times[seen]
            seen += 1
            # The way-point just before the event is the one at the event's time.
            assert last_q is not None and abs(last_q[0] - te) < 1e-9, (last_q, te)
            assert abs(clock - te) < 1e-9
    assert seen == len(events)
    moves = [c for c in cmds if isinstance(c, JointMove)]
    assert moves[-1].q_rad == tuple(q[-1])
    assert abs(sum(m.duration_s for m in moves) - float(t[-1] - t[0])) < 1e-9
