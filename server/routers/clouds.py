"""``/api/v1/clouds``: upload (file or sample), list, get, download, delete.

An uploaded file never passes through the event loop whole: the request body
is streamed in chunks to ``<data>/uploads/.tmp-upload-*`` (writes in a worker
thread), then a niced child process (``python -m server.cloud_io upload``)
finds the multipart ``file`` part by byte range, parses it in chunks and
writes the cloud's ``.npy`` atomically; the handler only awaits the child.
So the API, ``/health`` and the E-stop keep answering while a large cloud is
parsed, and memory stays a few chunks in both processes.  At most
:data:`PARSE_SLOTS` parses run at once per app.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import os
import sys
import tempfile
from pathlib import Path
from typing import Annotated, Any

import anyio
import numpy as np
from fastapi import APIRouter, Depends, HTTPException, Query, Request, Response, status
from fastapi.responses import FileResponse
from pydantic import BaseModel, Field, ValidationError

from planners.pointcloud.spacing import measure_spacing
from server.auth import Operator, Viewer
from server.kinds import get_kind, sample_names
from server.routers.responses import AUTH, errors
from server.services import Services, get_services
from server.store import new_id
from server.store.store import cloud_attribute_relname
from server.survey_io import UPLOAD_UNITS

log = logging.getLogger(__name__)

router = APIRouter(prefix="/clouds", tags=["clouds"], responses=AUTH)

Svc = Annotated[Services, Depends(get_services)]

#: The upload parser's command line (before its arguments); tests may wrap it.
PARSER: list[str] = [sys.executable, "-m", "server.cloud_io"]
#: Concurrent upload parses per app (each is one child process).
PARSE_SLOTS = 2
#: Body bytes buffered before one write to the spool file.
SPOOL_CHUNK = 1 << 20


class SampleRequest(BaseModel):
    sample: str = Field(..., description="name of a sample scene (GET /clouds/samples)")
    seed: int = Field(0, ge=0, le=2**31 - 1, description="generator seed")
    name: str | None = Field(None, description="display name; defaults to the sample name")


_UPLOAD_BODY: dict[str, Any] = {
    "requestBody": {
        "required": True,
        "content": {
            "multipart/form-data": {
                "schema": {
                    "type": "object",
                    "required": ["file"],
                    "properties": {
                        "file": {
                            "type": "string",
                            "format": "binary",
                            "description": "PLY, PCD (ascii/binary), XYZ/CSV, NPY, LAS/LAZ or E57",
                        },
                        "name": {"type": "string", "description": "display name"},
                        "units": {
                            "type": "string",
                            "enum": list(UPLOAD_UNITS),
                            "description": "unit of the file's coordinates (m, mm, ft: "
                            "international feet, us-ft: US survey feet); auto (default) "
                            "takes the unit of the file's CRS (LAS/LAZ) when it names "
                            "one, else decides metres or millimetres from the measured "
                            "point spacing; the cloud is stored in metres",
                        },
                    },
                }
            },
            "application/json": {"schema": SampleRequest.model_json_schema()},
        },
    }
}


@router.get("/samples")
def list_samples(_: Viewer) -> dict[str, str]:
    """Sample scene name → the plan kind that provides it."""
    return sample_names()


@router.post(
    "",
    status_code=status.HTTP_201_CREATED,
    responses=errors(400, 413, 415, 422),
    openapi_extra=_UPLOAD_BODY,
)
async def upload_cloud(request: Request, services: Svc, who: Operator) -> dict[str, Any]:
    """Store a cloud: multipart ``file`` (PLY, PCD ascii/binary, XYZ/CSV, NPY,
    LAS/LAZ, E57) with optional ``name`` and ``units`` (auto | m | mm | ft |
    us-ft), or JSON ``{"sample": name}``.  Non-finite rows are dropped and
    counted.  The response's ``survey`` says how the file was read: format,
    units, how (``units_from``: from the CRS, detected, set by the request)
    and why, the scale applied to reach metres, the CRS (name, EPSG code),
    the measured point spacing and the per-point attributes kept
    (intensity, rgb, classification: ``GET /clouds/{id}/attributes/{name}``);
    ``crs_wkt`` is the file's CRS in full.  See docs/uploads.md."""
    ctype = request.headers.get("content-type", "")
    if ctype.startswith("application/json"):
        rec = await _store_sample(request, services, who.actor)
    elif ctype.startswith("multipart/form-data"):
        rec = await _store_upload(request, services, who.actor, ctype)
    else:
        raise HTTPException(
            415,
            detail="send multipart/form-data with a 'file' field, or JSON {\"sample\": name}",
        )
    services.events.publish("cloud", {"id": rec.id, "n_points": rec.n_points})
    return rec.public()


