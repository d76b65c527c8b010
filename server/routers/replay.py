"""Routes of replay: a recorded run replayed in the console.

``GET /executions/{id}/replay`` (viewer) is the run's recorded timeline;
``POST /scene/replay`` and ``DELETE /scene/replay`` (operator, like every
scene action: the scene can propose plans) show and remove the replay robot
(:mod:`server.scene.replay`).
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends, HTTPException, Response
from fastapi.concurrency import run_in_threadpool
from pydantic import BaseModel, Field

from server.auth import Operator, Viewer
from server.routers.responses import errors, json_response
from server.scene import replay as scene_replay
from server.services import Services, get_services

router = APIRouter(tags=["replay"])

Svc = Annotated[Services, Depends(get_services)]


@router.get(
    "/executions/{execution_id}/replay",
    response_model=dict[str, Any],
    responses=errors(401, 403, 404),
)
async def execution_replay(execution_id: str, services: Svc, _: Viewer) -> Response:
    """The recorded timeline of a run: the robot's state reports (``t_s``
    after the execution's start; at most
    :data:`server.scene.replay.MAX_SAMPLES`, thinned above it as
    ``thinning`` says), the acknowledged commands and the operator's actions
    with their times, and the run's duration."""
    out = await run_in_threadpool(scene_replay.timeline, services.store, execution_id)
    return json_response(out)


class ReplayRequest(BaseModel):
    execution_id: str = Field(..., min_length=1, max_length=200)
    t_s: float = Field(
        ..., ge=-1e7, le=1e7, description="seconds after the execution's start (clamped)"
    )


def _scene(services: Services) -> Any:
    scene = services.scene
    if scene is None or not scene.running:
        raise HTTPException(409, detail="the 3D scene is not running: nothing to replay into")
    return scene


@router.post("/scene/replay", responses=errors(401, 403, 404, 409, 422))
def scene_replay_show(req: ReplayRequest, services: Svc, _: Operator) -> dict[str, Any]:
    """Show the execution's plan (unless shown) and the *replay robot*
    (blue, ``…/replay``) at the robot's recorded joints at ``t_s``,
    interpolated between the state reports around it."""
    scene = _scene(services)
    try:
        return scene_replay.show(scene, req.execution_id, req.t_s)
    except scene_replay.ReplayError as exc:
        raise HTTPException(409, detail=str(exc)) from None


@router.delete("/scene/replay", status_code=204, responses=errors(401, 403, 409))
def scene_replay_clear(services: Svc, _: Operator) -> Response:
    """Remove the replay robot; the plan stays shown."""
    scene_replay.clear(_scene(services))
    return Response(status_code=204)
