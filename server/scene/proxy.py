"""Authenticated reverse proxy to the viser scene, plus scene control endpoints.

viser has no authentication and listens on 127.0.0.1 only; the console
embeds ``/scene/`` from FastAPI, which forwards the page and the websocket
after checking the token (cookie from ``POST /api/v1/session`` or a bearer
header).  A viewer's scene is read-only: of what its browser sends, only the
camera reaches viser (:func:`viewer_may_send`), so its clicks pick,
measure and propose nothing.  viser's client derives its websocket address from the
page URL (``/scene/`` → ``ws://host/scene``), so both routes live here.

The websocket route also

- refuses cross-origin handshakes (a browser ``Origin`` other than this
  server's own ``Host``), since the session cookie is sent to any page on
  the same host, whatever its port;
- opens the upstream connection with a one-time ticket, without which viser
  refuses the handshake (:mod:`server.scene.wsguard`);
- closes the connection (code 1008) once its token is revoked or expires.

Scene proposals (``/api/v1/scene/proposals``): viewers list them, operators
accept (the plan is submitted through ``submit_plan`` as that operator; a
*finding* proposal's accept carries the finding's type, condition state and
notes and creates it as ``POST /api/v1/findings`` does) or dismiss them.
``POST /api/v1/scene/frame`` points the viewers' camera at a place or a
finding.
"""

from __future__ import annotations

import contextlib
import logging
from typing import Annotated, Any, Literal
from urllib.parse import urlsplit

import httpx
import msgspec
import websockets
from fastapi import APIRouter, Depends, HTTPException, Query, Request, Response, WebSocket
from fastapi.responses import RedirectResponse
from pydantic import BaseModel, ConfigDict, Field, StrictFloat, ValidationError, model_validator

from server.auth import Operator, TokenRefused, Viewer, resolve
from server.routers.findings import FindingType
from server.routers.plans import JsonSafeErrorsRoute
from server.routers.responses import errors
from server.scene.cloud_colours import ColourBy
from server.scene.proposals import STATES, ProposalBook, ProposalDecidedError
from server.scene.wsguard import TICKET_HEADER
from server.services import Services, get_services
from server.store import NotFoundError
from server.wsrelay import relay

log = logging.getLogger(__name__)

Svc = Annotated[Services, Depends(get_services)]

proxy_router = APIRouter(include_in_schema=False)
# JsonSafeErrorsRoute: a body holding NaN gets its 422, not a 500
api_router = APIRouter(prefix="/scene", tags=["scene"], route_class=JsonSafeErrorsRoute)

#: Anyone signed in sees the scene; only an operator acts in it (picks, proposals).
SCENE_ROLE = "viewer"
#: What a viewer's browser may send viser: its camera, nothing that acts.
VIEWER_MESSAGES = frozenset({"ViewerCameraMessage"})


def viewer_may_send(frame: bytes | str) -> bool:
    """Whether a read-only viewer's websocket frame goes to viser (allow-list)."""
    if not isinstance(frame, bytes):
        return False
    try:
        mapping = msgspec.msgpack.decode(frame)
    except msgspec.DecodeError:
        return False
    return isinstance(mapping, dict) and mapping.get("type") in VIEWER_MESSAGES


def _scene_port(services: Services) -> int:
    scene = services.scene
    if scene is None or not scene.running or scene.port is None:
        raise HTTPException(503, detail="the 3D scene is not running (STEELPATH_SCENE_PORT=0?)")
    return int(scene.port)


@proxy_router.get("/scene")
def scene_redirect() -> RedirectResponse:
    return RedirectResponse("/scene/")


@proxy_router.get("/scene/{path:path}")
async def scene_page(path: str, request: Request, services: Svc, _: Viewer) -> Response:
    port = _scene_port(services)
    async with httpx.AsyncClient(timeout=10.0) as client:
        upstream = await client.get(
            f"http://127.0.0.1:{port}/{path}",
            params=dict(request.query_params),
            headers={"accept-encoding": "identity"},
        )
    headers = {
        k: v
        for k, v in upstream.headers.items()
        if k.lower() in ("content-type", "cache-control", "etag", "last-modified")
    }
    return Response(upstream.content, status_code=upstream.status_code, headers=headers)


def same_origin(origin: str | None, host: str | None) -> bool:
    """A browser handshake's ``Origin`` must name this server (its ``Host``).

    Non-browser clients send no ``Origin``; they authenticate with a token
    they hold, so there is no ambient credential to misuse.
    """
    if origin is None:
        return True
    parts = urlsplit(origin)
    return parts.scheme in ("http", "https") and bool(host) and parts.netloc == host


