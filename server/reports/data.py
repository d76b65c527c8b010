"""What a plan's report shows, gathered from the store.

:func:`gather` reads one plan, its findings (kept and withdrawn) with their
photos, its executions and the audit trail of all of them into a frozen
:class:`ReportData`.  Nothing here reads a clock or draws at random: the
report of the same stored data is the same, and its "as of" time is the
newest time stamp in that data.
"""

from __future__ import annotations

import base64
import io
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from server.maintenance import maintenance_view
from server.services import Services
from server.store import Store
from server.store.findings import (
    CONDITION_STATES,
    PHOTO_MAX_PIXELS,
    Finding,
    FindingStore,
    Photo,
    open_photo,
)
from server.store.records import AuditEvent, ExecutionRecord, PlanRecord

#: Longest side of a photo's thumbnail in the report (px).
THUMB_PX = 480
#: Largest photo embedded as it is when it cannot be made a thumbnail (bytes).
PHOTO_RAW_MAX_BYTES = 2 * 1024 * 1024
#: Most audit events read per entity.
AUDIT_LIMIT = 10_000
#: Most findings and executions listed.
ROW_LIMIT = 10_000


class PhotoTooLarge(ValueError):
    """A photo declares more than :data:`PHOTO_MAX_PIXELS`: it is not decoded."""

    def __init__(self, width: int, height: int) -> None:
        super().__init__(
            f"{width} × {height} px ({width * height} pixels): more than the "
            f"{PHOTO_MAX_PIXELS} a report decodes, not shown"
        )
        self.width = width
        self.height = height


@dataclass(frozen=True)
class PhotoData:
    """One photo of a finding, embedded (``data_uri``) or not (``note`` says why)."""

    id: str
    filename: str
    content_type: str
    size: int
    created_by: str
    created_at: str
    data_uri: str | None
    note: str = ""


@dataclass(frozen=True)
class FindingData:
    """A finding as the report shows it."""

    id: str
    number: int
    type: str
    condition_state: int
    condition: str
    location: str
    #: Where to mark it in the picture (world frame, m); None: nowhere known.
    xyz: tuple[float, float, float] | None
    notes: str
    created_by: str
    created_at: str
    updated_by: str | None
    updated_at: str | None
    deleted_by: str | None
    deleted_at: str | None
    deleted_reason: str | None
    photos: tuple[PhotoData, ...]
    linked_plans: tuple[dict[str, Any], ...]


@dataclass(frozen=True)
class ExecutionData:
    """An execution of the plan with its timing."""

    record: ExecutionRecord
    duration_s: float | None


@dataclass(frozen=True)
class ReportData:
    """Everything a report of one plan shows."""

    plan: PlanRecord
    findings: tuple[FindingData, ...]
    withdrawn: tuple[FindingData, ...]
    executions: tuple[ExecutionData, ...]
    audit: tuple[AuditEvent, ...]
    #: The newest time stamp in the data (the report's "as of").
    as_of: str


def gather(services: Services, plan_id: str) -> ReportData:
    """Read plan ``plan_id``'s report data (``NotFoundError`` when unknown)."""
    store = services.store
    plan = store.get_plan(plan_id)
    fstore = FindingStore(store.db, store.data_dir / "photos")
    rows = fstore.listed(plan_id=plan_id, include_deleted=True, limit=ROW_LIMIT)
    rows.sort(key=lambda f: (f.created_at, f.id))  # oldest first: numbers stay put
    findings = [_finding(store, plan, fstore, f, i + 1) for i, f in enumerate(rows)]
    execs = sorted(
        store.list_executions(plan_id=plan_id, limit=ROW_LIMIT), key=lambda e: (e.created_at, e.id)
    )
    audit: list[AuditEvent] = list(store.list_audit("plan", plan_id, limit=AUDIT_LIMIT))
    for e in execs:
        audit += store.list_audit("execution", e.id, limit=AUDIT_LIMIT)
    for f in rows:
        audit += store.list_audit("finding", f.id, limit=AUDIT_LIMIT)
    audit.sort(key=lambda a: (a.ts, a.id))
    stamps = [plan.created_at, plan.updated_at, *(a.ts for a in audit)]
    stamps += [e.updated_at for e in execs]
    stamps += [t for f in rows for t in (f.created_at, f.updated_at, f.deleted_at) if t]
    return ReportData(
        plan=plan,
        findings=tuple(f for f in findings if f.deleted_at is None),
        withdrawn=tuple(f for f in findings if f.deleted_at is not None),
        executions=tuple(ExecutionData(e, _duration(e)) for e in execs),
        audit=tuple(audit),
        as_of=max(stamps),
    )


