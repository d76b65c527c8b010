"""``/api/v1/plans``: submit, list, get, revise, cancel, approve, delete, arrays."""

from __future__ import annotations

import io
import logging
import math
from collections.abc import Callable, Coroutine
from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, Depends, HTTPException, Query, Request, Response, status
from fastapi.exceptions import RequestValidationError
from fastapi.routing import APIRoute
from pydantic import BaseModel, Field, ValidationError

from planners.errors import PlannerError
from server.auth import Operator, Viewer
from server.kinds import get_kind
from server.kinds.base import PlanKind, drop_unknown_keys
from server.lifecycle import PlanState
from server.routers.responses import AUTH, errors, json_text
from server.services import Services, get_services
from server.store import NotFoundError, PlanRecord
from server.store.database import utcnow
from server.store.maintenance import MaintenanceStore

log = logging.getLogger(__name__)


def _json_number_name(value: float) -> str:
    """How JSON-with-extensions (and Python's json) spells a non-finite number."""
    return "NaN" if math.isnan(value) else ("Infinity" if value > 0 else "-Infinity")


def json_safe(value: Any) -> Any:
    """``value`` with every NaN and infinity replaced by its name as a string:
    strict JSON, which every response is, has no such numbers."""
    if isinstance(value, float) and not math.isfinite(value):
        return _json_number_name(value)
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    return value


class JsonSafeErrorsRoute(APIRoute):
    """A route whose request-validation errors can always be sent.

    Python's json (so starlette) parses ``NaN`` and ``Infinity``; a body field
    refusing one reports it in the error's ``input``, which FastAPI's 422
    handler then fails to encode (strict JSON), answering 500.  Here such
    values are spelled as strings first, so the client gets its 422.
    """

    def get_route_handler(self) -> Callable[[Request], Coroutine[Any, Any, Response]]:
        handler = super().get_route_handler()

        async def route(request: Request) -> Response:
            try:
                return await handler(request)
            except RequestValidationError as exc:
                raise RequestValidationError(
                    json_safe(exc.errors()), body=json_safe(exc.body), endpoint_ctx=exc.endpoint_ctx
                ) from None

        return route


router = APIRouter(prefix="/plans", tags=["plans"], responses=AUTH, route_class=JsonSafeErrorsRoute)

Svc = Annotated[Services, Depends(get_services)]


class PlanRequest(BaseModel):
    kind: str = Field(..., description="plan kind (GET /kinds)", examples=["demo.route"])
    params: dict[str, Any] = Field(default_factory=dict, description="the kind's params")
    parent_id: str | None = Field(None, description="plan this one revises")


class ReviseRequest(BaseModel):
    params: dict[str, Any] = Field(
        default_factory=dict, description="params to change; the rest are the parent's"
    )


class ApproveRequest(BaseModel):
    comment: str = Field("", max_length=2000, description="why it is safe to run")


def non_finite_errors(params: dict[str, Any]) -> list[dict[str, Any]]:
    """A validation error (pydantic's form, ``loc`` the path in ``params``)
    for each NaN or infinity anywhere in ``params``, nested lists included.

    Checked before any model sees the params, for every kind alike: a model's
    own error would carry the value itself, which no JSON response can hold.
    Walked with a stack, not recursion, whatever the nesting depth."""
    found: list[dict[str, Any]] = []
    stack: list[tuple[tuple[str | int, ...], Any]] = [((), params)]
    while stack:
        loc, value = stack.pop()
        if isinstance(value, float) and not math.isfinite(value):
            found.append(
                {
                    "type": "finite_number",
                    "loc": list(loc),
                    "msg": "Input should be a finite number",
                    "input": _json_number_name(value),
                }
            )
        elif isinstance(value, dict):
            stack.extend(((*loc, k), v) for k, v in reversed(value.items()))
        elif isinstance(value, list | tuple):
            stack.extend(((*loc, i), v) for i, v in reversed(list(enumerate(value))))
    return found