@proxy_router.websocket("/scene")
@proxy_router.websocket("/scene/")
async def scene_socket(websocket: WebSocket) -> None:
    services: Services = websocket.app.state.services
    origin = websocket.headers.get("origin")
    if not same_origin(origin, websocket.headers.get("host")):
        log.warning("refused a cross-origin scene websocket (Origin %r)", origin)
        await websocket.close(code=1008)  # before accept: the handshake gets HTTP 403
        return
    token = websocket.cookies.get("steelpath_token")
    header = websocket.headers.get("authorization", "")
    if header.lower().startswith("bearer "):
        token = header[7:].strip()
    try:
        principal = resolve(services.store, token)
    except TokenRefused:
        principal = None
    if principal is None or not principal.has(SCENE_ROLE):
        # Closing before accept refuses the handshake (HTTP 403).
        await websocket.close(code=1008)
        return
    scene = services.scene
    if scene is None or not scene.running:
        await websocket.close(code=1013)
        return
    offered = [
        p.strip()
        for p in websocket.headers.get("sec-websocket-protocol", "").split(",")
        if p.strip()
    ]
    try:
        upstream = await websockets.connect(
            f"ws://127.0.0.1:{scene.port}/",
            additional_headers={TICKET_HEADER: scene.issue_ticket()},
            subprotocols=offered or None,  # type: ignore[arg-type]
            max_size=None,
            compression=None,
            open_timeout=10,
        )
    except OSError:
        await websocket.close(code=1011)
        return
    await websocket.accept(subprotocol=upstream.subprotocol)

    read_only = not principal.has("operator")
    await relay(
        websocket,
        upstream,
        services.store,
        principal,
        "scene",
        may_send=viewer_may_send if read_only else None,
    )


class ShowRequest(BaseModel):
    plan_id: str | None = None
    cloud_id: str | None = None
    colour_by: ColourBy = Field(
        "auto",
        description="a cloud's colours: rgb, intensity (its stored attributes), height; "
        "auto: rgb when the cloud has it, else height",
    )

    @model_validator(mode="after")
    def _one(self) -> ShowRequest:
        if (self.plan_id is None) == (self.cloud_id is None):
            raise ValueError("give exactly one of plan_id or cloud_id")
        return self


@api_router.get("")
def scene_state(services: Svc, _: Viewer) -> dict[str, Any]:
    scene = services.scene
    if scene is None or not scene.running:
        return {"running": False}
    return {
        "running": True,
        "path": "/scene/",
        "current": scene.current,
        "proposals": [p.public() for p in scene.proposals.list("pending")],
        "measurement": scene.measurer.public(),
    }


@api_router.delete("/measurement", status_code=204, responses=errors(401, 403))
def clear_measurement(services: Svc, _: Operator) -> Response:
    """Forget the last measurement and any first pick; remove its markers."""
    scene = services.scene
    if scene is not None:
        scene.clear_measurement()
    return Response(status_code=204)


@api_router.post("/show")
def scene_show(req: ShowRequest, services: Svc, _: Operator) -> dict[str, Any]:
    """Draw a stored plan or cloud in the shared scene."""
    scene = services.scene
    if scene is None or not scene.running:
        raise HTTPException(503, detail="the 3D scene is not running")
    if req.plan_id is not None:
        return scene.show_plan(req.plan_id)
    assert req.cloud_id is not None
    return scene.show_cloud(req.cloud_id, req.colour_by)


# --------------------------------------------------------------- proposals
def _book(services: Services) -> ProposalBook | None:
    scene = services.scene
    return None if scene is None else scene.proposals


def _decided(exc: ProposalDecidedError) -> HTTPException:
    return HTTPException(409, detail=f"{exc}; only pending proposals can be decided")


@api_router.get("/proposals", responses=errors(401, 403, 422))
def list_proposals(
    services: Svc,
    _: Viewer,
    state: Annotated[
        Literal["pending", "accepting", "accepted", "dismissed", "lapsed"] | None,
        Query(description=f"only proposals in this state (one of {', '.join(STATES)})"),
    ] = None,
) -> list[dict[str, Any]]:
    """Scene interactions waiting for (or given) an operator's decision, newest first."""
    book = _book(services)
    return [] if book is None else [p.public() for p in book.list(state)]


@api_router.get("/proposals/{proposal_id}", responses=errors(401, 403, 404))
def get_proposal(proposal_id: str, services: Svc, _: Viewer) -> dict[str, Any]:
    return _require_book(services).get(proposal_id).public()


def _require_book(services: Services) -> ProposalBook:
    book = _book(services)
    if book is None:
        raise NotFoundError("no scene proposals: the 3D scene is not running")
    return book


class FindingFields(BaseModel):
    """What an operator says about a finding proposal's place when accepting it."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    type: FindingType
    condition_state: int = Field(..., ge=1, le=4, description="1 good, 2 fair, 3 poor, 4 severe")
    notes: str = Field("", max_length=5000)


def _accept_finding(
    services: Services, book: ProposalBook, proposal_id: str, fields: FindingFields | None, who: Any
) -> dict[str, Any]:
    """A finding proposal accepted: the finding, made by ``POST /api/v1/findings``'s code."""
    from server.routers.findings import FindingCreate, create_finding

    if fields is None:
        raise HTTPException(
            422,
            detail=[
                {
                    "loc": ["body"],
                    "msg": "a finding proposal is accepted with its type and condition_state",
                    "type": "missing",
                }
            ],
        )
    proposal = book.begin_accept(proposal_id)
    try:
        try:
            req = FindingCreate(plan_id=proposal.plan_id, **proposal.patch, **fields.model_dump())
        except ValidationError as exc:
            raise HTTPException(422, detail=exc.errors(include_url=False)) from None
        finding = create_finding(req, services, who)
    except BaseException:
        book.abort_accept(proposal_id)
        raise
    proposal = book.finish_accept(proposal_id, None, who.actor, finding_id=finding["id"])
    if services.scene is not None:
        services.scene.proposal_decided(proposal_id)
    services.events.publish("proposal", proposal.public())
    return {**finding, "proposal_id": proposal.id}


