"""Webhook deliveries: events → signed JSON POSTs, retried with back-off (issue #16 §5).

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

A 2xx answer delivers it; anything else (an error status, a refused or
timed-out connection) is retried after ``backoff_s · 2^(attempt-1)``
(capped at ``max_backoff_s``) until ``max_attempts`` attempts, then the
delivery is ``failed``.  Every attempt's status or error is stored and listed
(``GET /api/v1/webhooks/{id}/deliveries``).
"""

from __future__ import annotations

import hashlib
import hmac
import json
import logging
import queue
import threading
import time
from datetime import UTC, datetime
from typing import Any

import httpx

from server.store.webhooks import Delivery, WebhookStore

log = logging.getLogger(__name__)

#: Execution states that are sent, as ``execution.<state>``.
_EXECUTION_STATES = ("completed", "faulted", "interrupted")


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
    ) -> None:
        self.store = store
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
            r = client.post(hook.url, content=body, headers=headers)
            status = r.status_code
            if not 200 <= status < 300:
                error = f"HTTP {status}"
        except httpx.HTTPError as exc:
            error = f"{type(exc).__name__}: {exc}"[:300]
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
