"""The web server's view of the other servers sharing the store.

:class:`Peers` keeps, refreshed from the store in a thread of its own, who
owns which robot and which servers are alive, so that neither the E-stop nor
``GET /robots`` reads the store to find out.  It forwards:

- **E-stops** to every other live server, in parallel, with a short timeout,
  after this server has stopped its own robots (each server stops the robots
  it owns; a robot whose owner changed since the last refresh is still
  reached, since every live server is asked, not only the owner on record);
- **operator actions** on a robot (dispatch, pause, resume, abort, connection,
  takeover, clear E-stop, its live state) to the robot's owner.

**Credential.**  A forwarded request carries the caller's own bearer token.
Tokens live in the shared store, so it is valid on every server, and the
owner checks it and its role again and audits the real operator: forwarding
grants nothing the caller did not already have.  A per-installation
server-to-server secret would be a second credential to provision and
rotate on every server, valid for every action on every robot, and its
forwarded actions would be audited as the server rather than the person.
Revoking the caller's token stops forwarding with it (within the token
cache's 0.75 s).  ``X-SteelPath-Forwarded-By`` marks a forwarded request:
the receiver acts only on what it owns and never forwards again (one hop).
"""

from __future__ import annotations

import concurrent.futures
import logging
import threading
import time
from dataclasses import dataclass
from typing import Any

import httpx

from server.store.ownership import LeaseRow, OwnershipStore, ServerRow

log = logging.getLogger(__name__)

FORWARDED_HEADER = "X-SteelPath-Forwarded-By"
#: A peer that has not answered a forwarded E-stop within this long is reported
#: unreached (its robots' links to it are its own: they stop on their watchdog
#: if it is dead).
ESTOP_FORWARD_TIMEOUT_S = 0.5
#: Forwarded operator actions: a dispatch checks the store and starts a streamer.
FORWARD_TIMEOUT_S = 20.0


@dataclass(frozen=True)
class Forwarded:
    """A forwarded request's answer, as the owner gave it."""

    status: int
    body: Any
    server_id: str
    answered: bool = True  # False: the owner did not answer (dead, or unreachable)


