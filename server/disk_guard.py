"""A full disk answers 507 with a message, before a write starts and when one fails.

:class:`DiskReserve` (ASGI middleware) refuses a write request (POST, PUT, PATCH)
whose declared body would leave less than the reserve free, before anything is
read or stored, so partial uploads never fill the last megabytes and the audit
log and the E-stop keep room to write.  The E-stop, clear-estop and deletions
(which free space) are never refused for space.  :func:`disk_full_response`
turns a write that failed for space anyway (SQLite, PostgreSQL, a file) into
the same 507 instead of a 500.
"""

from __future__ import annotations

import re

from starlette.requests import Request
from starlette.responses import JSONResponse
from starlette.types import ASGIApp, Receive, Scope, Send

from server.asgi_response import send_json
from server.diskspace import DiskGauge, is_disk_full

#: Paths that must work on a full disk: stopping robots and clearing a stop
#: (which refuses by itself, 409, when it cannot be recorded).
ALWAYS_ALLOWED = re.compile(r"^/api/v1/(estop|robots/[^/]+/(estop|clear-estop))/?$")
WRITES = frozenset({"POST", "PUT", "PATCH"})

FULL_MESSAGE = (
    "the server's disk is full ({free_mb:.0f} MiB free, {reserve_mb:.0f} MiB kept for the "
    "audit log and the E-stop): this request was not stored. Free space on the server's "
    "data volume (delete old plans or clouds) and try again"
)


def _message(gauge: DiskGauge) -> str:
    reading = gauge.read()
    return FULL_MESSAGE.format(
        free_mb=reading.free_bytes / 2**20, reserve_mb=gauge.reserve_bytes / 2**20
    )


class DiskReserve:
    """507 before a write request that the data volume has no room for."""

    def __init__(self, app: ASGIApp, gauge: DiskGauge) -> None:
        self.app = app
        self.gauge = gauge

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if (
            scope["type"] != "http"
            or scope.get("method") not in WRITES
            or ALWAYS_ALLOWED.match(scope.get("path", ""))
        ):
            await self.app(scope, receive, send)
            return
        declared = dict(scope.get("headers") or []).get(b"content-length", b"0")
        size = int(declared) if declared.isdigit() else 0
        if self.gauge.room_for(size):
            await self.app(scope, receive, send)
            return
        await send_json(send, 507, {"detail": _message(self.gauge)})


def disk_full_response(gauge: DiskGauge, exc: BaseException) -> JSONResponse | None:
    """The 507 for a write that failed for space, or ``None`` for any other failure."""
    if not is_disk_full(exc):
        return None
    gauge.refresh()
    return JSONResponse({"detail": _message(gauge)}, status_code=507)


async def disk_full_handler(request: Request, exc: Exception) -> JSONResponse:
    """Exception handler for ``sqlite3.OperationalError`` and ``OSError``: 507 when the
    disk is full, else re-raised (a 500 with the traceback in the log, as before)."""
    gauge: DiskGauge = request.app.state.disk
    response = disk_full_response(gauge, exc)
    if response is None:
        raise exc
    return response
