"""Routes of what the robot's camera saw: ``/executions/{id}/captures``, ``/scene/captures``.

Viewer reads (like the execution, its replay and its recording); showing
captures in the 3D scene is an operator's action, like every scene action.
A capture's points are served in the plan's ``world`` frame (the camera pose
applied, float64), at most ``max_points`` of them (every ``stride``-th).
"""

from __future__ import annotations

from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, Depends, HTTPException, Path, Query, Response
from fastapi.concurrency import run_in_threadpool
from pydantic import BaseModel, Field

from server.auth import Operator, Viewer
from server.captures.store import CaptureStore
from server.recording.channels import iso_ns
from server.routers.responses import errors, json_response
from server.services import Services, get_services

router = APIRouter(tags=["captures"])

Svc = Annotated[Services, Depends(get_services)]

#: Most points one ``GET …/captures/{capture_id}`` returns.
MAX_POINTS = 200_000


def _list(services: Services, execution_id: str) -> dict[str, Any]:
    ex = services.store.get_execution(execution_id)  # NotFoundError: 404
    captures = CaptureStore(services.store)
    start = iso_ns(ex.created_at) / 1e9
    recs = captures.list(ex.id)
    lim = captures.limits
    return {
        "execution_id": ex.id,
        "plan_id": ex.plan_id,
        "robot": ex.robot,
        "started_at": ex.created_at,
        "frame_id": "world",
        "captures": [r.public(start) for r in recs],
        "totals": {"captures": len(recs), "points": sum(r.n_points for r in recs)},
        "limits": {
            "captures": lim.capture_max_per_execution,
            "points": lim.capture_max_points_per_execution,
        },
    }


@router.get(
    "/executions/{execution_id}/captures",
    response_model=dict[str, Any],
    responses=errors(401, 403, 404),
)
async def list_captures(execution_id: str, services: Svc, _: Viewer) -> Response:
    """What the robot's camera saw during the run, in the order the host
    received it: per capture its id, ``t_s`` (seconds after the execution's
    start; ``t_robot_s`` on the robot's clock), the ``capture`` command's
    index, the camera pose (camera → world: position, 3×3 rotation whose
    columns are the camera's axes), its point count and whether every point
    announced arrived (``complete``)."""
    return json_response(await run_in_threadpool(_list, services, execution_id))


def _one(services: Services, execution_id: str, capture_id: int, max_points: int) -> dict[str, Any]:
    ex = services.store.get_execution(execution_id)
    captures = CaptureStore(services.store)
    rec = captures.get(ex.id, capture_id)
    pts = captures.world_points(rec)
    inten = captures.intensity(rec)
    stride = max(1, -(-len(pts) // max_points))
    pts = pts[::stride]
    out = rec.public(iso_ns(ex.created_at) / 1e9)
    out.update(
        {
            "frame_id": "world",
            "stride": stride,
            "returned_points": len(pts),
            "points_m": np.round(pts, 6).tolist(),
            "intensity": None if inten is None else inten[::stride].tolist(),
        }
    )
    return out


@router.get(
    "/executions/{execution_id}/captures/{capture_id}",
    response_model=dict[str, Any],
    responses=errors(401, 403, 404, 422),
)
async def get_capture(
    execution_id: str,
    capture_id: Annotated[int, Path(ge=0, le=2**63 - 1, description="the robot's capture id")],
    services: Svc,
    _: Viewer,
    max_points: Annotated[
        int, Query(ge=1, le=MAX_POINTS, description="at most this many points (thinned above)")
    ] = 100_000,
) -> Response:
    """One capture with its points in the plan's ``world`` frame (metres,
    rounded to the micrometre), ``intensity`` (0–255) if it has one; above
    ``max_points`` every ``stride``-th point."""
    out = await run_in_threadpool(_one, services, execution_id, capture_id, max_points)
    return json_response(out)


class SceneCaptures(BaseModel):
    execution_id: str = Field(..., min_length=1, max_length=200)
    up_to_s: float | None = Field(
        None, ge=-1e7, le=1e7, description="only captures received by then (s after the start)"
    )


def _scene(services: Services) -> Any:
    scene = services.scene
    if scene is None or not scene.running:
        raise HTTPException(409, detail="the 3D scene is not running: nothing to show captures in")
    return scene


@router.post("/scene/captures", responses=errors(401, 403, 404, 409, 422))
def scene_captures_show(req: SceneCaptures, services: Svc, _: Operator) -> dict[str, Any]:
    """Show the execution's plan (unless shown) and what the robot's camera
    saw (the latest 50 captures, or those received by ``up_to_s``) over it;
    later captures of the run are drawn as they arrive."""
    from server.scene import captures as scene_captures

    scene = _scene(services)
    scene_captures.follow(scene, services.events)
    try:
        return scene_captures.show(scene, req.execution_id, req.up_to_s)
    except scene_captures.CaptureSceneError as exc:
        raise HTTPException(409, detail=str(exc)) from None


@router.delete("/scene/captures", status_code=204, responses=errors(401, 403, 409))
def scene_captures_clear(services: Svc, _: Operator) -> Response:
    """Remove the drawn captures; the plan stays shown."""
    from server.scene import captures as scene_captures

    scene_captures.clear(_scene(services))
    return Response(status_code=204)