class Peers:
    """Owners and live servers, refreshed every ``refresh_s``; forwards requests."""

    def __init__(
        self, db: Any, server_id: str, url: str, lease_s: float, *, refresh_s: float = 0.25
    ) -> None:
        self.store = OwnershipStore(db)
        self.server_id = server_id
        self.url = url
        self.lease_s = lease_s
        self.refresh_s = refresh_s
        self._leases: dict[str, LeaseRow] = {}
        self._servers: list[ServerRow] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        # Keep-alive connections to the peers: a forwarded E-stop does not pay
        # for a TCP handshake.  httpx clients are thread-safe.
        self._estop_http = httpx.Client(
            timeout=httpx.Timeout(ESTOP_FORWARD_TIMEOUT_S),
            limits=httpx.Limits(max_connections=64, max_keepalive_connections=16),
        )
        self._http = httpx.Client(timeout=httpx.Timeout(FORWARD_TIMEOUT_S, connect=2.0))
        self._pool = concurrent.futures.ThreadPoolExecutor(8, thread_name_prefix="estop-forward")

    # -------------------------------------------------------------- lifecycle
    def start(self) -> Peers:
        self.refresh()
        self._thread = threading.Thread(target=self._loop, name="peers refresh", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2)
        self._pool.shutdown(wait=False, cancel_futures=True)
        self._estop_http.close()
        self._http.close()

    def _loop(self) -> None:
        while not self._stop.wait(self.refresh_s):
            self.refresh()

    def refresh(self) -> None:
        """Read the leases and servers (never on a request's path)."""
        try:
            leases = self.store.leases()
            servers = self.store.servers()
        except Exception as exc:  # the next refresh tries again; the last view stays
            log.warning("could not read robot owners: %s", exc)
            return
        self._leases, self._servers = leases, servers

    # ------------------------------------------------------------------ views
    def owner(self, robot: str, *, fresh: bool = False) -> LeaseRow | None:
        """The robot's unexpired lease (``fresh``: read from the store now)."""
        lease = self.store.leases().get(robot) if fresh else self._leases.get(robot)
        if lease is None or lease.expires_at < time.time():
            return None
        return lease

    def owners(self) -> dict[str, LeaseRow]:
        now = time.time()
        return {n: lease for n, lease in self._leases.items() if lease.expires_at >= now}

    def others(self) -> list[ServerRow]:
        """Other servers heard from within two leases (a killed one drops out)."""
        now = time.time()
        return [
            s
            for s in self._servers
            if s.id != self.server_id and now - s.heartbeat_at < 2 * self.lease_s
        ]

    def describe(self, robot: str) -> dict[str, Any]:
        """Owner fields for ``GET /robots``."""
        lease = self.owner(robot)
        if lease is None:
            return {"owner": None, "owner_url": None, "owned_here": False}
        return {
            "owner": lease.server_id,
            "owner_url": lease.url,
            "owned_here": lease.server_id == self.server_id,
        }

    # ------------------------------------------------------------- forwarding
    def estop_others(
        self, robot: str | None, reason: str, token: str | None
    ) -> list[dict[str, Any]]:
        """E-stop every other live server in parallel; one outcome per server.

        Nothing is asked when this server is alone (the embedded set-up): no
        thread, no socket, no wait.
        """
        others = self.others()
        if not others:
            return []
        futures = {
            s.id: self._pool.submit(self._estop_one, s, robot, reason, token) for s in others
        }
        out = []
        for sid, fut in futures.items():
            try:
                out.append(fut.result(timeout=ESTOP_FORWARD_TIMEOUT_S + 0.5))
            except Exception as exc:
                out.append({"server": sid, "ok": False, "reached": [], "error": str(exc)})
        return out

    def _estop_one(
        self, server: ServerRow, robot: str | None, reason: str, token: str | None
    ) -> dict[str, Any]:
        t0 = time.monotonic()
        result: dict[str, Any] = {"server": server.id, "url": server.url, "reached": []}
        try:
            r = self._estop_http.post(
                f"{server.url}/api/v1/estop",
                json={"robot": robot, "reason": reason},
                headers=self._headers(token),
            )
            result["status"] = r.status_code
            body = (
                r.json() if r.headers.get("content-type", "").startswith("application/json") else {}
            )
            result["ok"] = r.status_code == 200
            result["reached"] = list(body.get("local", []) if isinstance(body, dict) else [])
            if r.status_code != 200:
                result["error"] = str(body.get("detail") if isinstance(body, dict) else r.text)
        except httpx.HTTPError as exc:
            result["ok"] = False
            result["error"] = f"{type(exc).__name__}: {exc}"
        result["took_ms"] = round((time.monotonic() - t0) * 1e3, 2)
        return result

    def forward(
        self,
        lease: LeaseRow,
        method: str,
        path: str,
        token: str | None,
        json_body: Any = None,
    ) -> Forwarded:
        """Send an operator action to the robot's owner; its answer is ours."""
        if not lease.url:
            detail = f"owner {lease.server_id} has no URL"
            return Forwarded(503, {"detail": detail}, lease.server_id, answered=False)
        try:
            r = self._http.request(
                method,
                f"{lease.url}{path}",
                json=json_body,
                headers=self._headers(token),
            )
        except httpx.HTTPError as exc:
            detail = f"the robot's server {lease.server_id} ({lease.url}) did not answer: {exc}"
            return Forwarded(503, {"detail": detail}, lease.server_id, answered=False)
        try:
            body = r.json()
        except ValueError:
            body = {"detail": r.text}
        return Forwarded(r.status_code, body, lease.server_id)

    def _headers(self, token: str | None) -> dict[str, str]:
        headers = {FORWARDED_HEADER: self.server_id}
        if token:
            headers["Authorization"] = f"Bearer {token}"
        return headers
