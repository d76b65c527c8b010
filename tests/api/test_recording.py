"""Recorded runs: an execution exported as MCAP and read back with the MCAP
reader (issue #16 §3)."""

from __future__ import annotations

import io
import json
import time
from collections import Counter, defaultdict

from mcap.reader import make_reader

from tests.api.test_dispatch import approved_demo, wait_execution


def test_a_real_run_exports_as_mcap_with_every_channel(make_api) -> None:
    api = make_api(emulators=True, emulator_time_scale=10.0)
    assert api.services.dispatch.wait_connected("ara", 20)
    plan = approved_demo(api, end="c2")
    eid = api.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": "ara"}).json()["id"]
    wait_execution(api, eid, ("running",), timeout=30)
    time.sleep(1.0)
    assert api.post(f"/api/v1/executions/{eid}/pause").status_code == 200
    time.sleep(0.5)
    assert api.post(f"/api/v1/executions/{eid}/resume").status_code == 200
    ex = wait_execution(api, eid, ("completed",), timeout=120)

    r = api.get(f"/api/v1/executions/{eid}/recording.mcap", "viewer")
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == "application/octet-stream"
    assert f"{eid}.mcap" in r.headers["content-disposition"]

    reader = make_reader(io.BytesIO(r.content))
    summary = reader.get_summary()
    assert summary is not None
    topics = {c.id: c.topic for c in summary.channels.values()}
    assert set(topics.values()) == {
        "/plan/program",
        "/commands/acknowledged",
        "/robot/state",
        "/operator",
    }
    schemas = {summary.channels[i].topic: summary.schemas[summary.channels[i].schema_id].name
               for i in summary.channels}  # fmt: skip
    assert schemas["/operator"] == "foxglove.Log"
    assert all(c.message_encoding == "json" for c in summary.channels.values())

    msgs: dict[str, list[tuple[int, dict]]] = defaultdict(list)
    for _schema, channel, message in reader.iter_messages():
        msgs[channel.topic].append((message.log_time, json.loads(message.data)))
    counts = Counter({t: len(v) for t, v in msgs.items()})
    # The summary's statistics say the same.
    stats = summary.statistics
    assert stats is not None
    assert {topics[i]: n for i, n in stats.channel_message_counts.items()} == dict(counts)

    program = api.get(f"/api/v1/plans/{plan['id']}").json()["program"]
    assert [m["command"] for _, m in msgs["/plan/program"]] == program
    acked = msgs["/commands/acknowledged"]
    assert [m["index"] for _, m in acked] == list(range(ex["total"]))
    assert [m["op"] for _, m in acked] == [c["op"] for c in program]
    times = [t for t, _ in acked]
    assert times == sorted(times)
    # State reports (2 Hz) while it ran, between the first and last ack roughly.
    states = msgs["/robot/state"]
    assert len(states) >= 2
    assert all(m["robot"] == "ara" and len(m["q_rad"]) == 6 for _, m in states)
    # The operator's actions, as Foxglove log lines.
    lines = [m["message"] for _, m in msgs["/operator"]]
    for word in ("approve", "pause", "resume", "complete"):
        assert any(f" {word}" in line for line in lines), (word, lines)
    assert all(m["level"] in (2, 3) and "sec" in m["timestamp"] for _, m in msgs["/operator"])

    assert api.get("/api/v1/executions/ex_nope/recording.mcap").status_code == 404