def _finding(
    store: Store, plan: PlanRecord, fstore: FindingStore, f: Finding, number: int
) -> FindingData:
    location, xyz = _locate(plan, f)
    return FindingData(
        id=f.id,
        number=number,
        type=f.type,
        condition_state=f.condition_state,
        condition=CONDITION_STATES.get(f.condition_state, "?"),
        location=location,
        xyz=xyz,
        notes=f.notes,
        created_by=f.created_by,
        created_at=f.created_at,
        updated_by=f.updated_by,
        updated_at=f.updated_at,
        deleted_by=f.deleted_by,
        deleted_at=f.deleted_at,
        deleted_reason=f.deleted_reason,
        photos=tuple(_photo(fstore, f.id, p) for p in f.photos),
        linked_plans=tuple(maintenance_view(store, f.id)[0]),
    )


def _locate(plan: PlanRecord, f: Finding) -> tuple[str, tuple[float, float, float] | None]:
    """Where the finding is, in words, and a point to mark it at."""
    parts: list[str] = []
    if f.member_id is not None:
        parts.append(f"member {f.member_id}")
    if f.face_id is not None:
        parts.append(f"face {f.face_id}")
    if f.cluster_id is not None:
        parts.append(f"cluster {f.cluster_id}")
    xyz: tuple[float, float, float] | None = None
    if f.point_m is not None:
        xyz = _xyz(f.point_m)
        parts.append("point (" + ", ".join(f"{v:.3f}" for v in xyz) + ") m")
    if f.region_m:
        parts.append(f"region of {len(f.region_m)} corners")
        if xyz is None:
            xyz = _mean(f.region_m)
    if xyz is None and f.cluster_id is not None:
        for c in plan.result.get("clusters", []) or []:
            if isinstance(c, dict) and c.get("id") == f.cluster_id and c.get("centre"):
                xyz = _xyz(c["centre"])
    return ", ".join(parts) or "—", xyz


def _xyz(p: Sequence[float]) -> tuple[float, float, float]:
    return (float(p[0]), float(p[1]), float(p[2]))


def _mean(pts: Sequence[Sequence[float]]) -> tuple[float, float, float]:
    n = len(pts)
    return (
        sum(float(p[0]) for p in pts) / n,
        sum(float(p[1]) for p in pts) / n,
        sum(float(p[2]) for p in pts) / n,
    )


def _duration(e: ExecutionRecord) -> float | None:
    try:
        t0 = datetime.fromisoformat(e.created_at)
        t1 = datetime.fromisoformat(e.updated_at)
    except ValueError:
        return None
    return max(0.0, (t1 - t0).total_seconds())


def _photo(fstore: FindingStore, finding_id: str, p: Photo) -> PhotoData:
    def made(data_uri: str | None, note: str = "") -> PhotoData:
        return PhotoData(
            id=p.id,
            filename=p.filename,
            content_type=p.content_type,
            size=p.size,
            created_by=p.created_by,
            created_at=p.created_at,
            data_uri=data_uri,
            note=note,
        )

    _, path = fstore.photo_file(finding_id, p.id)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        return made(None, f"photo file unreadable ({exc.strerror})")
    try:
        thumb = thumbnail(raw)
    except PhotoTooLarge as exc:
        # Stored before uploads were limited (or imported): embedding its
        # bytes would only move the decoding to the viewer or the PDF printer.
        return made(None, str(exc))
    if thumb is not None:
        return made(_data_uri("image/png", thumb))
    if len(raw) <= PHOTO_RAW_MAX_BYTES:
        return made(_data_uri(p.content_type, raw))
    return made(None, f"{len(raw)} bytes: too large to embed without a thumbnail")


def thumbnail(raw: bytes, size: int = THUMB_PX) -> bytes | None:
    """A PNG at most ``size`` px on its longest side (Pillow), or None when
    Pillow is missing or cannot read the image.

    Raises :class:`PhotoTooLarge`, having read only the header, when the image
    declares more than :data:`PHOTO_MAX_PIXELS`.  A JPEG is decoded at the
    smallest of 1/2, 1/4, 1/8 scale still twice ``size`` (``draft``); other
    formats are decoded once at full size and reduced.  The image is closed
    before this returns, so a report holds one decoded photo at a time.
    """
    with io.BytesIO(raw) as fp:
        try:
            im = open_photo(fp)
        except ImportError:  # pragma: no cover - Pillow comes with matplotlib
            return None
        if im is None:
            return None
        with im:
            width, height = im.size
            if width * height > PHOTO_MAX_PIXELS:
                raise PhotoTooLarge(width, height)
            try:
                # reducing_gap: draft() for a JPEG, then reduce() by whole
                # factors before the final resampling.
                im.thumbnail((size, size), reducing_gap=2.0)
                with im.convert("RGBA" if "A" in im.getbands() else "RGB") as out:
                    buf = io.BytesIO()
                    out.save(buf, format="PNG", optimize=False)
                    return buf.getvalue()
            except Exception:  # a damaged or truncated image: fall back to its bytes
                return None


def _data_uri(ctype: str, data: bytes) -> str:
    return f"data:{ctype};base64,{base64.b64encode(data).decode('ascii')}"