async def _store_sample(request: Request, services: Services, actor: str) -> Any:
    try:
        req = SampleRequest.model_validate(await request.json())
    except ValidationError as exc:
        raise HTTPException(422, detail=exc.errors(include_url=False)) from None
    except ValueError:
        raise HTTPException(400, detail="request body is not valid JSON") from None
    samples = sample_names()
    if req.sample not in samples:
        raise HTTPException(
            422,
            detail=f"unknown sample {req.sample!r}; available: {', '.join(sorted(samples))}",
        )
    fn = get_kind(samples[req.sample]).samples[req.sample]

    def make() -> Any:  # generators can take a while: off the event loop
        points = np.asarray(fn(req.seed), dtype=np.float64)
        finite = np.isfinite(points).all(axis=1)
        spacing = measure_spacing(points[finite])
        return services.store.add_cloud(
            req.name or req.sample,
            f"sample:{req.sample}:{req.seed}",
            points[finite],
            int((~finite).sum()),
            actor,
            survey={
                "format": "sample",
                "units": "m",
                "units_reason": "sample generators work in metres",
                "scale_to_m": 1.0,
                "spacing_m": spacing,
            },
        )

    return await anyio.to_thread.run_sync(make)


async def _store_upload(request: Request, services: Services, actor: str, ctype: str) -> Any:
    spool_dir = services.store.data_dir / "uploads"
    raw = await _spool_body(request, spool_dir)
    cid = new_id("cl")
    out = services.store.arrays.path(f"clouds/{cid}.npy")
    try:
        outcome = await _parse(request, raw, ctype, out)
    finally:
        raw.unlink(missing_ok=True)

    def remove_arrays() -> None:
        out.unlink(missing_ok=True)
        for name in outcome.get("attributes") or []:
            services.store.arrays.delete(cloud_attribute_relname(cid, str(name)))

    if not outcome.get("ok"):
        remove_arrays()
        if outcome.get("log"):  # the reader's full report: for us, not the uploader
            log.warning("upload refused (%s): %s", outcome.get("detail"), outcome["log"])
        raise HTTPException(int(outcome.get("status", 400)), detail=str(outcome.get("detail")))
    filename = outcome.get("filename") or ""
    log.info(
        "parsed upload %s: %d points, %d dropped, parser peak RSS %.0f MB",
        filename,
        outcome["n_points"],
        outcome["dropped"],
        outcome.get("peak_rss_kb", 0) / 1024,
    )
    try:
        return await anyio.to_thread.run_sync(
            lambda: services.store.register_cloud(
                cid,
                str(outcome.get("name") or filename or "upload"),
                f"upload:{filename}",
                int(outcome["n_points"]),
                outcome["bounds"],
                int(outcome["dropped"]),
                actor,
                survey=outcome.get("survey"),
                crs_wkt=outcome.get("crs_wkt"),
                attributes=[str(a) for a in outcome.get("attributes") or []],
            )
        )
    except BaseException:
        remove_arrays()  # no row will refer to them
        raise


