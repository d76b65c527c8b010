"""``POST /api/v1/estop`` and the audit log."""

from __future__ import annotations

import asyncio
import logging
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Annotated, Any

from fastapi import APIRouter, Depends, HTTPException, Query, Request, status
from pydantic import BaseModel, Field

from server.auth import Principal, Viewer, authenticate, token_from_request
from server.diskspace import describe
from server.ownership.peers import FORWARDED_HEADER
from server.routers.responses import AUTH
from server.services import Services, get_services
from server.store import NotFoundError

router = APIRouter(tags=["safety"])
log = logging.getLogger(__name__)

Svc = Annotated[Services, Depends(get_services)]


class EstopRequest(BaseModel):
    robot: str | None = Field(None, description="one robot; all robots when omitted")
    reason: str = Field("operator E-stop", max_length=500)


def trigger_estop(
    services: Services,
    robot: str | None,
    actor: str,
    reason: str,
    *,
    token: str | None = None,
    forwarded_by: str | None = None,
) -> dict[str, Any]:
    """Stop every robot (or one) through every registered handler, then the
    robots other servers own through them, then record it.

    Handlers run first and each in isolation: a failing handler must not keep
    the others from stopping their robots.  Then, unless this request was
    itself forwarded, every other live server sharing the store is asked in
    parallel with the caller's token (``server.ownership.peers``); alone, this
    server asks nobody and waits for nothing.  The audit write comes last.
    ``robots`` says which server reached each robot; ``unreached`` lists the
    robots nobody reported stopping (no owner, or its server did not answer);
    ``held`` those whose E-stop is kept in the store for the next server that
    drives them, which latches it before anything else.
    """
    if robot is not None and services.dispatch is not None:
        known = services.dispatch.robot_names()
        if robot not in known:
            raise NotFoundError(f"no robot {robot!r}; robots: {', '.join(known)}")
    t0 = time.perf_counter()
    reached, errors = [], []
    local: list[str] = []
    for handler in list(services.estop_handlers):
        try:
            got = handler(robot, f"{reason} (by {actor})")
            reached.append(getattr(handler, "__name__", repr(handler)))
            if isinstance(got, list):
                local.extend(str(name) for name in got)
        except Exception as exc:
            log.exception("E-stop handler failed")
            errors.append(f"{type(exc).__name__}: {exc}")
    peers = services.peers
    me = peers.server_id if peers is not None else None
    robots: dict[str, str | None] = dict.fromkeys(local, me)
    forwarded: list[dict[str, Any]] = []
    if peers is not None and forwarded_by is None:
        forwarded = peers.estop_others(robot, reason, token)
        for outcome in forwarded:
            for name in outcome.get("reached", []):
                robots.setdefault(str(name), outcome["server"])
            if not outcome.get("ok"):
                errors.append(f"server {outcome['server']}: {outcome.get('error')}")
    names = services.dispatch.robot_names() if services.dispatch is not None else []
    targets = [robot] if robot is not None else names
    target = robot or "all"
    unreached = [n for n in targets if n not in robots] if forwarded_by is None else []
    held: list[str] = []
    if unreached and peers is not None:
        # No live server drives these (an owner died and its lease has not lapsed,
        # or none took them): the next server to drive each latches it first.
        try:
            peers.store.hold_estops(unreached, actor, reason)
            held = unreached
        except Exception as exc:
            log.exception("could not hold the E-stop for the unreached robots")
            errors.append(f"holding the E-stop for {', '.join(unreached)}: {exc}")
    t_stopped = time.perf_counter()
    why = f"{reason} (forwarded by server {forwarded_by})" if forwarded_by else reason
    # The robots are stopped whatever the store does: the event goes out first,
    # then the record, kept in memory and written later if the store refuses it.
    services.events.publish("estop", {"robot": target, "reason": reason, "by": actor})
    # On a disk known to be full the write fails at once: say so rather than "queued".
    full = services.disk is not None and services.disk.read().state == "full"
    audit = record_safety(
        services, actor, "robot", target, "estop", why, wait_s=None if full else ESTOP_AUDIT_WAIT_S
    )
    t_end = time.perf_counter()
    return {
        "robot": target,
        "audit": audit,
        "handlers": reached,
        "errors": errors,
        "server": me,
        "local": local,
        "robots": robots,
        "unreached": unreached,
        "held": held,
        "servers": forwarded,
        # Where this server's time went: stopping the robots (every handler and
        # peer), then the event and the audit record.
        "timings_ms": {
            "stop": round((t_stopped - t0) * 1e3, 2),
            "record": round((t_end - t_stopped) * 1e3, 2),
        },
    }


