"""``GET /api/v1/health`` (public) and ``GET /api/v1/kinds``."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Depends

from server import __version__
from server.auth import Viewer
from server.kinds import import_errors, registry
from server.routers.responses import AUTH
from server.services import Services, get_services
from server.store.migrations import SCHEMA_VERSION

router = APIRouter(tags=["health"])


@router.get("/health")
async def health(services: Annotated[Services, Depends(get_services)]) -> dict[str, Any]:
    """Liveness and what this server can do; needs no token.

    ``async`` and lock-free: it answers from the event loop without waiting
    for a worker thread, which a loaded server may have none of to spare.
    """
    scene = services.scene
    return {
        "status": "ok",
        "version": __version__,
        "schema_version": SCHEMA_VERSION,
        "kinds": sorted(registry()),
        "kind_errors": import_errors(),
        "scene": {"running": bool(scene and scene.running), "path": "/scene/"},
        "jobs": {"mode": services.jobs.mode, "running": services.jobs.running_count()},
    }


@router.get("/kinds", responses=AUTH)
def kinds(_: Viewer) -> list[dict[str, Any]]:
    """Every plan kind with its params JSON schema and defaults."""
    out = []
    for kind in registry().values():
        out.append(
            {
                "name": kind.name,
                "title": kind.title,
                "description": kind.description.strip(),
                "robot": kind.robot,
                "samples": sorted(kind.samples),
                "params_schema": kind.params_model.model_json_schema(),
                "defaults": kind.params_model().model_dump(mode="json"),
                "compiles": kind.compile is not None,
            }
        )
    return out
