"""Findings on the structure and their photos, in the service's database (SQLite or PostgreSQL).

A finding says where (an inspection plan and, in its structure model, a
member and face — ``ara.inspect`` — or a cluster — ``ara.navigate`` — plus
a point or a region polygon, world frame, metres), what (``type``), how bad
(``condition_state`` 1–4: good / fair / poor / severe) and notes.  Every
create, edit and delete is audited in the same transaction; a delete only
marks the row (who, when, why), so nothing found is lost.  Photos are files
under ``<data>/photos`` named by their id, listed in ``finding_photos``.
"""

from __future__ import annotations

import json
import secrets
from dataclasses import dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

from server.store.database import RowLike, StoreDatabase, ensure_private_dir, utcnow
from server.store.store import NotFoundError

if TYPE_CHECKING:
    from PIL.ImageFile import ImageFile

FINDING_TYPES: tuple[str, ...] = (
    "corrosion",
    "coating_loss",
    "section_loss",
    "crack",
    "deformation",
    "loose_fastener",
    "other",
)
#: AASHTO-style condition states.
CONDITION_STATES: dict[int, str] = {1: "good", 2: "fair", 3: "poor", 4: "severe"}
#: Most pixels (width × height) a photo may declare.  A report decodes every
#: photo to make its thumbnail, at 4 bytes a pixel: 40 MP (160 MB) is above
#: any inspection camera's frame, while a 657 KB solid-colour PNG can declare
#: 13000 × 13000 (169 MP, 1.3 GB once decoded).
PHOTO_MAX_PIXELS = 40_000_000


def open_photo(fp: IO[bytes]) -> ImageFile | None:
    """The JPEG, PNG or WebP image in ``fp`` with only its header read (no pixel
    decoded: check ``size`` before anything loads it), or None when Pillow
    cannot identify it as one of the three.

    The format's Pillow plugin is called directly rather than through
    ``Image.open``, which warns (89 MP) or raises (179 MP) against a
    process-wide limit before the caller can compare the declared size with
    :data:`PHOTO_MAX_PIXELS` and say by how much it is over.
    """
    from PIL.JpegImagePlugin import JpegImageFile
    from PIL.PngImagePlugin import PngImageFile
    from PIL.WebPImagePlugin import WebPImageFile

    head = fp.read(16)
    fp.seek(0)
    plugin: type[ImageFile]
    if head.startswith(b"\xff\xd8\xff"):
        plugin = JpegImageFile
    elif head.startswith(b"\x89PNG\r\n\x1a\n"):
        plugin = PngImageFile
    elif head[:4] == b"RIFF" and head[8:12] == b"WEBP":
        plugin = WebPImageFile
    else:
        return None
    try:
        return plugin(fp)
    except Exception:  # a broken header raises whatever its parser hit
        return None


@dataclass(frozen=True)
class Photo:
    id: str
    finding_id: str
    filename: str
    content_type: str
    size: int
    created_by: str
    created_at: str

    def public(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "filename": self.filename,
            "content_type": self.content_type,
            "size": self.size,
            "created_by": self.created_by,
            "created_at": self.created_at,
            "url": f"/api/v1/findings/{self.finding_id}/photos/{self.id}",
        }


@dataclass(frozen=True)
class Finding:
    id: str
    plan_id: str
    member_id: int | None
    face_id: int | None
    cluster_id: int | None
    point_m: list[float] | None
    region_m: list[list[float]] | None
    type: str
    condition_state: int
    notes: str
    created_by: str
    created_at: str
    updated_by: str | None
    updated_at: str | None
    deleted_by: str | None
    deleted_at: str | None
    deleted_reason: str | None
    photos: tuple[Photo, ...] = ()

    @classmethod
    def from_row(cls, r: RowLike, photos: tuple[Photo, ...] = ()) -> Finding:
        d = dict(r)
        for k in ("point_m", "region_m"):
            d[k] = json.loads(d[k]) if d[k] is not None else None
        return cls(**d, photos=photos)

    def public(self) -> dict[str, Any]:
        out = {k: getattr(self, k) for k in self.__dataclass_fields__ if k != "photos"}
        out["condition"] = CONDITION_STATES[self.condition_state]
        out["deleted"] = self.deleted_at is not None
        out["photos"] = [p.public() for p in self.photos]
        return out


#: Fields a PATCH may change.
EDITABLE = ("type", "condition_state", "notes", "point_m", "region_m", "face_id")


