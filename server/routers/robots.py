"""``/api/v1/robots``, ``/plans/{id}/dispatch`` and ``/executions``."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, HTTPException, Query, Response
from fastapi.concurrency import run_in_threadpool
from pydantic import BaseModel, Field, field_validator

from server.auth import Admin, Operator, Viewer
from server.dispatch import DispatchError
from server.linkservice import LinkServiceClient
from server.routers.responses import errors, json_response
from server.services import Services, get_services

router = APIRouter(tags=["robots"])

Svc = Annotated[Services, Depends(get_services)]


def engine(services: Services) -> LinkServiceClient:
    if services.dispatch is None:
        raise HTTPException(503, detail="dispatch is not running")
    return services.dispatch


def _refuse(exc: DispatchError) -> HTTPException:
    return HTTPException(exc.status, detail=str(exc))


class ConnectionRequest(BaseModel):
    url: str = Field(
        ...,
        description="pyserial URL: /dev/ttyUSB0, socket://host:port, loop://, rfc2217://host:port",
        examples=["socket://127.0.0.1:5000"],
    )
    secret: str | None = Field(
        None,
        description="the robot's link secret as 64 hex characters (real hardware: the same "
        "secret the robot holds); omitted: keep the stored one. Never returned.",
        min_length=64,
        max_length=64,
        pattern="^[0-9a-fA-F]{64}$",
    )

    @field_validator("url")
    @classmethod
    def _looks_like_a_port(cls, v: str) -> str:
        v = v.strip()
        if not v:
            raise ValueError("url must not be empty")
        if "://" in v:
            scheme = v.split("://", 1)[0]
            if scheme not in {"socket", "loop", "rfc2217", "spy", "alt", "hwgrep"}:
                raise ValueError(
                    f"unsupported URL scheme {scheme!r}: use a device path, socket://host:port, "
                    "loop:// or rfc2217://host:port"
                )
        elif not v.startswith("/") and not v.upper().startswith("COM"):
            raise ValueError("a serial device must be an absolute path like /dev/ttyUSB0")
        return v


class DispatchRequest(BaseModel):
    robot: str = Field(..., description="robot name (GET /robots)")


class ResumeRequest(BaseModel):
    clear_faults: bool = Field(
        False, description="clear a latched robot fault first (only once its cause is fixed)"
    )


@router.get("/robots")
async def list_robots(services: Svc, _: Viewer) -> list[dict[str, Any]]:
    """Every robot's live status: one round trip to the link service, not one
    per robot; a recent shared answer comes straight from the event loop
    (at most 2 s old, and dropped at once on a link, E-stop or execution
    state change), refreshed in the background."""
    return await statuses_now(engine(services))


async def statuses_now(eng: LinkServiceClient) -> list[dict[str, Any]]:
    """Every robot's status: the recent shared answer when there is one (no
    waiting), else one round trip off the event loop.  ``GET /robots`` and
    the event stream's ``robots`` snapshots both read it here."""
    recent = getattr(eng, "recent_statuses", None)
    statuses = recent() if recent is not None else None
    if statuses is not None:
        return statuses
    return await run_in_threadpool(eng.robot_statuses)


@router.get("/robots/{name}/state")
def robot_state(name: str, services: Svc, _: Viewer) -> dict[str, Any]:
    """Live link status and the last state report (also persisted, 2 Hz)."""
    status = engine(services).robot_status(name)
    stored = services.store.robot_state(name)
    status["stored_report"] = stored[0] if stored else None
    status["stored_at"] = stored[1] if stored else None
    return status


@router.put("/robots/{name}/connection")
def set_connection(name: str, req: ConnectionRequest, services: Svc, who: Admin) -> dict[str, Any]:
    """Persist the robot's connection URL and reconnect."""
    try:
        return engine(services).set_connection(name, req.url, who.actor, req.secret)
    except DispatchError as exc:
        raise _refuse(exc) from None


@router.post("/robots/{name}/takeover")
def takeover(name: str, services: Svc, who: Operator) -> dict[str, Any]:
    """Take the robot's line over from another controller that holds it.

    The robot refuses every second controller while one is alive; this is the
    explicit operator action that makes it drop the other one (stopping any
    motion) and accept this server.  It still needs this server's secret.
    """
    try:
        return engine(services).takeover(name, who.actor)
    except DispatchError as exc:
        raise _refuse(exc) from None