def validate_params(services: Services, kind: PlanKind, params: dict[str, Any]) -> dict[str, Any]:
    """Validate ``params`` for ``kind``; 422 with a message naming what is wrong."""
    bad = non_finite_errors(params)
    if bad:
        raise HTTPException(422, detail=bad)
    try:
        model = kind.params_model.model_validate(params)
    except ValidationError as exc:
        raise HTTPException(
            422, detail=exc.errors(include_url=False, include_context=False)
        ) from None
    cloud_id = getattr(model, "cloud_id", None)
    if cloud_id is not None:
        try:
            cloud = services.store.get_cloud(cloud_id)
        except NotFoundError:
            raise HTTPException(
                422, detail=f"params.cloud_id: no stored cloud {cloud_id!r}"
            ) from None
        scale = (cloud.survey or {}).get("scale_to_m", 1.0)
        if getattr(model, "units", None) == "mm" and scale != 1.0:
            # the upload already turned its millimetres into metres: scaling
            # again would plan a structure a thousand times too small
            raise HTTPException(
                422,
                detail=f"params.units: cloud {cloud_id!r} was converted from millimetres to "
                "metres when it was uploaded; use units 'auto' or 'm'",
            )
    if kind.validate is not None:
        try:
            kind.validate(model)
        except PlannerError as exc:
            raise HTTPException(422, detail=str(exc)) from None
    return model.model_dump(mode="json")


def submit_plan(
    services: Services,
    kind_name: str,
    params: dict[str, Any],
    actor: str,
    parent_id: str | None = None,
) -> PlanRecord:
    """The one path every new plan takes: REST, console, CLI and scene proposals."""
    try:
        kind = get_kind(kind_name)
    except KeyError as exc:
        raise HTTPException(422, detail=str(exc)) from None
    if parent_id is not None:
        # Keys a revision inherits unchanged from a parent stored before params
        # forbade unknown keys are dropped; keys typed now are still checked.
        parent = services.store.get_plan(parent_id).params
        params, dropped = drop_unknown_keys(
            kind.params_model,
            params,
            only=lambda key: key in parent and params.get(key) == parent[key],
        )
        if dropped:
            log.info("revision of %s drops legacy params keys %s", parent_id, dropped)
    clean = validate_params(services, kind, params)
    plan = services.store.create_plan(kind.name, clean, actor, parent_id=parent_id)
    services.jobs.submit(plan.id)
    services.events.publish("plan", {"id": plan.id, "kind": plan.kind, "state": plan.state})
    return plan


@router.post("", status_code=status.HTTP_202_ACCEPTED, responses=errors(404))
def create_plan(
    req: PlanRequest, services: Svc, who: Operator, response: Response
) -> dict[str, Any]:
    """Queue a plan; poll ``GET /plans/{id}`` or watch ``/events`` for progress."""
    if req.parent_id is not None:
        services.store.get_plan(req.parent_id)
    plan = submit_plan(services, req.kind, req.params, who.actor, req.parent_id)
    response.headers["Location"] = f"/api/v1/plans/{plan.id}"
    return plan.public()


# The four polled reads (this listing, the plan detail, the executions) are
# ``async`` and read SQLite on the event loop: each is a few indexed queries
# and a splice of stored JSON text, well under a millisecond of work, while a
# worker-thread hop per poll put dozens of threads in the GIL's queue ahead
# of the loop under a console's polling (bench_busy: /health, itself
# thread-free, waited 280 ms at p95 behind them).


@router.get("", response_model=list[dict[str, Any]])
async def list_plans(
    services: Svc,
    _: Viewer,
    kind: str | None = None,
    state: Annotated[PlanState | None, Query(description="only plans in this state")] = None,
    parent_id: str | None = None,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
    offset: Annotated[int, Query(ge=0, le=10**9)] = 0,
) -> Response:
    """Plans, newest first, without their (possibly large) results."""
    body = services.store.list_plans_json(
        kind=kind,
        state=None if state is None else state.value,
        parent_id=parent_id,
        limit=limit,
        offset=offset,
    )
    return Response(body.encode("utf-8"), media_type="application/json")