class FindingStore:
    """Findings over the service's :class:`Database`; photos under ``photo_dir``."""

    def __init__(self, db: StoreDatabase, photo_dir: Path) -> None:
        self.db = db
        self.photo_dir = photo_dir

    def _audit(self, conn: Any, actor: str, fid: str, action: str, why: str) -> None:
        conn.execute(
            "INSERT INTO audit_events (ts, actor, entity, entity_id, action, reason) "
            "VALUES (?,?,?,?,?,?)",
            (utcnow(), actor, "finding", fid, action, why),
        )

    def add(self, fields: dict[str, Any], actor: str) -> Finding:
        fid = f"fd_{secrets.token_hex(6)}"
        now = utcnow()
        with self.db.transaction() as conn:
            conn.execute(
                "INSERT INTO findings (id, plan_id, member_id, face_id, cluster_id, point_m, "
                "region_m, type, condition_state, notes, created_by, created_at) "
                "VALUES (?,?,?,?,?,?,?,?,?,?,?,?)",
                (
                    fid,
                    fields["plan_id"],
                    fields.get("member_id"),
                    fields.get("face_id"),
                    fields.get("cluster_id"),
                    _opt_json(fields.get("point_m")),
                    _opt_json(fields.get("region_m")),
                    fields["type"],
                    int(fields["condition_state"]),
                    fields.get("notes", ""),
                    actor,
                    now,
                ),
            )
            self._audit(
                conn,
                actor,
                fid,
                "create",
                f"{fields['type']}, condition {fields['condition_state']} on plan {fields['plan_id']}",
            )
        return self.get(fid)

    def get(self, finding_id: str) -> Finding:
        r = self.db.query_one("SELECT * FROM findings WHERE id = ?", (finding_id,))
        if r is None:
            raise NotFoundError(f"no finding with id {finding_id!r}")
        return Finding.from_row(r, tuple(self.photos(finding_id)))

    def listed(
        self,
        *,
        plan_id: str | None = None,
        member_id: int | None = None,
        type_: str | None = None,
        condition_state: int | None = None,
        min_condition_state: int | None = None,
        include_deleted: bool = False,
        limit: int = 500,
    ) -> list[Finding]:
        sql = "SELECT * FROM findings WHERE 1=1"
        args: list[Any] = []
        for col, val in (
            ("plan_id", plan_id),
            ("member_id", member_id),
            ("type", type_),
            ("condition_state", condition_state),
        ):
            if val is not None:
                sql += f" AND {col} = ?"
                args.append(val)
        if min_condition_state is not None:
            sql += " AND condition_state >= ?"
            args.append(min_condition_state)
        if not include_deleted:
            sql += " AND deleted_at IS NULL"
        sql += " ORDER BY created_at DESC, rowid DESC LIMIT ?"
        args.append(limit)
        return [Finding.from_row(r, tuple(self.photos(r["id"]))) for r in self.db.query(sql, args)]

    def update(self, finding_id: str, changes: dict[str, Any], actor: str) -> Finding:
        """Apply ``changes`` (keys of :data:`EDITABLE`); audited with the
        fields that changed, old → new."""
        before = self.get(finding_id)
        if before.deleted_at is not None:
            raise ValueError(f"finding {finding_id} is deleted; it can be read, not edited")
        changed = {k: v for k, v in changes.items() if getattr(before, k) != v}
        if not changed:
            return before
        sets = ", ".join(f"{k} = ?" for k in changed)
        vals = [_opt_json(v) if k in ("point_m", "region_m") else v for k, v in changed.items()]
        why = "; ".join(f"{k}: {getattr(before, k)!r} → {v!r}" for k, v in changed.items())
        with self.db.transaction() as conn:
            conn.execute(
                f"UPDATE findings SET {sets}, updated_by = ?, updated_at = ? WHERE id = ?",
                (*vals, actor, utcnow(), finding_id),
            )
            self._audit(conn, actor, finding_id, "edit", why[:2000])
        return self.get(finding_id)

    def delete(self, finding_id: str, actor: str, reason: str) -> Finding:
        """Mark it deleted (who, when, why); it stays readable."""
        before = self.get(finding_id)
        if before.deleted_at is not None:
            return before
        with self.db.transaction() as conn:
            conn.execute(
                "UPDATE findings SET deleted_by = ?, deleted_at = ?, deleted_reason = ? "
                "WHERE id = ?",
                (actor, utcnow(), reason, finding_id),
            )
            self._audit(conn, actor, finding_id, "delete", reason)
        return self.get(finding_id)

    # ------------------------------------------------------------------ photos
    def photos(self, finding_id: str) -> list[Photo]:
        rows = self.db.query(
            "SELECT * FROM finding_photos WHERE finding_id = ? ORDER BY created_at, rowid",
            (finding_id,),
        )
        return [Photo(**dict(r)) for r in rows]

    def add_photo(
        self, finding_id: str, data: bytes, filename: str, content_type: str, actor: str
    ) -> Photo:
        """Store the image file first, then its row (a crash leaves at worst an orphan file)."""
        self.get(finding_id)
        pid = f"ph_{secrets.token_hex(6)}"
        ensure_private_dir(self.photo_dir)
        path = self.photo_dir / pid
        tmp = path.with_suffix(".part")
        tmp.write_bytes(data)
        tmp.replace(path)
        with self.db.transaction() as conn:
            conn.execute(
                "INSERT INTO finding_photos (id, finding_id, filename, content_type, size, "
                "created_by, created_at) VALUES (?,?,?,?,?,?,?)",
                (pid, finding_id, filename, content_type, len(data), actor, utcnow()),
            )
            self._audit(conn, actor, finding_id, "photo", f"{filename} ({len(data)} bytes)")
        return next(p for p in self.photos(finding_id) if p.id == pid)

    def photo_file(self, finding_id: str, photo_id: str) -> tuple[Photo, Path]:
        for p in self.photos(finding_id):
            if p.id == photo_id:
                return p, self.photo_dir / p.id
        raise NotFoundError(f"finding {finding_id} has no photo {photo_id!r}")


def _opt_json(v: Any) -> str | None:
    return None if v is None else json.dumps(v)
