"""The event stream carries the robots' statuses (``robots_every_s``), so the
console follows heartbeats, faults and E-stop latches without polling
``GET /robots`` (the polling once made ~9,300 access-log lines
a session)."""

from __future__ import annotations

import itertools
import json
import time
from pathlib import Path

import httpx

from tests.conftest import make_settings
from tests.support.live import free_port, live_server


def _robots_events(url: str, token: str, every: float, n: int) -> list[tuple[float, list]]:
    """The first ``n`` ``event: robots`` payloads with their arrival times."""
    out: list[tuple[float, list]] = []
    with httpx.stream(
        "GET",
        f"{url}/api/v1/events?robots_every_s={every}",
        headers={"Authorization": f"Bearer {token}"},
        timeout=httpx.Timeout(10.0, read=30.0),
    ) as r:
        assert r.status_code == 200
        event = None
        for line in r.iter_lines():
            if line.startswith("event: "):
                event = line[7:]
            elif line.startswith("data: ") and event == "robots":
                out.append((time.monotonic(), json.loads(line[6:])))
                if len(out) >= n:
                    break
            elif not line:
                event = None
    return out


def test_the_stream_carries_every_robots_status_at_the_asked_rate(tmp_path: Path) -> None:
    settings = make_settings(tmp_path / "var", port=free_port(), scene_port=free_port())
    with live_server(settings) as (url, tokens, _app):
        h = {"Authorization": f"Bearer {tokens['viewer']}"}
        want = {r["name"] for r in httpx.get(f"{url}/api/v1/robots", headers=h).json()}
        assert want, "the embedded defaults have robots"
        t0 = time.monotonic()
        got = _robots_events(url, tokens["viewer"], 0.5, 4)
        names = [{r["name"] for r in payload} for _, payload in got]
        assert all(n == want for n in names), names
        for _, payload in got:
            for r in payload:
                assert {"state", "last_heartbeat", "faults", "estop_latched"} <= set(r)
        # The first at once, then every 0.5 s (not faster; loose upper bound).
        gaps = [b[0] - a[0] for a, b in itertools.pairwise(got)]
        assert got[0][0] - t0 < 5.0
        assert all(0.45 <= g < 3.0 for g in gaps), gaps
        # An E-stop shows up in the very next status: an answer whose round
        # trip began before the latch is not cached (it once was, for 0.5 s).
        op = {"Authorization": f"Bearer {tokens['operator']}"}
        name = sorted(want)[0]
        r = httpx.post(f"{url}/api/v1/estop", json={"robot": name, "reason": "test"}, headers=op)
        assert r.status_code == 200, r.text
        seen = _robots_events(url, tokens["viewer"], 0.5, 4)
        flags = [next(x for x in p if x["name"] == name)["estop_latched"] for _, p in seen]
        assert all(f is True for f in flags), flags


def test_robots_every_s_is_bounded(tmp_path: Path) -> None:
    settings = make_settings(tmp_path / "var", port=free_port(), scene_port=free_port())
    with live_server(settings) as (url, tokens, _app):
        h = {"Authorization": f"Bearer {tokens['viewer']}"}
        for bad in ("0.1", "-1", "301", "x"):
            r = httpx.get(f"{url}/api/v1/events?once=true&robots_every_s={bad}", headers=h)
            assert r.status_code == 422, (bad, r.text)
            assert "robots_every_s" in r.text
        # Off by default: a stream without it sends no robots event.
        r = httpx.get(f"{url}/api/v1/events?once=true", headers=h)
        assert r.status_code == 200 and "event: robots" not in r.text
