"""``POST /api/v1/estop`` and the audit log."""

from __future__ import annotations

import logging
from typing import Annotated, Any

from fastapi import APIRouter, Depends
from pydantic import BaseModel, Field

from server.auth import Operator, Viewer
from server.services import Services, get_services
from server.store import NotFoundError

router = APIRouter(tags=["safety"])
log = logging.getLogger(__name__)

Svc = Annotated[Services, Depends(get_services)]


class EstopRequest(BaseModel):
    robot: str | None = Field(None, description="one robot; all robots when omitted")
    reason: str = Field("operator E-stop", max_length=500)


def trigger_estop(services: Services, robot: str | None, actor: str, reason: str) -> dict[str, Any]:
    """Stop every robot (or one) through every registered handler, then record it.

    Handlers run first and each in isolation: a failing handler must not keep
    the others from stopping their robots; the audit write comes after.
    """
    if robot is not None and services.dispatch is not None:
        known = services.dispatch.robot_names()
        if robot not in known:
            raise NotFoundError(f"no robot {robot!r}; robots: {', '.join(known)}")
    reached, errors = [], []
    for handler in list(services.estop_handlers):
        try:
            handler(robot, reason)
            reached.append(getattr(handler, "__name__", repr(handler)))
        except Exception as exc:
            log.exception("E-stop handler failed")
            errors.append(f"{type(exc).__name__}: {exc}")
    target = robot or "all"
    services.store.audit(actor, "robot", target, "estop", reason)
    services.events.publish("estop", {"robot": target, "reason": reason, "by": actor})
    return {"robot": target, "handlers": reached, "errors": errors}


@router.post("/estop")
def estop(services: Svc, who: Operator, req: EstopRequest | None = None) -> dict[str, Any]:
    """Emergency stop: every robot (or ``robot``) stops now, in any state."""
    req = req or EstopRequest()
    return trigger_estop(services, req.robot, who.actor, req.reason)


@router.post("/robots/{robot}/estop")
def estop_robot(robot: str, services: Svc, who: Operator) -> dict[str, Any]:
    return trigger_estop(services, robot, who.actor, "operator E-stop")


@router.get("/audit")
def audit(
    services: Svc,
    _: Viewer,
    entity: str | None = None,
    entity_id: str | None = None,
    limit: int = 200,
) -> list[dict[str, Any]]:
    """Audit events, newest first: who did what, when, from which state to which."""
    return [e.public() for e in services.store.list_audit(entity, entity_id, min(limit, 2000))]
