"""``/api/v1/findings``: what an inspection found, tied to the structure.

Viewer reads, operator writes.  A finding is placed on an ``ara.inspect``
plan's structure model (``member_id``, optionally ``face_id``) or on an
``ara.navigate`` plan's cluster (``cluster_id``), with a ``point_m`` and/or
a ``region_m`` polygon; on a face, every point must lie on its plane (within
:data:`ON_FACE_M`).  Edits and deletes are audited; a delete is a mark with
who and why, never a removal.  A new finding of condition state 3 or 4 is
published as the webhook event ``finding.created``.
"""

from __future__ import annotations

import io
from typing import Annotated, Any, Literal

import numpy as np
from fastapi import APIRouter, Depends, File, Form, HTTPException, Query, Response, UploadFile
from fastapi.responses import FileResponse
from pydantic import BaseModel, ConfigDict, Field

from server.auth import Operator, Viewer
from server.maintenance import (
    MaintenanceError,
    blast_params,
    inspect_params,
    maintenance_view,
)
from server.routers.plans import submit_plan
from server.routers.responses import errors
from server.services import Services, get_services
from server.store import NotFoundError
from server.store.findings import (
    EDITABLE,
    PHOTO_MAX_PIXELS,
    Finding,
    FindingStore,
    open_photo,
)
from server.store.maintenance import MaintenanceStore

router = APIRouter(prefix="/findings", tags=["findings"])

Svc = Annotated[Services, Depends(get_services)]

#: How far a finding's point may lie off its face's plane (m): scan noise
#: and a click's depth on a thin flange.
ON_FACE_M = 0.05
#: Largest photo accepted (bytes).
PHOTO_MAX_BYTES = 10 * 1024 * 1024

FindingType = Literal[
    "corrosion", "coating_loss", "section_loss", "crack", "deformation", "loose_fastener", "other"
]
Point = tuple[float, float, float]