@router.post("/robots/{name}/clear-estop")
def clear_estop(name: str, services: Svc, who: Operator) -> dict[str, Any]:
    return engine(services).clear_estop(name, who.actor)


@router.post("/plans/{plan_id}/dispatch", status_code=201)
def dispatch(plan_id: str, req: DispatchRequest, services: Svc, who: Operator) -> dict[str, Any]:
    """Send an approved plan whose checks passed to a connected robot."""
    try:
        ex = engine(services).dispatch(plan_id, req.robot, who.actor)
    except DispatchError as exc:
        raise _refuse(exc) from None
    return ex.public()


# async: a polled read of a few rows, cheaper on the event loop than a
# worker-thread hop (see server/routers/plans.py).
@router.get("/executions", response_model=list[dict[str, Any]])
async def list_executions(
    services: Svc,
    _: Viewer,
    plan_id: str | None = None,
    state: str | None = None,
    limit: Annotated[int, Query(ge=1, le=500)] = 100,
    offset: Annotated[int, Query(ge=0, le=10**9)] = 0,
) -> Response:
    """Executions, newest first; page with ``limit`` and ``offset``."""
    rows = services.store.list_executions(plan_id, state, limit=limit, offset=offset)
    return json_response([e.public() for e in rows])


@router.get("/executions/{execution_id}", response_model=dict[str, Any])
async def get_execution(execution_id: str, services: Svc, _: Viewer) -> Response:
    ex = services.store.get_execution(execution_id)
    out = ex.public()
    out["current_command"] = services.store.plan_command(ex.plan_id, ex.acked)
    out["audit"] = [e.public() for e in services.store.list_audit("execution", execution_id)]
    return json_response(out)


@router.get(
    "/executions/{execution_id}/recording.mcap",
    responses={
        200: {
            "content": {"application/octet-stream": {}, "application/zip": {}},
            "description": "the run as MCAP, or as a zipped ROS 2 bag with format=rosbag2",
        },
        **errors(401, 403, 404, 422),
    },
)
def execution_recording(
    execution_id: str,
    services: Svc,
    _: Viewer,
    format: Annotated[
        Literal["mcap", "rosbag2"],
        Query(description="mcap (default) or rosbag2: a ROS 2 bag directory, zipped"),
    ] = "mcap",
) -> Response:
    """The run as an MCAP file (Foxglove / Lichtblick): the planned program,
    each command at its acknowledgement, the robot's state reports, link
    frames and tool pose while it ran, the planned path, the plan's stored
    cloud and the operator's actions; or, with ``format=rosbag2``, as a ROS 2
    bag (joint states, tool pose, path, cloud) zipped (see
    :mod:`server.recording`)."""
    import io

    from server.recording import plan_cloud, write_recording, write_rosbag2

    store = services.store
    ex = store.get_execution(execution_id)
    plan = store.get_plan(ex.plan_id)
    cloud = plan_cloud(store, plan)
    states = store.execution_states(ex.id)
    if format == "rosbag2":
        data, _counts = write_rosbag2(ex, plan, states, cloud=cloud)
        return Response(
            data,
            media_type="application/zip",
            headers={"Content-Disposition": f'attachment; filename="{ex.id}.rosbag2.zip"'},
        )
    audit = store.list_audit("execution", ex.id, limit=10_000) + store.list_audit(
        "plan", plan.id, limit=10_000
    )
    buf = io.BytesIO()
    write_recording(buf, ex, plan, store.ack_times(ex.id), states, audit, cloud=cloud)
    return Response(
        buf.getvalue(),
        media_type="application/octet-stream",
        headers={"Content-Disposition": f'attachment; filename="{ex.id}.mcap"'},
    )


@router.post("/executions/{execution_id}/pause")
def pause(execution_id: str, services: Svc, who: Operator) -> dict[str, Any]:
    try:
        return engine(services).pause(execution_id, who.actor).public()
    except DispatchError as exc:
        raise _refuse(exc) from None


@router.post("/executions/{execution_id}/resume")
def resume(
    execution_id: str, services: Svc, who: Operator, req: ResumeRequest | None = None
) -> dict[str, Any]:
    try:
        ex = engine(services).resume(execution_id, who.actor, bool(req and req.clear_faults))
    except DispatchError as exc:
        raise _refuse(exc) from None
    return ex.public()


@router.post("/executions/{execution_id}/abort")
def abort(execution_id: str, services: Svc, who: Operator) -> dict[str, Any]:
    return engine(services).abort(execution_id, who.actor).public()
