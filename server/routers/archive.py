"""``GET /api/v1/plans/{id}/export`` and ``POST /api/v1/imports``.

A plan's whole history — the plan, its arrays and source cloud, executions
(with acks, recorded states and MCAP), findings with photos, audit events —
as one zip, and its import on another server (:mod:`server.archive`).

Export is a read (viewer).  Import is admin only: it writes history in other
people's names (who created, approved, ran and found what, and when) that no
one on this server did, which an operator must not be able to forge; and it
may add a cloud of up to the upload limit.  An imported plan is
``archived``: never approvable or dispatchable here (see
:mod:`server.archive.import_` for the rule and why).
"""

from __future__ import annotations

import os
import tempfile
from typing import Annotated, Any

from fastapi import APIRouter, Depends, File, HTTPException, UploadFile
from fastapi.responses import FileResponse
from starlette.background import BackgroundTask

from server.archive import ArchiveError, export_plan, import_archive
from server.auth import Admin, Viewer
from server.routers.responses import errors
from server.services import Services, get_services

router = APIRouter(tags=["archive"])

Svc = Annotated[Services, Depends(get_services)]


@router.get(
    "/plans/{plan_id}/export",
    response_class=FileResponse,
    responses={
        200: {"content": {"application/zip": {}}, "description": "the plan's history as a zip"},
        **errors(401, 403, 404),
    },
)
def export_plan_archive(plan_id: str, services: Svc, who: Viewer) -> FileResponse:
    """The plan's history as ``steelpath-plan-<id>.zip``: ``manifest.json`` (format,
    versions, files with SHA-256, counts), ``plan.json``, ``arrays/*.npy``, the
    source cloud, ``executions/<id>.json`` + ``.mcap``, ``findings.json`` with
    ``photos/``, ``audit.json``."""
    fd, path = tempfile.mkstemp(prefix="steelpath-export-", suffix=".zip")
    try:
        with os.fdopen(fd, "wb") as out:
            export_plan(services.store, plan_id, out, who.actor)
    except BaseException:
        os.unlink(path)
        raise
    return FileResponse(
        path,
        media_type="application/zip",
        filename=f"steelpath-plan-{plan_id}.zip",
        background=BackgroundTask(os.unlink, path),
    )


@router.post("/imports", status_code=201, responses=errors(400, 401, 403, 409, 413, 422))
def import_plan_archive(
    services: Svc,
    who: Admin,
    file: Annotated[UploadFile, File(description="a zip made by GET /plans/{id}/export")],
) -> dict[str, Any]:
    """Import a plan archive from another server, all or nothing; the ids are
    kept and an existing one is never overwritten (409).  The plan comes in
    ``archived`` (history only: it cannot be approved or dispatched here)."""
    limit = services.settings.max_upload_bytes
    size = file.size
    if size is None:
        file.file.seek(0, os.SEEK_END)
        size = file.file.tell()
    file.file.seek(0)
    try:
        result = import_archive(services.store, file.file, size, limit=limit, actor=who.actor)
    except ArchiveError as exc:
        raise HTTPException(exc.status, detail=exc.detail) from None
    services.events.publish(
        "plan", {"id": result.plan_id, "kind": result.kind, "state": result.state}
    )
    return result.public()