@router.get("/{plan_id}", responses=errors(404), response_model=dict[str, Any])
async def get_plan(plan_id: str, services: Svc, _: Viewer) -> Response:
    """The plan with its result, program, audit trail and revisions.

    ``result`` and ``program`` go out as the JSON text they are stored as
    (strict JSON, written by the store), never decoded here.
    """
    plan, result_json, program_json = services.store.get_plan_json(plan_id)
    out = plan.public(include_result=False)
    out["audit"] = [e.public() for e in services.store.list_audit("plan", plan_id)]
    out["revisions"] = [
        p.id for p in services.store.list_plans(parent_id=plan_id, limit=500, summary=True)
    ]
    # a maintenance plan made from a finding links back to it
    link = MaintenanceStore(services.store.db).of_plan(plan_id)
    out["finding_id"] = None if link is None else link.finding_id
    head = json_text(out)
    body = f'{head[:-1]},"result":{result_json},"program":{program_json}}}'
    return Response(body.encode("utf-8"), media_type="application/json")


@router.post("/{plan_id}/revise", status_code=status.HTTP_202_ACCEPTED, responses=errors(404))
def revise_plan(
    plan_id: str, services: Svc, who: Operator, req: ReviseRequest | None = None
) -> dict[str, Any]:
    """A new plan with the parent's params updated by ``params``; the parent is unchanged."""
    parent = services.store.get_plan(plan_id)
    patch = req.params if req else {}
    plan = submit_plan(services, parent.kind, {**parent.params, **patch}, who.actor, plan_id)
    return plan.public()


@router.post("/{plan_id}/cancel", responses=errors(404, 409))
def cancel_plan(plan_id: str, services: Svc, who: Operator) -> dict[str, Any]:
    outcome = services.jobs.cancel(plan_id, who.actor)
    plan = services.store.get_plan(plan_id)
    return {"outcome": outcome, **plan.public(include_result=False)}


@router.post("/{plan_id}/approve", responses=errors(404, 409))
def approve_plan(
    plan_id: str, services: Svc, who: Operator, req: ApproveRequest | None = None
) -> dict[str, Any]:
    """Approve a planned plan whose checks all passed (409 otherwise)."""
    plan = services.store.get_plan(plan_id)
    failed = plan.failed_checks
    if failed:
        names = ", ".join(f"{c['name']} ({c.get('message', '')})" for c in failed)
        raise HTTPException(
            409,
            detail={
                "message": f"plan {plan_id} cannot be approved: failed checks: {names}",
                "state": plan.state,
                "failed_checks": [c["name"] for c in failed],
                "allowed_actions": ["revise", "delete"],
            },
        )
    comment = req.comment if req else ""
    plan = services.store.transition_plan(
        plan_id,
        "approve",
        who.actor,
        comment or "approved",
        expect=PlanState.PLANNED,
        approved_by=who.actor,
        approved_at=utcnow(),
    )
    services.events.publish("plan", {"id": plan.id, "kind": plan.kind, "state": plan.state})
    return plan.public()


@router.delete("/{plan_id}", status_code=204, responses=errors(404, 409))
def delete_plan(plan_id: str, services: Svc, who: Operator) -> Response:
    services.store.delete_plan(plan_id, who.actor)
    services.events.publish("plan", {"id": plan_id, "state": "deleted"})
    return Response(status_code=204)


@router.get(
    "/{plan_id}/arrays/{name}",
    responses={
        200: {
            "content": {"application/octet-stream": {}, "application/json": {}},
            "description": "the array as .npy, or JSON {shape, dtype, data}",
        },
        **errors(404, 413),
    },
)
def get_array(plan_id: str, name: str, services: Svc, _: Viewer, format: str = "npy") -> Response:
    """A stored result array as ``.npy`` (default) or JSON (``?format=json``)."""
    plan = services.store.get_plan(plan_id)
    try:
        arr = plan.array(name)
    except KeyError as exc:
        raise NotFoundError(str(exc.args[0])) from None
    if format == "json":
        if arr.size > 2_000_000:
            raise HTTPException(413, detail=f"array {name} has {arr.size} values; fetch it as npy")
        import json

        body = json.dumps({"shape": list(arr.shape), "dtype": str(arr.dtype), "data": arr.tolist()})
        return Response(body, media_type="application/json")
    if format != "npy":
        raise HTTPException(422, detail="format must be 'npy' or 'json'")
    buf = io.BytesIO()
    np.save(buf, arr, allow_pickle=False)
    return Response(buf.getvalue(), media_type="application/octet-stream")