@api_router.post(
    "/proposals/{proposal_id}/accept",
    status_code=202,
    responses=errors(401, 403, 404, 409, 422),
)
def accept_proposal(
    proposal_id: str,
    services: Svc,
    who: Operator,
    response: Response,
    finding: FindingFields | None = None,
) -> dict[str, Any]:
    """Make the proposed plan (a revision of the plan it derives from) as this
    operator; for a finding proposal (``action: finding``), the finding at its
    place with the body's type, condition state and notes (201)."""
    from server.routers.plans import submit_plan

    book = _require_book(services)
    try:
        if book.get(proposal_id).action == "finding":
            out = _accept_finding(services, book, proposal_id, finding, who)
            response.status_code = 201
            response.headers["Location"] = f"/api/v1/findings/{out['id']}"
            return out
        proposal = book.begin_accept(proposal_id)
    except ProposalDecidedError as exc:
        raise _decided(exc) from None
    try:
        parent = services.store.get_plan(proposal.plan_id)
        plan = submit_plan(
            services, parent.kind, {**parent.params, **proposal.patch}, who.actor, parent.id
        )
    except BaseException:
        book.abort_accept(proposal_id)
        raise
    proposal = book.finish_accept(proposal_id, plan.id, who.actor)
    services.store.audit(
        who.actor,
        "plan",
        plan.id,
        "accept_proposal",
        reason=f"scene proposal {proposal.id} from {proposal.source}: {proposal.patch}",
    )
    services.events.publish("proposal", proposal.public())
    if services.scene is not None:
        services.scene.follow(plan.id)
    response.headers["Location"] = f"/api/v1/plans/{plan.id}"
    return plan.public()


@api_router.post(
    "/proposals/{proposal_id}/dismiss",
    responses=errors(401, 403, 404, 409),
)
def dismiss_proposal(proposal_id: str, services: Svc, who: Operator) -> dict[str, Any]:
    try:
        proposal = _require_book(services).dismiss(proposal_id, who.actor)
    except ProposalDecidedError as exc:
        raise _decided(exc) from None
    if services.scene is not None:
        services.scene.proposal_decided(proposal_id)
    services.events.publish("proposal", proposal.public())
    return proposal.public()


# ----------------------------------------------------------------- framing
class FrameRequest(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    # StrictFloat takes 0 and 1.5 but not ``false``: a boolean is not a coordinate
    point_m: tuple[StrictFloat, StrictFloat, StrictFloat] | None = Field(
        None, description="look here (world, m)"
    )
    finding_id: str | None = Field(None, description="look at this finding's place")

    @model_validator(mode="after")
    def _one(self) -> FrameRequest:
        if (self.point_m is None) == (self.finding_id is None):
            raise ValueError("give exactly one of point_m or finding_id")
        return self


def _finding_place(services: Services, finding_id: str) -> tuple[list[float], Any]:
    """A finding's point (or its region's centre) and its face's normal, if any."""
    import numpy as np

    from server.routers.findings import _store

    f = _store(services).get(finding_id)
    pts = [f.point_m] if f.point_m is not None else list(f.region_m or [])
    if not pts:
        raise HTTPException(422, detail=f"finding {finding_id} has no place to look at")
    point = np.asarray(pts, dtype=float).mean(axis=0).tolist()
    normal = None
    if f.face_id is not None:
        with contextlib.suppress(Exception):  # the plan's model gone: the usual direction
            res = services.store.get_plan(f.plan_id).result or {}
            member = next(m for m in res.get("members", []) if m["id"] == f.member_id)
            normal = next(g["normal"] for g in member["faces"] if g["id"] == f.face_id)
    return point, normal


@api_router.post("/frame", responses=errors(401, 403, 404, 422, 503))
def scene_frame(req: FrameRequest, services: Svc, _: Operator) -> dict[str, Any]:
    """Point every viewer's camera at a place (``point_m``) or a finding
    (from in front of its face), about 1.6 m of the structure in view."""
    scene = services.scene
    if scene is None or not scene.running:
        raise HTTPException(503, detail="the 3D scene is not running")
    normal = None
    if req.finding_id is not None:
        point, normal = _finding_place(services, req.finding_id)
    else:
        assert req.point_m is not None
        point = list(req.point_m)
    return {"framed": point, "view": scene.frame_point(point, normal)}
