"""``/api/v1/robots``, ``/plans/{id}/dispatch`` and ``/executions``."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, HTTPException, Query, Request, Response
from fastapi.concurrency import run_in_threadpool
from pydantic import BaseModel, Field, field_validator

from server.auth import Admin, Operator, Principal, Viewer, token_from_request
from server.diskspace import describe
from server.dispatch import DispatchError
from server.linkservice import LinkServiceClient
from server.ownership.peers import FORWARDED_HEADER
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


def _forward(
    services: Services,
    request: Request,
    response: Response,
    robot: str | None,
    body: Any = None,
    *,
    read_only: bool = False,
) -> dict[str, Any] | None:
    """Send this request to ``robot``'s owner when another server drives it; its
    answer (status and body) becomes ours.  ``None``: act here.

    Alone (no other live server) nothing is looked up.  The cached owner is
    confirmed from the store before forwarding; a forwarded request is never
    forwarded again: if the robot moved meanwhile, this server's engine
    refuses it (503, try again).  A read (``read_only``) whose owner does not
    answer is served here from the store instead.
    """
    peers = services.peers
    if robot is None or peers is None or not peers.others():
        return None
    if request.headers.get(FORWARDED_HEADER):
        return None
    if robot not in engine(services).robot_names():
        return None  # the engine answers 404
    cached = peers.owner(robot)
    if cached is not None and cached.server_id == peers.server_id:
        return None
    lease = peers.owner(robot, fresh=True)
    if lease is None or lease.server_id == peers.server_id:
        return None
    path = request.url.path + (f"?{request.url.query}" if request.url.query else "")
    got = peers.forward(lease, request.method, path, token_from_request(request), body)
    if read_only and not got.answered:
        return None
    response.status_code = got.status
    response.headers["X-SteelPath-Served-By"] = got.server_id
    return dict(got.body) if isinstance(got.body, dict) else {"detail": got.body}


def _execution_robot(services: Services, execution_id: str) -> str | None:
    """The robot of an execution, only when other servers share the store (else no read)."""
    if services.peers is None or not services.peers.others():
        return None
    return services.store.get_execution(execution_id).robot


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
    return await statuses_now(engine(services), services.peers)


async def statuses_now(eng: LinkServiceClient, peers: Any = None) -> list[dict[str, Any]]:
    """Every robot's status: the recent shared answer when there is one (no
    waiting), else one round trip off the event loop.  ``GET /robots`` and
    the event stream's ``robots`` snapshots both read it here."""
    recent = getattr(eng, "recent_statuses", None)
    statuses: list[dict[str, Any]] | None = recent() if recent is not None else None
    if statuses is None:
        statuses = await run_in_threadpool(eng.robot_statuses)
    return _with_owners(statuses, peers)


def _with_owners(statuses: list[dict[str, Any]], peers: Any) -> list[dict[str, Any]]:
    """Which server owns each robot (``owner``, ``owner_url``, ``owned_here``)."""
    if peers is None:
        return statuses
    for s in statuses:
        s.update(peers.describe(s["name"]))
    return statuses


@router.get("/robots/{name}/state")
def robot_state(
    name: str, services: Svc, _: Viewer, request: Request, response: Response
) -> dict[str, Any]:
    """Live link status and the last state report (also persisted, 2 Hz); from
    the robot's owner when another server drives it."""
    fwd = _forward(services, request, response, name, read_only=True)
    if fwd is not None:
        return fwd
    status = engine(services).robot_status(name)
    if services.peers is not None:
        status.update(services.peers.describe(name))
    stored = services.store.robot_state(name)
    status["stored_report"] = stored[0] if stored else None
    status["stored_at"] = stored[1] if stored else None
    return status


@router.put("/robots/{name}/connection")
def set_connection(
    name: str,
    req: ConnectionRequest,
    services: Svc,
    who: Admin,
    request: Request,
    response: Response,
) -> dict[str, Any]:
    """Persist the robot's connection URL and reconnect (on the robot's owner)."""
    fwd = _forward(services, request, response, name, req.model_dump())
    if fwd is not None:
        return fwd
    try:
        return engine(services).set_connection(name, req.url, who.actor, req.secret)
    except DispatchError as exc:
        raise _refuse(exc) from None


