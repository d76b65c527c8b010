"""Import of a plan archive made by another SteelPath server.

**All or nothing.**  The zip is checked before anything is unpacked — its
size against the service's upload limit, its entry count and total
uncompressed size (zip bombs), every name (no absolute paths, no ``..``,
only the archive's layout), every entry's size against the one its manifest
lists — then every entry is inflated and hashed without being written
(stopping at the first byte past its declared size; a SHA-256 can only be
compared at the end of its entry, and a gigabyte of zeros under a wrong hash
must not reach the disk first), and only then unpacked under a temporary
directory beside the data, counted and hashed again.  The rows then go in
one SQLite transaction; the files are moved into place inside it, before the
commit, and removed again if anything fails, so a refused or failed import
leaves neither a row nor a file behind.  Ids are kept; an id already present
here (the plan, an execution, a finding, a photo, or a different cloud of
the same id) refuses the whole import with 409: nothing is overwritten.

**The state rule: an imported plan is ``archived``.**  Whatever state the
plan had on the exporting server (``approved``, ``completed``, even
``executing``), it comes in as :attr:`~server.lifecycle.PlanState.ARCHIVED`,
a state with no transition out: it cannot be approved, dispatched or resumed
here.  An approval given on another server, for another robot fleet and
maybe another version of the checks, says nothing about this site, and the
import is done by an admin, not by an operator who reviewed the plan here;
so "nothing moves a robot without an approved plan whose checks passed"
stays true of *this* server's approvals.  The history is kept: the plan's
row is otherwise as exported (params, result, program, checks, who created
and approved it and when), every audit event comes in with its original
time and actor, and an ``import`` event by the admin records the state it
had there (``from_state``) and ``archived`` (``to_state``).  To run it here,
revise it: the revision is a new plan, planned, checked and approved here.

Executions are history too.  One that was still active when exported
(``pending``, ``running``, ``paused``) comes in as ``interrupted`` with the
reason in its ``error`` and an ``import`` audit event; none can be resumed
(its plan is archived), and none makes its robot busy here.  The source
cloud is imported under its id unless this server already holds the same
cloud (same points); the MCAP files are checked but not stored — this server
writes the recording again from the imported rows.
"""

from __future__ import annotations

import hashlib
import json
import os
import secrets
import shutil
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from server.archive.manifest import (
    MANIFEST,
    MAX_ENTRIES,
    MAX_EXPANSION,
    MAX_MANIFEST_BYTES,
    ArchiveError,
    check_id,
    check_name,
    parse_manifest,
)
from server.lifecycle import ExecutionState, PlanState
from server.store import Store
from server.store.archive import ArchiveStore, IdConflictError, UnknownColumnsError
from server.store.database import IntegrityError, ensure_private_dir, utcnow
from server.store.store import cloud_attribute_relname

#: Execution states imported as ``interrupted``: the run was still going on
#: the exporting server, and how it ended is not known here.
STILL_ACTIVE = frozenset({ExecutionState.PENDING, ExecutionState.RUNNING, ExecutionState.PAUSED})
_CHUNK = 1 << 20