#: How long an E-stop's answer waits for its audit record to be written; past
#: it the answer says "queued" and the record follows (the stop has happened).
ESTOP_AUDIT_WAIT_S = 0.03


def record_safety(
    services: Services,
    actor: str,
    entity: str,
    entity_id: str,
    action: str,
    reason: str,
    *,
    wait_s: float | None = None,
) -> str:
    """Audit a safety action already taken: "recorded", "queued" (``wait_s``
    passed, written later in order), or why not and that it is kept."""
    backlog = services.audit_backlog
    if backlog is None:
        try:
            services.store.audit(actor, entity, entity_id, action, reason)
        except Exception as exc:
            log.exception("the %s record could not be written", action)
            return f"failed: {describe(exc)}"
        return "recorded"
    return str(backlog.record(actor, entity, entity_id, action, reason, wait_s=wait_s))


#: E-stop requests never queue behind other requests for a worker thread: they
#: have threads of their own (the shared pool may be taken by 40 slow polls).
_ESTOP_POOL = ThreadPoolExecutor(4, thread_name_prefix="estop-http")


def _operator(services: Services, token: str | None) -> Principal:
    principal = authenticate(services, token)
    if principal is None:
        raise HTTPException(
            status.HTTP_401_UNAUTHORIZED,
            detail="missing or invalid token: send 'Authorization: Bearer <token>'",
            headers={"WWW-Authenticate": "Bearer"},
        )
    if not principal.has("operator"):
        raise HTTPException(
            status.HTTP_403_FORBIDDEN,
            detail=f"the E-stop needs the operator role; token {principal.name!r} has "
            f"{principal.role}",
        )
    return principal


async def _estop_first(request: Request, robot: str | None, reason: str) -> dict[str, Any]:
    """Authenticate and stop on the E-stop pool, not the shared worker threads.

    The handler is ``async`` and takes no sync dependencies, so nothing waits
    for a free thread of the shared pool; the event loop only hands over.
    """
    services: Services = request.app.state.services
    token = token_from_request(request)
    forwarded_by = request.headers.get(FORWARDED_HEADER)

    t_handler = time.perf_counter()

    def run() -> dict[str, Any]:
        t_thread = time.perf_counter()
        who = _operator(services, token)
        out = trigger_estop(
            services, robot, who.actor, reason, token=token, forwarded_by=forwarded_by
        )
        out["timings_ms"]["to_thread"] = round((t_thread - t_handler) * 1e3, 2)
        return out

    return await asyncio.get_running_loop().run_in_executor(_ESTOP_POOL, run)


_ESTOP_RESPONSES: dict[int | str, dict[str, Any]] = {
    401: {"description": "missing, invalid or revoked token"},
    403: {"description": "the token's role is below operator"},
    404: {"description": "no such robot"},
}


@router.post("/estop", responses=_ESTOP_RESPONSES)
async def estop(request: Request, req: EstopRequest | None = None) -> dict[str, Any]:
    """Emergency stop: every robot (or ``robot``) stops now, in any state."""
    req = req or EstopRequest()
    return await _estop_first(request, req.robot, req.reason)


@router.post("/robots/{robot}/estop", responses=_ESTOP_RESPONSES)
async def estop_robot(robot: str, request: Request) -> dict[str, Any]:
    return await _estop_first(request, robot, "operator E-stop")


@router.get("/audit", responses=AUTH)
def audit(
    services: Svc,
    _: Viewer,
    entity: str | None = None,
    entity_id: str | None = None,
    # Bounded: a huge value overflowed SQLite's integer (500), -1 meant "no limit".
    limit: Annotated[int, Query(ge=1, le=2000, description="at most this many")] = 200,
) -> list[dict[str, Any]]:
    """Audit events, newest first: who did what, when, from which state to which."""
    return [e.public() for e in services.store.list_audit(entity, entity_id, limit)]