@router.post("/robots/{name}/takeover")
def takeover(
    name: str, services: Svc, who: Operator, request: Request, response: Response
) -> dict[str, Any]:
    """Take the robot's line over from another controller that holds it.

    The robot refuses every second controller while one is alive; this is the
    explicit operator action that makes it drop the other one (stopping any
    motion) and accept this server.  It still needs this server's secret.
    """
    fwd = _forward(services, request, response, name)
    if fwd is not None:
        return fwd
    try:
        return engine(services).takeover(name, who.actor)
    except DispatchError as exc:
        raise _refuse(exc) from None


@router.post("/robots/{name}/clear-estop")
def clear_estop(
    name: str, services: Svc, who: Operator, request: Request, response: Response
) -> dict[str, Any]:
    """Clear the robot's E-stop latch (and one held for it): recorded first, so a
    store that cannot record it (a full disk) leaves the robot stopped (409)."""
    if services.peers is not None and name in services.peers.store.held_estops():
        # An E-stop held for the robot's next driver is cleared with it.
        try:
            services.store.audit(who.actor, "robot", name, "clear-held-estop")
        except Exception as exc:
            raise HTTPException(
                409,
                detail=f"{name} stays E-stopped: the clear-estop could not be recorded "
                f"({describe(exc)}); free space on the server and try again",
            ) from None
        services.peers.store.take_estops([name])
    fwd = _forward(services, request, response, name)
    if fwd is not None:
        return fwd
    try:
        return engine(services).clear_estop(name, who.actor)
    except DispatchError as exc:
        raise _refuse(exc) from None


@router.post("/plans/{plan_id}/dispatch", status_code=201)
def dispatch(
    plan_id: str,
    req: DispatchRequest,
    services: Svc,
    who: Operator,
    request: Request,
    response: Response,
) -> dict[str, Any]:
    """Send an approved plan whose checks passed to a connected robot (through
    the server that drives it)."""
    fwd = _forward(services, request, response, req.robot, req.model_dump())
    if fwd is not None:
        return fwd
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
    from server.recording.captures import load_captures

    store = services.store
    ex = store.get_execution(execution_id)
    plan = store.get_plan(ex.plan_id)
    cloud = plan_cloud(store, plan)
    states = store.execution_states(ex.id)
    captures = load_captures(store, ex.id, ex.robot, plan)
    if format == "rosbag2":
        data, _counts = write_rosbag2(ex, plan, states, cloud=cloud, captures=captures)
        return Response(
            data,
            media_type="application/zip",
            headers={"Content-Disposition": f'attachment; filename="{ex.id}.rosbag2.zip"'},
        )
    audit = store.list_audit("execution", ex.id, limit=10_000) + store.list_audit(
        "plan", plan.id, limit=10_000
    )
    buf = io.BytesIO()
    write_recording(
        buf, ex, plan, store.ack_times(ex.id), states, audit, cloud=cloud, captures=captures
    )
    return Response(
        buf.getvalue(),
        media_type="application/octet-stream",
        headers={"Content-Disposition": f'attachment; filename="{ex.id}.mcap"'},
    )


def _execution_op(
    op: Literal["pause", "abort"],
    execution_id: str,
    services: Services,
    who: Principal,
    request: Request,
    response: Response,
) -> dict[str, Any]:
    """Pause or abort, on the server that drives the execution's robot."""
    fwd = _forward(services, request, response, _execution_robot(services, execution_id))
    if fwd is not None:
        return fwd
    eng = engine(services)
    act = eng.pause if op == "pause" else eng.abort
    try:
        return act(execution_id, who.actor).public()
    except DispatchError as exc:
        raise _refuse(exc) from None


@router.post("/executions/{execution_id}/pause")
def pause(
    execution_id: str, services: Svc, who: Operator, request: Request, response: Response
) -> dict[str, Any]:
    return _execution_op("pause", execution_id, services, who, request, response)


@router.post("/executions/{execution_id}/resume")
def resume(
    execution_id: str,
    services: Svc,
    who: Operator,
    request: Request,
    response: Response,
    req: ResumeRequest | None = None,
) -> dict[str, Any]:
    robot = _execution_robot(services, execution_id)
    fwd = _forward(services, request, response, robot, req.model_dump() if req else None)
    if fwd is not None:
        return fwd
    try:
        ex = engine(services).resume(execution_id, who.actor, bool(req and req.clear_faults))
    except DispatchError as exc:
        raise _refuse(exc) from None
    return ex.public()


@router.post("/executions/{execution_id}/abort")
def abort(
    execution_id: str, services: Svc, who: Operator, request: Request, response: Response
) -> dict[str, Any]:
    return _execution_op("abort", execution_id, services, who, request, response)