@dataclass
class ImportResult:
    """What an import wrote (the ids are the archive's: none is renamed)."""

    plan_id: str
    kind: str
    state: str
    original_state: str
    executions: list[str] = field(default_factory=list)
    interrupted: list[str] = field(default_factory=list)
    findings: list[str] = field(default_factory=list)
    photos: list[str] = field(default_factory=list)
    cloud_id: str | None = None
    cloud: str = "none"
    arrays: list[str] = field(default_factory=list)
    audit_events: int = 0
    parent_id_dropped: str | None = None
    #: Finding → maintenance plan links whose finding is neither in the
    #: archive nor here (kept out: the link would point at nothing).
    links_dropped: list[str] = field(default_factory=list)
    exported_at: str | None = None
    exported_by: str | None = None
    schema_version: int | None = None

    def public(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def _bad(detail: str) -> ArchiveError:
    return ArchiveError(422, detail)


def _open_zip(source: IO[bytes], size: int, limit: int) -> zipfile.ZipFile:
    if size > limit:
        raise ArchiveError(
            413, f"archive of {size} bytes exceeds the upload limit of {limit} bytes"
        )
    try:
        return zipfile.ZipFile(source)
    except (zipfile.BadZipFile, OSError, ValueError, EOFError):
        raise ArchiveError(400, "the upload is not a zip archive") from None


def _check_entries(zf: zipfile.ZipFile, limit: int) -> dict[str, zipfile.ZipInfo]:
    """Every file entry by name, after the bomb, name and duplicate checks."""
    infos = zf.infolist()
    if len(infos) > MAX_ENTRIES:
        raise ArchiveError(413, f"archive has {len(infos)} entries (at most {MAX_ENTRIES})")
    budget = MAX_EXPANSION * limit
    total = sum(i.file_size for i in infos)
    if total > budget:
        raise ArchiveError(
            413,
            f"archive unpacks to {total} bytes (at most {budget}: {MAX_EXPANSION}× the "
            "upload limit)",
        )
    entries: dict[str, zipfile.ZipInfo] = {}
    for info in infos:
        check_name(info.filename.rstrip("/") if info.is_dir() else info.filename)
        if info.is_dir():
            continue
        if info.flag_bits & 0x1:
            raise ArchiveError(400, f"encrypted entry {info.filename!r}")
        if info.filename in entries:
            raise ArchiveError(400, f"{info.filename!r} is in the archive twice")
        entries[info.filename] = info
    return entries


def _read_limited(zf: zipfile.ZipFile, info: zipfile.ZipInfo, limit: int) -> bytes:
    out = bytearray()
    with zf.open(info) as fh:
        while chunk := fh.read(_CHUNK):
            out += chunk
            if len(out) > min(limit, info.file_size):
                raise ArchiveError(413, f"{info.filename} unpacks to more than it declares")
    return bytes(out)


def _check_listed(entries: dict[str, zipfile.ZipInfo], listed: list[dict[str, Any]]) -> None:
    """The manifest's files against the zip's entries, before any entry is read:
    the same names, and no entry larger than its manifest declares (422).  A
    smaller one is read (it is small) and fails its SHA-256 at its end."""
    names = {f["name"] for f in listed}
    extra = sorted(set(entries) - names - {MANIFEST})
    if extra:
        raise _bad(f"{extra[0]} is in the archive but not in its manifest")
    missing = sorted(names - set(entries))
    if missing:
        raise _bad(f"{missing[0]} is listed in the manifest but not in the archive")
    for f in listed:
        zipped = entries[f["name"]].file_size
        if zipped > f["size"]:
            raise _bad(
                f"{f['name']} unpacks to {zipped} bytes, more than the {f['size']} its "
                "manifest declares"
            )


def _stream(
    zf: zipfile.ZipFile, info: zipfile.ZipInfo, expect: dict[str, Any], sink: IO[bytes] | None
) -> None:
    """Inflate one entry in chunks into ``sink`` (None: only check it), counting
    and hashing as it goes; 422 naming the entry at the first byte past the size
    its manifest declares, or when its size or SHA-256 differs at its end."""
    name, declared = info.filename, int(expect["size"])
    h = hashlib.sha256()
    size = 0
    try:
        with zf.open(info) as src:
            # One byte past the declared size is enough to know it lies.
            while chunk := src.read(min(_CHUNK, declared - size + 1)):
                size += len(chunk)
                if size > declared:
                    raise _bad(f"{name} unpacks to more than the {declared} bytes declared for it")
                h.update(chunk)
                if sink is not None:
                    sink.write(chunk)
    except (zipfile.BadZipFile, zlib.error, EOFError):
        # zlib's and zipfile's own words say nothing more to the person importing.
        raise ArchiveError(
            400, f"{name} cannot be unpacked: its compressed data is damaged"
        ) from None
    if size != declared or h.hexdigest() != expect["sha256"]:
        sizes = f"; {size} bytes, the manifest lists {declared}" if size != declared else ""
        raise _bad(
            f"sha256 mismatch for {name}: the file is not the one exported "
            f"(changed or damaged since{sizes})"
        )


def _unpack(
    zf: zipfile.ZipFile, info: zipfile.ZipInfo, target: Path, expect: dict[str, Any]
) -> None:
    """Stream one entry to ``target``, counting and hashing (see :func:`_stream`)."""
    with open(target, "wb") as dst:
        _stream(zf, info, expect, dst)


def _load_json(path: Path, name: str) -> Any:
    try:
        return json.loads(path.read_bytes())
    except (ValueError, UnicodeDecodeError) as exc:
        raise _bad(f"{name} is not valid JSON: {exc}") from None


def _json_col(value: Any) -> str | None:
    return None if value is None else json.dumps(value, allow_nan=False, separators=(",", ":"))


class _Importer:
    """One import: unpacked files under ``tmp``, rows gathered, then written."""

    def __init__(self, store: Store, actor: str, tmp: Path) -> None:
        self.store = store
        self.actor = actor
        self.tmp = tmp
        self.rows = ArchiveStore(store.db)
        self.files: dict[str, Path] = {}
        self.moves: list[tuple[Path, Path]] = []
        self.moved: list[Path] = []

    def unpack(
        self, zf: zipfile.ZipFile, entries: dict[str, zipfile.ZipInfo], listed: list[dict[str, Any]]
    ) -> None:
        """Write every listed entry under ``tmp`` (checked by :func:`_check_listed`
        and :func:`_stream` before: this pass counts and hashes again)."""
        for i, f in enumerate(listed):
            target = self.tmp / f".tmp-{i}"
            _unpack(zf, entries[f["name"]], target, f)
            self.files[f["name"]] = target

    def json(self, name: str) -> Any:
        if name not in self.files:
            raise _bad(f"the archive has no {name}")
        return _load_json(self.files[name], name)

    def _check_npy(self, name: str) -> None:
        try:
            np.load(self.files[name], mmap_mode="r", allow_pickle=False)
        except (ValueError, OSError, EOFError):
            # numpy's words may hold the temporary file's path: not for the response.
            raise _bad(f"{name} is not a readable .npy array") from None

    def build(
        self, manifest: dict[str, Any]
    ) -> tuple[ImportResult, dict[str, list[dict[str, Any]]], dict[str, list[str]]]:
        plan = self.json("plan.json")
        if not isinstance(plan, dict):
            raise _bad("plan.json is not a JSON object")
        pid = check_id(plan.get("id"), "plan.json: id")
        if pid != manifest["plan_id"]:
            raise _bad(f"plan.json is plan {pid}, the manifest says {manifest['plan_id']}")
        original = str(plan.get("state"))
        result = ImportResult(
            plan_id=pid,
            kind=str(plan.get("kind")),
            state=str(PlanState.ARCHIVED),
            original_state=original,
            exported_at=manifest.get("exported_at"),
            exported_by=manifest.get("exported_by"),
            schema_version=manifest.get("schema_version"),
        )
        try:
            arrays = {}
            for name in sorted(plan.get("arrays") or {}):
                fname = f"arrays/{name}.npy"
                if fname not in self.files:
                    raise _bad(f"plan.json names array {name!r} but the archive has no {fname}")
                self._check_npy(fname)
                rel = f"plans/{pid}/{name}.npy"
                arrays[name] = rel
                self.moves.append((self.files[fname], self.store.arrays.path(rel)))
            result.arrays = sorted(arrays)
            parent = plan.get("parent_id")
            if parent is not None and not self.rows.existing("plans", [str(parent)]):
                result.parent_id_dropped, parent = str(parent), None
            plan_row = {
                "id": pid,
                "kind": str(plan["kind"]),
                "state": str(PlanState.ARCHIVED),
                "params": _json_col(plan.get("params") or {}),
                "parent_id": parent,
                "progress": float(plan.get("progress") or 0.0),
                "stage": str(plan.get("stage") or ""),
                "result": _json_col(plan.get("result")),
                "metrics": _json_col(plan.get("metrics")),
                "checks": _json_col(plan.get("checks")),
                "arrays": _json_col(arrays),
                "error": plan.get("error"),
                "created_at": str(plan["created_at"]),
                "updated_at": str(plan["updated_at"]),
                "created_by": str(plan["created_by"]),
                "approved_by": plan.get("approved_by"),
                "approved_at": plan.get("approved_at"),
                "program": _json_col(plan.get("program")),
            }
        except (KeyError, TypeError, ValueError) as exc:
            if isinstance(exc, ArchiveError):
                raise
            raise _bad(f"plan.json is incomplete or malformed: {exc!r}") from None

        rows: dict[str, list[dict[str, Any]]] = {"plans": [plan_row]}
        new: dict[str, list[str]] = {"plans": [pid]}
        events: list[dict[str, Any]] = []

        # The source cloud: imported, or already here with the same points.
        clouds = [n for n in self.files if n.startswith("cloud/") and n.endswith(".json")]
        rows["clouds"] = []
        for name in clouds:
            cid = check_id(name[len("cloud/") : -len(".json")], "cloud id")
            npy = f"cloud/{cid}.npy"
            if npy not in self.files:
                raise _bad(f"the archive has {name} but no {npy}")
            self._check_npy(npy)
            row = self.json(name)
            if not isinstance(row, dict) or row.get("id") != cid:
                raise _bad(f"{name} is not the row of cloud {cid}")
            result.cloud_id = cid
            if self.rows.existing("clouds", [cid]):
                here = self.store.cloud_path(cid)
                if _sha256(here) != _sha256(self.files[npy]):
                    raise ArchiveError(
                        409, f"cloud {cid} already exists here with other points; not overwritten"
                    )
                result.cloud = "already here"
                continue
            rel = f"clouds/{cid}.npy"
            # Per-point attributes travel beside the points; one the archive
            # lacks is dropped from the row rather than named without its file.
            attrs = row.get("attributes") or "{}"
            named = json.loads(attrs) if isinstance(attrs, str) else dict(attrs)
            carried: dict[str, str] = {}
            for attr in sorted(named):
                check_id(attr, "cloud attribute")
                src = f"cloud/{cid}.{attr}.npy"
                if src in self.files:
                    self._check_npy(src)
                    carried[attr] = cloud_attribute_relname(cid, attr)
                    self.moves.append((self.files[src], self.store.arrays.path(carried[attr])))
            rows["clouds"].append({**row, "array_file": rel, "attributes": json.dumps(carried)})
            new["clouds"] = [cid]
            self.moves.append((self.files[npy], self.store.arrays.path(rel)))
            result.cloud = "imported"
            events.append(self._event("cloud", cid, "import", reason=f"source cloud of plan {pid}"))

        # Executions: rows, acks, states; still active → interrupted.
        rows["executions"], rows["execution_acks"], rows["execution_states"] = [], [], []
        for name in sorted(self.files):
            if not (name.startswith("executions/") and name.endswith(".json")):
                continue
            eid = check_id(name[len("executions/") : -len(".json")], "execution id")
            doc = self.json(name)
            try:
                ex = dict(doc["execution"])
                if ex.get("id") != eid or ex.get("plan_id") != pid:
                    raise _bad(f"{name} is not an execution {eid} of plan {pid}")
                if f"executions/{eid}.mcap" not in self.files:
                    raise _bad(f"the archive has {name} but no executions/{eid}.mcap")
                if ex.get("state") in STILL_ACTIVE:
                    why = (
                        f"imported while {ex['state']} on the exporting server "
                        f"(exported {manifest.get('exported_at')}): how it ended is not known here"
                    )
                    events.append(
                        self._event("execution", eid, "import", ex["state"], "interrupted", why)
                    )
                    ex.update(state=str(ExecutionState.INTERRUPTED), error=why)
                    result.interrupted.append(eid)
                rows["executions"].append(ex)
                rows["execution_acks"] += [
                    {"execution_id": eid, "idx": int(i), "ts": str(ts)} for i, ts in doc["acks"]
                ]
                rows["execution_states"] += [
                    {"execution_id": eid, "t": float(t), "state": _json_col(st)}
                    for t, st in doc["states"]
                ]
            except (KeyError, TypeError, ValueError) as exc:
                if isinstance(exc, ArchiveError):
                    raise
                raise _bad(f"{name} is malformed: {exc!r}") from None
            result.executions.append(eid)
        new["executions"] = result.executions

        # Findings (deleted ones too) and their photos.
        doc = self.json("findings.json")
        try:
            findings = [dict(f) for f in doc["findings"]]
            photos = [(dict(p["row"]), str(p["file"])) for p in doc["photos"]]
        except (KeyError, TypeError, ValueError) as exc:
            raise _bad(f"findings.json is malformed: {exc!r}") from None
        fids = set()
        for f in findings:
            fids.add(check_id(f.get("id"), "findings.json: finding id"))
            if f.get("plan_id") != pid:
                raise _bad(f"findings.json: finding {f.get('id')} is not on plan {pid}")
        photo_dir = self.store.data_dir / "photos"
        for p, fname in photos:
            phid = check_id(p.get("id"), "findings.json: photo id")
            if p.get("finding_id") not in fids:
                raise _bad(f"findings.json: photo {phid} is of no finding in the archive")
            if fname not in self.files or not fname.startswith(f"photos/{p['finding_id']}/{phid}."):
                raise _bad(f"findings.json: photo {phid}'s file {fname!r} is not in the archive")
            self.moves.append((self.files[fname], photo_dir / phid))
        rows["findings"] = findings
        rows["finding_photos"] = [p for p, _ in photos]
        result.findings = [f["id"] for f in findings]
        result.photos = [p["id"] for p, _ in photos]
        new["findings"] = result.findings
        new["finding_photos"] = result.photos
        rows["finding_plans"] = self._links(doc.get("finding_plans") or [], fids, result)

        # The audit trail as it was, then this import's own events.
        audit = self.json("audit.json")
        if not isinstance(audit, list) or not all(isinstance(e, dict) for e in audit):
            raise _bad("audit.json is not a list of events")
        kept = [{k: v for k, v in e.items() if k != "id"} for e in audit]
        origin = (
            f"exported {manifest.get('exported_at')} by {manifest.get('exported_by')} from "
            f"SteelPath {manifest.get('server_version')} (schema {manifest.get('schema_version')})"
        )
        events.insert(
            0,
            self._event(
                "plan",
                pid,
                "import",
                original,
                str(PlanState.ARCHIVED),
                f"imported as read-only history, {origin}; it was {original} there. "
                "Revise it to plan and approve it here.",
            ),
        )
        rows["audit_events"] = kept + events
        result.audit_events = len(rows["audit_events"])
        return result, rows, new

    def _links(self, links: Any, fids: set[str], result: ImportResult) -> list[dict[str, Any]]:
        """The finding → maintenance plan links to insert: those whose finding
        is in the archive or here, not already here (an identical row here is
        skipped; a different one for the same plan is a 409)."""
        if not isinstance(links, list) or not all(isinstance(r, dict) for r in links):
            raise _bad("findings.json: finding_plans is not a list of rows")
        if not links:
            return []
        if not self.rows.columns("finding_plans"):
            raise _bad("the archive links findings to plans; this server has no such links")
        out = []
        for link in links:
            fid, lpid = link.get("finding_id"), link.get("plan_id")
            if fid not in fids and not self.rows.existing("findings", [str(fid)]):
                result.links_dropped.append(f"{fid} → {lpid}")
                continue
            here = self.rows.rows("finding_plans", "plan_id", [str(lpid)])
            if here:
                if here[0] != link:
                    raise ArchiveError(
                        409,
                        f"plan {lpid} is already linked here to finding "
                        f"{here[0].get('finding_id')}; not overwritten",
                    )
                continue
            out.append(dict(link))
        return out

    def _event(
        self,
        entity: str,
        entity_id: str,
        action: str,
        from_state: str | None = None,
        to_state: str | None = None,
        reason: str = "",
    ) -> dict[str, Any]:
        return {
            "ts": utcnow(),
            "actor": self.actor,
            "entity": entity,
            "entity_id": entity_id,
            "action": action,
            "from_state": from_state,
            "to_state": to_state,
            "reason": reason,
        }

    def move_files(self) -> None:
        """Move every unpacked file into place (inside the rows' transaction)."""
        for src, dst in self.moves:
            if dst.exists():
                raise ArchiveError(409, f"{dst.name} already exists here; not overwritten")
            ensure_private_dir(dst.parent)
            os.replace(src, dst)
            self.moved.append(dst)

    def undo_moves(self) -> None:
        """Remove the files :meth:`move_files` put in place (the rows rolled back)."""
        for dst in self.moved:
            dst.unlink(missing_ok=True)


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while chunk := fh.read(_CHUNK):
            h.update(chunk)
    return h.hexdigest()


def import_archive(
    store: Store, source: IO[bytes], size: int, *, limit: int, actor: str
) -> ImportResult:
    """Import the plan archive in ``source`` (``size`` bytes); all or nothing.

    ``limit`` is the service's upload limit in bytes.  Raises
    :class:`~server.archive.manifest.ArchiveError` (with its HTTP status) for
    every refusal; on any error nothing is left behind.
    """
    zf = _open_zip(source, size, limit)
    with zf:
        entries = _check_entries(zf, limit)
        if MANIFEST not in entries:
            raise _bad("the archive has no manifest.json")
        try:
            manifest = parse_manifest(
                json.loads(_read_limited(zf, entries[MANIFEST], MAX_MANIFEST_BYTES))
            )
        except (ValueError, UnicodeDecodeError) as exc:
            if isinstance(exc, ArchiveError):
                raise
            raise _bad(f"manifest.json is not valid JSON: {exc}") from None
        rows = ArchiveStore(store.db)
        if rows.existing("plans", [manifest["plan_id"]]):
            raise ArchiveError(
                409, f"plan {manifest['plan_id']} already exists here; an import never overwrites"
            )
        _check_listed(entries, manifest["files"])
        # Every entry checked before one is written: nothing of a refused
        # archive touches the disk.  Costs a second inflate of a good one.
        for f in manifest["files"]:
            _stream(zf, entries[f["name"]], f, None)
        uploads = store.data_dir / "uploads"
        ensure_private_dir(uploads)
        tmp = uploads / f"import-{secrets.token_hex(6)}"
        tmp.mkdir(mode=0o700)
        imp = _Importer(store, actor, tmp)
        try:
            imp.unpack(zf, entries, manifest["files"])
            result, table_rows, new = imp.build(manifest)
            try:
                rows.write(table_rows, must_be_new=new, before_commit=imp.move_files)
            except BaseException:
                imp.undo_moves()  # the transaction rolled back: so do the files
                raise
        except IdConflictError as exc:
            raise ArchiveError(
                409,
                f"{exc.table} {', '.join(exc.ids)} already exist here; an import never overwrites",
            ) from None
        except (UnknownColumnsError, IntegrityError) as exc:
            raise _bad(f"the archive's rows do not fit this server's database: {exc}") from None
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    return result
