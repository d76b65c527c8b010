"""``/api/v1/clouds``: upload (file or sample), list, get, download, delete."""

from __future__ import annotations

from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, Depends, HTTPException, Request, Response, status
from pydantic import BaseModel, Field, ValidationError

from server.auth import Operator, Viewer
from server.cloud_io import CloudFormatError, read_cloud
from server.kinds import get_kind, sample_names
from server.services import Services, get_services

router = APIRouter(prefix="/clouds", tags=["clouds"])

Svc = Annotated[Services, Depends(get_services)]


class SampleRequest(BaseModel):
    sample: str = Field(..., description="name of a sample scene (GET /clouds/samples)")
    seed: int = Field(0, ge=0, description="generator seed")
    name: str | None = Field(None, description="display name; defaults to the sample name")


@router.get("/samples")
def list_samples(_: Viewer) -> dict[str, str]:
    """Sample scene name → the plan kind that provides it."""
    return sample_names()


@router.post("", status_code=status.HTTP_201_CREATED)
async def upload_cloud(request: Request, services: Svc, who: Operator) -> dict[str, Any]:
    """Store a cloud: multipart ``file`` (PLY, PCD ascii/binary, XYZ/CSV, NPY) or
    JSON ``{"sample": name}``.  Non-finite rows are dropped and counted."""
    ctype = request.headers.get("content-type", "")
    if ctype.startswith("application/json"):
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
        points = np.asarray(fn(req.seed), dtype=np.float64)
        finite = np.isfinite(points).all(axis=1)
        rec = services.store.add_cloud(
            req.name or req.sample,
            f"sample:{req.sample}:{req.seed}",
            points[finite],
            int((~finite).sum()),
            who.actor,
        )
    elif ctype.startswith("multipart/form-data"):
        form = await request.form()
        upload = form.get("file")
        if upload is None or isinstance(upload, str):
            raise HTTPException(
                422, detail="multipart upload needs a 'file' field holding the cloud"
            )
        data = await upload.read()
        try:
            points, dropped = read_cloud(data, upload.filename or "")
        except CloudFormatError as exc:
            raise HTTPException(400, detail=f"{upload.filename or 'upload'}: {exc}") from None
        name = str(form.get("name") or upload.filename or "upload")
        rec = services.store.add_cloud(
            name, f"upload:{upload.filename}", points, dropped, who.actor
        )
    else:
        raise HTTPException(
            415,
            detail="send multipart/form-data with a 'file' field, or JSON {\"sample\": name}",
        )
    services.events.publish("cloud", {"id": rec.id, "n_points": rec.n_points})
    return rec.public()


@router.get("")
def list_clouds(
    services: Svc, _: Viewer, limit: int = 100, offset: int = 0
) -> list[dict[str, Any]]:
    return [c.public() for c in services.store.list_clouds(limit, offset)]


@router.get("/{cloud_id}")
def get_cloud(cloud_id: str, services: Svc, _: Viewer) -> dict[str, Any]:
    return services.store.get_cloud(cloud_id).public()


@router.get("/{cloud_id}/points.npy", response_class=Response)
def download_points(cloud_id: str, services: Svc, _: Viewer) -> Response:
    path = services.store.cloud_path(cloud_id)
    return Response(path.read_bytes(), media_type="application/octet-stream")


@router.delete("/{cloud_id}", status_code=204)
def delete_cloud(cloud_id: str, services: Svc, who: Operator) -> Response:
    services.store.delete_cloud(cloud_id, who.actor)
    return Response(status_code=204)