async def _spool_body(request: Request, spool_dir: Path) -> Path:
    """Stream the request body to a temporary file; never the whole body in memory.

    The size limit is enforced by the app's ``BodySizeLimit`` middleware while
    the body streams (it raises out of ``request.stream()``); the partial file
    is removed on that or any other error.
    """
    await anyio.to_thread.run_sync(lambda: spool_dir.mkdir(parents=True, exist_ok=True))
    fd, name = tempfile.mkstemp(dir=spool_dir, prefix=".tmp-upload-", suffix=".part")
    path = Path(name)
    try:
        with os.fdopen(fd, "wb") as fh:
            buf = bytearray()
            async for chunk in request.stream():
                buf += chunk
                if len(buf) >= SPOOL_CHUNK:
                    data, buf = bytes(buf), bytearray()
                    await anyio.to_thread.run_sync(fh.write, data)
            if buf:
                await anyio.to_thread.run_sync(fh.write, bytes(buf))
    except BaseException:
        path.unlink(missing_ok=True)
        raise
    return path


def _slots(request: Request) -> asyncio.Semaphore:
    """The app's parse semaphore (made lazily on the app's own event loop)."""
    sem = getattr(request.app.state, "cloud_parse_slots", None)
    if sem is None:
        sem = asyncio.Semaphore(PARSE_SLOTS)
        request.app.state.cloud_parse_slots = sem
    return sem


async def _parse(request: Request, raw: Path, ctype: str, out: Path) -> dict[str, Any]:
    """Run the upload parser child and return its JSON outcome."""
    async with _slots(request):
        proc = await asyncio.create_subprocess_exec(
            *PARSER,
            "upload",
            str(raw),
            ctype,
            str(out),
            str(os.getpid()),
            stdin=asyncio.subprocess.DEVNULL,
            stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.PIPE,
        )
        try:
            stdout, stderr = await proc.communicate()
        except BaseException:  # the request was cancelled: do not leave the child behind
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
            with contextlib.suppress(Exception):
                await asyncio.shield(proc.wait())
            raise
    lines = stdout.decode("utf-8", "replace").strip().splitlines()
    if proc.returncode != 0 or not lines:
        log.error(
            "upload parser exited with %s: %s", proc.returncode, stderr.decode("utf-8", "replace")
        )
        raise HTTPException(500, detail="the upload parser failed; see the server log")
    return json.loads(lines[-1])


@router.get("")
def list_clouds(
    services: Svc,
    _: Viewer,
    limit: Annotated[int, Query(ge=1, le=2000, description="at most this many")] = 100,
    offset: Annotated[int, Query(ge=0, le=10**9, description="skip this many")] = 0,
) -> list[dict[str, Any]]:
    """Stored clouds, newest first."""
    return [c.public() for c in services.store.list_clouds(limit, offset)]


@router.get("/{cloud_id}", responses=errors(404))
def get_cloud(cloud_id: str, services: Svc, _: Viewer) -> dict[str, Any]:
    return services.store.get_cloud(cloud_id).public()


@router.get(
    "/{cloud_id}/points.npy",
    response_class=FileResponse,
    responses={
        200: {"content": {"application/octet-stream": {}}, "description": "(N,3) float64 .npy"},
        **errors(404),
    },
)
def download_points(cloud_id: str, services: Svc, _: Viewer) -> FileResponse:
    """The cloud's points as an (N,3) float64 ``.npy`` file (streamed from disk)."""
    path = services.store.cloud_path(cloud_id)
    return FileResponse(path, media_type="application/octet-stream")


@router.get(
    "/{cloud_id}/attributes/{name}",
    response_class=FileResponse,
    responses={
        200: {
            "content": {"application/octet-stream": {}},
            "description": ".npy of one value per point, rows as points.npy: intensity "
            "(N,) (uint16 from LAS, float32 from E57 and text), rgb (N,3) uint16 (its "
            "bit depth in the survey record's attributes), classification (N,) uint8",
        },
        **errors(404),
    },
)
def download_attribute(cloud_id: str, name: str, services: Svc, _: Viewer) -> FileResponse:
    """One per-point attribute of the cloud as ``.npy`` (streamed from disk);
    the cloud's record lists which it has (``attributes``)."""
    path = services.store.cloud_attribute_path(cloud_id, name)
    return FileResponse(path, media_type="application/octet-stream")


@router.delete("/{cloud_id}", status_code=204, responses=errors(404))
def delete_cloud(cloud_id: str, services: Svc, who: Operator) -> Response:
    services.store.delete_cloud(cloud_id, who.actor)
    return Response(status_code=204)
