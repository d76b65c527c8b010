"""Export of a plan's whole history as one zip; layout in
:mod:`server.archive.manifest`.

Everything comes from what the service stored: the plan as the REST API
shows it, its arrays and source cloud as the ``.npy`` files on disk, every
execution with its acknowledgements and recorded robot states (and the same
run as MCAP), every finding (soft-deleted ones too) with its photos, and the
audit events of the plan, its executions and its findings.  Rows are carried
whole (``SELECT *``), so a column added later travels too.
"""

from __future__ import annotations

import hashlib
import io
import json
import zipfile
from pathlib import Path
from typing import IO, Any

from server import __version__
from server.archive.manifest import FORMAT, FORMAT_VERSION, MANIFEST
from server.store import NotFoundError, Store
from server.store.archive import ArchiveStore
from server.store.database import utcnow
from server.store.migrations import SCHEMA_VERSION

#: Audit events read per entity (far more than any plan has).
AUDIT_LIMIT = 1_000_000
_IMAGE_EXT = {"image/png": "png", "image/jpeg": "jpg", "image/webp": "webp", "image/gif": "gif"}
#: Already compressed: stored as they are.
_STORED = (".mcap", ".png", ".jpg", ".jpeg", ".webp", ".gif")


def _dumps(obj: Any) -> bytes:
    return json.dumps(obj, allow_nan=False, indent=1, ensure_ascii=False).encode("utf-8")


def photo_ext(filename: str, content_type: str) -> str:
    """The extension a photo is archived under: its content type's, else its name's."""
    if content_type in _IMAGE_EXT:
        return _IMAGE_EXT[content_type]
    suffix = Path(filename).suffix.lstrip(".").lower()
    return suffix if suffix.isalnum() and 0 < len(suffix) <= 8 else "bin"


class _Writer:
    """Adds files to the zip and remembers each one's size and SHA-256."""

    def __init__(self, zf: zipfile.ZipFile) -> None:
        self.zf = zf
        self.files: list[dict[str, Any]] = []

    def _kind(self, name: str) -> int:
        return zipfile.ZIP_STORED if name.endswith(_STORED) else zipfile.ZIP_DEFLATED

    def data(self, name: str, data: bytes) -> None:
        self.zf.writestr(name, data, compress_type=self._kind(name))
        self.files.append(
            {"name": name, "size": len(data), "sha256": hashlib.sha256(data).hexdigest()}
        )

    def file(self, name: str, path: Path) -> None:
        h = hashlib.sha256()
        size = 0
        with open(path, "rb") as src, self.zf.open(name, "w", force_zip64=True) as dst:
            while chunk := src.read(1 << 20):
                h.update(chunk)
                size += len(chunk)
                dst.write(chunk)
        self.files.append({"name": name, "size": size, "sha256": h.hexdigest()})


def export_plan(store: Store, plan_id: str, out: IO[bytes], actor: str) -> dict[str, Any]:
    """Write plan ``plan_id``'s archive to ``out``; returns its manifest.

    :class:`~server.store.NotFoundError` for an unknown plan.
    """
    from server.recording import plan_cloud, write_recording
    from server.recording.captures import load_captures

    plan = store.get_plan(plan_id)
    rows = ArchiveStore(store.db)
    photo_dir = store.data_dir / "photos"
    counts: dict[str, int] = {}
    with zipfile.ZipFile(out, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        w = _Writer(zf)
        w.data("plan.json", _dumps(plan.public(include_result=True)))
        for name in sorted(plan.arrays):
            w.file(f"arrays/{name}.npy", store.arrays.path(plan.arrays[name]))
        counts["arrays"] = len(plan.arrays)

        cloud_id = plan.params.get("cloud_id")
        counts["clouds"] = 0
        if isinstance(cloud_id, str):
            try:
                cloud = store.get_cloud(cloud_id)
            except NotFoundError:
                cloud = None  # deleted since: the plan still names it
            if cloud is not None:
                (row,) = rows.rows("clouds", "id", [cloud.id])
                w.data(f"cloud/{cloud.id}.json", _dumps(row))
                w.file(f"cloud/{cloud.id}.npy", store.cloud_path(cloud.id))
                for name in cloud.attributes:  # intensity, rgb, classification
                    w.file(
                        f"cloud/{cloud.id}.{name}.npy", store.cloud_attribute_path(cloud.id, name)
                    )
                counts["clouds"] = 1

        executions = rows.rows("executions", "plan_id", [plan.id])
        recorded_cloud = plan_cloud(store, plan) if executions else None
        audit = store.list_audit("plan", plan.id, limit=AUDIT_LIMIT)
        for ex_row in executions:
            ex = store.get_execution(ex_row["id"])
            acks = store.ack_times(ex.id)
            states = store.execution_states(ex.id)
            ex_audit = store.list_audit("execution", ex.id, limit=AUDIT_LIMIT)
            audit += ex_audit
            w.data(
                f"executions/{ex.id}.json",
                _dumps({"execution": ex_row, "acks": acks, "states": states}),
            )
            buf = io.BytesIO()
            recording_audit = store.list_audit("execution", ex.id, limit=10_000) + (
                store.list_audit("plan", plan.id, limit=10_000)
            )
            write_recording(
                buf,
                ex,
                plan,
                acks,
                states,
                recording_audit,
                cloud=recorded_cloud,
                captures=load_captures(store, ex.id, ex.robot, plan),
            )
            w.data(f"executions/{ex.id}.mcap", buf.getvalue())
        counts["executions"] = len(executions)

        findings = rows.rows("findings", "plan_id", [plan.id])
        photos = rows.rows("finding_photos", "finding_id", [f["id"] for f in findings])
        photo_items = []
        for p in photos:
            name = (
                f"photos/{p['finding_id']}/{p['id']}.{photo_ext(p['filename'], p['content_type'])}"
            )
            w.file(name, photo_dir / p["id"])
            photo_items.append({"row": p, "file": name})
        for f in findings:
            audit += store.list_audit("finding", f["id"], limit=AUDIT_LIMIT)
        # Links between findings and the maintenance plans made from them:
        # from this plan's findings, and to this plan if a finding made it.
        links: list[dict[str, Any]] = []
        if rows.columns("finding_plans"):
            links = rows.rows("finding_plans", "finding_id", [f["id"] for f in findings])
            links += [r for r in rows.rows("finding_plans", "plan_id", [plan.id]) if r not in links]
        w.data(
            "findings.json",
            _dumps({"findings": findings, "photos": photo_items, "finding_plans": links}),
        )
        counts["finding_plans"] = len(links)
        counts["findings"] = len(findings)
        counts["photos"] = len(photos)

        events = sorted((e.public() for e in audit), key=lambda e: e["id"])
        w.data("audit.json", _dumps(events))
        counts["audit_events"] = len(events)

        manifest = {
            "format": FORMAT,
            "format_version": FORMAT_VERSION,
            "schema_version": SCHEMA_VERSION,
            "server_version": __version__,
            "exported_at": utcnow(),
            "exported_by": actor,
            "plan_id": plan.id,
            "plan_state": plan.state,
            "counts": counts,
            "files": w.files,
        }
        zf.writestr(MANIFEST, _dumps(manifest))
    return manifest
