"""Webhook deliveries: events → signed JSON POSTs, retried with back-off.

The event bus tells :class:`WebhookDispatcher` of every event; the ones a
webhook may ask for (:data:`server.store.webhooks.WEBHOOK_EVENTS`) are handed
to its thread (the publisher — an E-stop request, say — never waits on the
database), which stores them as deliveries, so from then on a delivery
survives a restart, and posts the due ones.  An execution event becomes
``execution.<state>`` when its state changes to completed, faulted or
interrupted (ack events repeat a state and are not re-sent); an E-stop
becomes ``estop``; a new finding of condition state 3 or 4
``finding.created``.

Each POST carries the JSON body ``{"id", "event", "at", "data"}`` and:

* ``X-SteelPath-Event``, ``X-SteelPath-Delivery``;
* ``X-SteelPath-Timestamp``: Unix seconds when it was signed;
* ``X-SteelPath-Signature``: ``sha256=`` + hex HMAC-SHA256 of
  ``f"{timestamp}.{body}"`` with the webhook's secret — a receiver checks it
  (:func:`verify`) and refuses old timestamps, so a captured delivery cannot
  be replayed later.

Before every attempt the webhook's host is resolved again and checked
(:func:`server.netpolicy.check_url`: public addresses only, unless the
webhook has ``allow_private_network``), since DNS may have changed since it
was registered; the POST then goes to the address that was checked (the URL's
host rewritten to it, the original ``Host`` header and TLS server name kept),
not to a fresh resolution, and redirects are not followed.

A 2xx answer delivers it; anything else is retried after
``backoff_s · 2^(attempt-1)`` (capped at ``max_backoff_s``) until
``max_attempts`` attempts, then the delivery is ``failed``.  Every attempt's
outcome is stored and listed (``GET /api/v1/webhooks/{id}/deliveries``): an
answer as ``HTTP <status>`` (a redirect too), and every failure to get one —
refused or timed-out connection, DNS or TLS failure, an address the policy
refuses — as the one word ``unreachable``, so the list cannot tell a closed
port from a filtered one or a refused address (no port scanner); the server's
log has the reason.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import logging
import queue
import socket
import threading
import time
from datetime import UTC, datetime
from typing import Any

import httpx

from server.netpolicy import Address, Resolver, UnsafeWebhookUrl, check_url
from server.store.webhooks import Delivery, Webhook, WebhookStore

log = logging.getLogger(__name__)

#: Execution states that are sent, as ``execution.<state>``.
_EXECUTION_STATES = ("completed", "faulted", "interrupted")

#: The stored error of every attempt that got no HTTP answer.
UNREACHABLE = "unreachable"


def sign(secret: str, timestamp: int, body: bytes) -> str:
    """The ``X-SteelPath-Signature`` value of ``body`` signed at ``timestamp``."""
    mac = hmac.new(secret.encode(), f"{timestamp}.".encode() + body, hashlib.sha256)
    return "sha256=" + mac.hexdigest()


def verify(
    secret: str,
    timestamp: str,
    body: bytes,
    signature: str,
    *,
    now: float | None = None,
    tolerance_s: float = 300.0,
) -> bool:
    """What a receiver checks: the signature matches and the timestamp is
    recent (within ``tolerance_s`` of ``now``)."""
    try:
        ts = int(timestamp)
    except ValueError:
        return False
    if abs((time.time() if now is None else now) - ts) > tolerance_s:
        return False
    return hmac.compare_digest(sign(secret, ts, body), signature)


class WebhookDispatcher:
    """Turns bus events into deliveries and sends them from one thread."""

    def __init__(
        self,
        store: WebhookStore,
        *,
        backoff_s: float = 2.0,
        max_backoff_s: float = 300.0,
        max_attempts: int = 8,
        timeout_s: float = 5.0,
        resolve: Resolver = socket.getaddrinfo,
    ) -> None:
        self.store = store
        #: How webhook hosts are resolved, at registration (the router uses it)
        #: and before each attempt; tests put a stand-in here.
        self.resolve = resolve
        self.backoff_s = backoff_s
        self.max_backoff_s = max_backoff_s
        self.max_attempts = max_attempts
        self.timeout_s = timeout_s
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._exec_states: dict[str, str] = {}
        self._lock = threading.Lock()
        self._inbox: queue.SimpleQueue[tuple[str, dict[str, Any]]] = queue.SimpleQueue()

    # ----------------------------------------------------------- lifecycle
    def start(self) -> WebhookDispatcher:
        self._thread = threading.Thread(target=self._run, name="webhooks", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=self.timeout_s + 2)

    # -------------------------------------------------------------- events
    def on_event(self, type_: str, data: dict[str, Any]) -> None:
        """A bus event, on the publisher's thread: named and handed over."""
        name = self._event_name(type_, data)
        if name is None:
            return
        payload = {
            "event": name,
            "at": datetime.now(UTC).isoformat(timespec="milliseconds"),
            "data": data,
        }
        self._inbox.put((name, payload))
        self._wake.set()

    def _store_inbox(self) -> None:
        while True:
            try:
                name, payload = self._inbox.get_nowait()
            except queue.Empty:
                return
            self.store.enqueue(name, payload, time.time())

    def _event_name(self, type_: str, data: dict[str, Any]) -> str | None:
        if type_ == "estop":
            return "estop"
        if type_ == "finding":
            serious = int(data.get("condition_state", 0)) >= 3
            return "finding.created" if data.get("action") == "created" and serious else None
        if type_ != "execution":
            return None
        eid, state = str(data.get("id", "")), str(data.get("state", ""))
        with self._lock:
            before = self._exec_states.get(eid)
            self._exec_states[eid] = state
            while len(self._exec_states) > 1024:
                self._exec_states.pop(next(iter(self._exec_states)))
        if state in _EXECUTION_STATES and state != before:
            return f"execution.{state}"
        return None

    # ------------------------------------------------------------- sending
    def _run(self) -> None:
        with httpx.Client(timeout=self.timeout_s, follow_redirects=False) as client:
            while not self._stop.is_set():
                try:
                    self._store_inbox()
                    for d in self.store.due(time.time()):
                        if self._stop.is_set():
                            return
                        self.send(client, d)
                    nxt = self.store.next_due()
                except Exception:
                    log.exception("webhook sender failed; retrying in 1 s")
                    nxt = time.time() + 1.0
                wait = 60.0 if nxt is None else max(0.0, min(60.0, nxt - time.time()))
                if self._inbox.empty():
                    self._wake.wait(wait)
                self._wake.clear()

    def send(self, client: httpx.Client, d: Delivery) -> Delivery:
        """One attempt at ``d``; its stored outcome."""
        try:
            hook = self.store.get(d.webhook_id)
        except KeyError:
            return self.store.record_attempt(
                d.id, ok=False, status=None, error="webhook gone", retry_at=None
            )
        body = json.dumps({"id": d.id, **d.payload}, separators=(",", ":")).encode()
        ts = int(time.time())
        headers = {
            "Content-Type": "application/json",
            "User-Agent": "SteelPath-Webhooks",
            "X-SteelPath-Event": d.event,
            "X-SteelPath-Delivery": d.id,
            "X-SteelPath-Timestamp": str(ts),
            "X-SteelPath-Signature": sign(hook.secret, ts, body),
        }
        status: int | None = None
        error: str | None = None
        try:
            ips = check_url(
                hook.url, allow_private=hook.allow_private_network, resolve=self.resolve
            )
            status = self._post(client, hook, ips, body, headers)
            if not 200 <= status < 300:
                error = f"HTTP {status}"
        except (UnsafeWebhookUrl, httpx.HTTPError, httpx.InvalidURL) as exc:
            log.warning("webhook %s delivery %s: %s: %s", hook.id, d.id, type(exc).__name__, exc)
            error = UNREACHABLE
        ok = error is None
        attempt = d.attempts + 1
        retry_at = None
        if not ok and attempt < self.max_attempts:
            delay = min(self.max_backoff_s, self.backoff_s * 2 ** (attempt - 1))
            retry_at = time.time() + delay
        if not ok:
            log.warning(
                "webhook %s delivery %s (%s) attempt %d: %s", hook.id, d.id, d.event, attempt, error
            )
        return self.store.record_attempt(d.id, ok=ok, status=status, error=error, retry_at=retry_at)

    def _post(
        self,
        client: httpx.Client,
        hook: Webhook,
        ips: list[Address],
        body: bytes,
        headers: dict[str, str],
    ) -> int:
        """POST to the first of ``ips`` (checked) that connects; its status.

        The URL's host is replaced by the address, so nothing resolves the name
        again; ``Host`` and the TLS server name (which the certificate is
        checked against) stay the name's.  The answer's body is never read.
        """
        url = httpx.URL(hook.url)
        pinned_headers = {**headers, "Host": url.netloc.decode("ascii")}
        extensions = {"sni_hostname": url.raw_host.decode("ascii")} if url.scheme == "https" else {}
        for i, ip in enumerate(ips):
            request = client.build_request(
                "POST",
                url.copy_with(host=str(ip)),
                content=body,
                headers=pinned_headers,
                extensions=extensions,
            )
            try:
                response = client.send(request, stream=True, follow_redirects=False)
            except httpx.ConnectError:
                if i == len(ips) - 1:
                    raise
                continue  # another address of the same name may answer
            response.close()
            return response.status_code
        raise httpx.ConnectError("no address to connect to")  # check_url returns at least one
