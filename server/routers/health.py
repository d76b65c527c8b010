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
        "disk": _disk(services),
    }


def _disk(services: Services) -> dict[str, Any]:
    """The data volume: ``ok``, ``low`` (under 512 MiB above the reserve) or ``full``
    (at the reserve: writes answer 507), and safety records not yet written."""
    gauge = services.disk
    backlog = services.audit_backlog
    pending = backlog.pending() if backlog is not None else 0
    if gauge is None:
        return {"state": "ok", "free_mb": None, "audit_pending": pending}
    reading = gauge.read()
    return {
        "state": reading.state,
        "free_mb": round(reading.free_bytes / 2**20, 1),
        "reserve_mb": round(gauge.reserve_bytes / 2**20, 1),
        "audit_pending": pending,
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