class FindingCreate(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    plan_id: str = Field(..., description="the ara.inspect or ara.navigate plan it was found on")
    member_id: int | None = Field(None, ge=0, description="member of the structure model")
    face_id: int | None = Field(None, ge=0, description="face of that member")
    cluster_id: int | None = Field(None, ge=0, description="cluster (ara.navigate)")
    point_m: Point | None = Field(None, description="where, world frame (m)")
    region_m: list[Point] | None = Field(
        None, min_length=3, max_length=200, description="region polygon on the face (m)"
    )
    type: FindingType
    condition_state: int = Field(..., ge=1, le=4, description="1 good, 2 fair, 3 poor, 4 severe")
    notes: str = Field("", max_length=5000)


class FindingPatch(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    type: FindingType | None = None
    condition_state: int | None = Field(None, ge=1, le=4)
    notes: str | None = Field(None, max_length=5000)
    point_m: Point | None = None
    region_m: list[Point] | None = Field(None, min_length=3, max_length=200)
    face_id: int | None = Field(None, ge=0)


def _store(services: Services) -> FindingStore:
    return FindingStore(services.store.db, services.store.data_dir / "photos")


def _bad(field: str, msg: str) -> HTTPException:
    return HTTPException(422, detail=[{"loc": ["body", field], "msg": msg, "type": "value_error"}])


def _locate(services: Services, f: dict[str, Any]) -> None:
    """Check that the finding's place exists in its plan's model (422 otherwise)."""
    try:
        plan = services.store.get_plan(f["plan_id"])
    except NotFoundError:
        raise _bad("plan_id", f"no plan with id {f['plan_id']!r}") from None
    pts = [p for p in [f.get("point_m")] + list(f.get("region_m") or []) if p is not None]
    if not pts:
        raise _bad("point_m", "give point_m or region_m: where on the structure it is")
    res = plan.result or {}
    if plan.kind == "ara.inspect":
        if f.get("cluster_id") is not None:
            raise _bad("cluster_id", "an ara.inspect plan has members, not clusters")
        if f.get("member_id") is None:
            raise _bad("member_id", "a finding on an ara.inspect plan names its member")
        member = next((m for m in res.get("members", []) if m["id"] == f["member_id"]), None)
        if member is None:
            raise _bad("member_id", f"plan {plan.id} has no member {f['member_id']}")
        if f.get("face_id") is None:
            return
        face = next((g for g in member.get("faces", []) if g["id"] == f["face_id"]), None)
        if face is None:
            ids = [g["id"] for g in member.get("faces", [])]
            raise _bad("face_id", f"member {member['id']} has no face {f['face_id']} (faces {ids})")
        n = np.asarray(face["normal"], dtype=float)
        o = np.asarray(face["outline"], dtype=float).mean(axis=0)
        off = np.abs((np.asarray(pts, dtype=float) - o) @ (n / np.linalg.norm(n)))
        if off.max() > ON_FACE_M:
            raise _bad(
                "region_m" if f.get("region_m") and off[-1] > ON_FACE_M else "point_m",
                f"{off.max():.3f} m off face {face['id']}'s plane (at most {ON_FACE_M} m)",
            )
    elif plan.kind == "ara.navigate":
        if f.get("member_id") is not None or f.get("face_id") is not None:
            raise _bad("member_id", "an ara.navigate plan has clusters, not members")
        if f.get("cluster_id") is None:
            raise _bad("cluster_id", "a finding on an ara.navigate plan names its cluster")
        if not any(c["id"] == f["cluster_id"] for c in res.get("clusters", [])):
            raise _bad("cluster_id", f"plan {plan.id} has no cluster {f['cluster_id']}")
    else:
        raise _bad(
            "plan_id", f"findings are placed on ara.inspect or ara.navigate plans, not {plan.kind}"
        )


def _view(services: Services, f: Finding) -> dict[str, Any]:
    """The finding as REST shows it, with its maintenance plans
    (:func:`server.maintenance.maintenance_view`)."""
    out = f.public()
    out["maintenance_plans"], out["awaiting_review"] = maintenance_view(services.store, f.id)
    return out


def _publish(services: Services, action: str, f: Finding) -> None:
    if services.scene is not None:  # its markers, if its plan is shown
        services.scene.findings_changed(f.plan_id)
    services.events.publish(
        "finding",
        {
            "id": f.id,
            "action": action,
            "plan_id": f.plan_id,
            "member_id": f.member_id,
            "cluster_id": f.cluster_id,
            "type": f.type,
            "condition_state": f.condition_state,
        },
    )


@router.post("", status_code=201, responses=errors(401, 403, 422))
def create_finding(req: FindingCreate, services: Svc, who: Operator) -> dict[str, Any]:
    fields = req.model_dump()
    if fields["region_m"] is not None:
        fields["region_m"] = [list(p) for p in fields["region_m"]]
    if fields["point_m"] is not None:
        fields["point_m"] = list(fields["point_m"])
    _locate(services, fields)
    f = _store(services).add(fields, who.actor)
    _publish(services, "created", f)
    return _view(services, f)


@router.get("", responses=errors(401, 422))
def list_findings(
    services: Svc,
    _: Viewer,
    plan_id: str | None = None,
    member_id: Annotated[int | None, Query(ge=0, le=10**9)] = None,
    type: FindingType | None = None,
    condition_state: Annotated[int | None, Query(ge=1, le=4)] = None,
    min_condition_state: Annotated[int | None, Query(ge=1, le=4)] = None,
    include_deleted: bool = False,
    limit: Annotated[int, Query(ge=1, le=1000)] = 500,
) -> list[dict[str, Any]]:
    """Findings, newest first, filtered by plan, member, type or condition state."""
    rows = _store(services).listed(
        plan_id=plan_id,
        member_id=member_id,
        type_=type,
        condition_state=condition_state,
        min_condition_state=min_condition_state,
        include_deleted=include_deleted,
        limit=limit,
    )
    return [_view(services, f) for f in rows]


@router.get("/{finding_id}", responses=errors(401, 404))
def get_finding(finding_id: str, services: Svc, _: Viewer) -> dict[str, Any]:
    f = _store(services).get(finding_id)
    out = _view(services, f)
    out["audit"] = [e.public() for e in services.store.list_audit("finding", finding_id)]
    return out


@router.patch("/{finding_id}", responses=errors(401, 403, 404, 409, 422))
def edit_finding(
    finding_id: str, req: FindingPatch, services: Svc, who: Operator
) -> dict[str, Any]:
    """Change what, how bad, the notes or the place on its face (audited)."""
    store = _store(services)
    f = store.get(finding_id)
    if f.deleted_at is not None:
        raise HTTPException(
            409, detail=f"finding {finding_id} is deleted; it can be read, not edited"
        )
    changes = {
        k: (list(v) if k == "point_m" else [list(p) for p in v] if k == "region_m" else v)
        for k, v in req.model_dump(exclude_unset=True).items()
        if k in EDITABLE and v is not None
    }
    if any(k in changes for k in ("point_m", "region_m", "face_id")):
        _locate(services, {**f.public(), **changes})
    out = store.update(finding_id, changes, who.actor)
    if "condition_state" in changes:  # answers a run's request, even unchanged
        MaintenanceStore(services.store.db).reviewed(finding_id)
    _publish(services, "edited", out)
    return _view(services, out)


@router.delete("/{finding_id}", responses=errors(401, 403, 404, 422))
def delete_finding(
    finding_id: str,
    services: Svc,
    who: Operator,
    reason: Annotated[str, Query(min_length=1, max_length=2000, description="why it is withdrawn")],
) -> dict[str, Any]:
    """Withdraw it: marked deleted with who, when and why; it stays readable
    (``include_deleted``) and in the audit trail."""
    store = _store(services)
    store.get(finding_id)  # 404 when unknown
    out = store.delete(finding_id, who.actor, reason)
    _publish(services, "deleted", out)
    return _view(services, out)


class MaintenancePlanRequest(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    kind: Literal["blast", "ara.inspect"] = Field(
        ..., description="blast: sand-blast the finding's region; ara.inspect: drive to its member"
    )
    patch_m: float = Field(
        0.3,
        gt=0.02,
        le=5.0,
        description="blast: side of the square around a point-only finding (m)",
    )
    start: int | None = Field(
        None,
        ge=0,
        le=10**9,
        description="ara.inspect: start vertex (None: the source plan's start)",
    )
    params: dict[str, Any] = Field(
        default_factory=dict, description="more params of the kind (checked as POST /plans checks)"
    )


@router.post("/{finding_id}/plan", status_code=202, responses=errors(401, 403, 404, 409, 422))
def plan_from_finding(
    finding_id: str,
    req: MaintenancePlanRequest,
    services: Svc,
    who: Operator,
    response: Response,
) -> dict[str, Any]:
    """Make a maintenance plan from the finding: a ``blast``
    plan of its region on its face with the base searched near it, or a
    close-inspection ``ara.inspect`` route to its member.  The plan is linked
    to the finding; the finding lists it with its state and, once run, what
    the run achieved."""
    f = _store(services).get(finding_id)
    if f.deleted_at is not None:
        raise HTTPException(409, detail=f"finding {finding_id} is deleted: plan from a live one")
    try:
        if req.kind == "blast":
            params = blast_params(
                services.store, f, who.actor, patch_m=req.patch_m, overrides=req.params
            )
        else:
            start = req.start
            if start is None:
                start = services.store.get_plan(f.plan_id, result=False).params.get("start")
            params = inspect_params(services.store, f, who.actor, start=start, overrides=req.params)
    except MaintenanceError as exc:
        raise _bad(exc.field, str(exc)) from None
    plan = submit_plan(services, req.kind, params, who.actor)
    MaintenanceStore(services.store.db).link(f.id, plan.id, req.kind, who.actor)
    _publish(services, "planned", f)
    response.headers["Location"] = f"/api/v1/plans/{plan.id}"
    return {**plan.public(), "finding_id": f.id}


_MAGIC = (
    (b"\xff\xd8\xff", "image/jpeg"),
    (b"\x89PNG\r\n\x1a\n", "image/png"),
)


def _image_type(head: bytes) -> str | None:
    for magic, ctype in _MAGIC:
        if head.startswith(magic):
            return ctype
    if head[:4] == b"RIFF" and head[8:12] == b"WEBP":
        return "image/webp"
    return None


@router.post(
    "/{finding_id}/photos", status_code=201, responses=errors(401, 403, 404, 413, 415, 422)
)
async def add_photo(
    finding_id: str,
    services: Svc,
    who: Operator,
    file: Annotated[UploadFile, File(description="a JPEG, PNG or WebP photo")],
    caption: Annotated[str, Form(max_length=200)] = "",
) -> dict[str, Any]:
    """Attach a photo (JPEG, PNG or WebP by its content, at most 10 MiB and
    40 megapixels)."""
    store = _store(services)
    store.get(finding_id)  # 404 when unknown
    data = await file.read(PHOTO_MAX_BYTES + 1)
    if len(data) > PHOTO_MAX_BYTES:
        raise HTTPException(413, detail=f"photo larger than {PHOTO_MAX_BYTES} bytes")
    ctype = _image_type(data[:16])
    if ctype is None:
        raise HTTPException(
            415, detail="not a JPEG, PNG or WebP image (checked by its content, not its name)"
        )
    _check_pixels(data)
    name = caption or (file.filename or "photo")
    return store.add_photo(finding_id, data, name[:200], ctype, who.actor).public()


def _check_pixels(data: bytes) -> None:
    """422 unless Pillow identifies ``data`` and it declares at most
    :data:`PHOTO_MAX_PIXELS`; only the header is read, nothing is decoded (a
    small file may declare a picture of gigabytes)."""
    with io.BytesIO(data) as fp:
        im = open_photo(fp)
        if im is None:
            raise _bad("file", "not a readable JPEG, PNG or WebP image (its header is damaged)")
        with im:
            width, height = im.size
    if width * height > PHOTO_MAX_PIXELS:
        raise _bad(
            "file",
            f"{width} × {height} px is {width * height} pixels: more than the "
            f"{PHOTO_MAX_PIXELS} pixels a photo may have",
        )


@router.get("/{finding_id}/photos/{photo_id}", responses=errors(401, 404))
def get_photo(finding_id: str, photo_id: str, services: Svc, _: Viewer) -> FileResponse:
    store = _store(services)
    photo, path = store.photo_file(finding_id, photo_id)
    return FileResponse(path, media_type=photo.content_type)
