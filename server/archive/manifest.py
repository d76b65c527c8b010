"""The archive format: its name and version, its layout, its limits and errors.

A plan archive is a zip holding ``manifest.json`` and the files it lists,
each with its size and SHA-256::

    manifest.json                  format, versions, plan id, files, counts
    plan.json                      the plan as GET /api/v1/plans/{id} shows it
    arrays/<name>.npy              the plan's stored result arrays
    cloud/<cloud_id>.json, .npy    the source cloud's row and points (if any)
    executions/<id>.json           an execution's row, acks (index, time), states
    executions/<id>.mcap           the same run as MCAP (server.recording)
    findings.json                  every finding of the plan (deleted ones too)
                                   and its photos' rows
    photos/<finding>/<photo>.<ext> the photo files
    audit.json                     the audit events of the plan, its
                                   executions and its findings

Names are checked before anything is read (:func:`check_name`): relative,
``/``-separated, no ``..``, no backslash, no drive, inside this layout.
"""

from __future__ import annotations

import re
from typing import Any

#: The format's name in ``manifest.json``.
FORMAT = "steelpath.plan-archive"
#: The one version this server writes and reads.
FORMAT_VERSION = 1
MANIFEST = "manifest.json"

#: Most entries an archive may hold (checked before extracting).
MAX_ENTRIES = 10_000
#: Total uncompressed size an archive may unpack to, as a multiple of the
#: service's upload limit (``STEELPATH_MAX_UPLOAD_MB``): arrays and JSON
#: compress, but not by more than this unless the zip is a bomb.
MAX_EXPANSION = 4
#: Largest ``manifest.json`` read (bytes).
MAX_MANIFEST_BYTES = 16 * 1024 * 1024

#: Ids the archive uses as file names: what :func:`server.store.new_id` makes.
ID = r"[A-Za-z0-9][A-Za-z0-9_-]{0,63}"
_ID_RX = re.compile(f"^{ID}$")
#: Every name an archive may hold besides the manifest.
LAYOUT = re.compile(
    r"^(?:plan\.json|findings\.json|audit\.json"
    rf"|arrays/[A-Za-z0-9_][A-Za-z0-9_.-]{{0,99}}\.npy"
    rf"|cloud/{ID}\.(?:json|npy)"
    rf"|cloud/{ID}\.(?:intensity|rgb|classification)\.npy"
    rf"|executions/{ID}\.(?:json|mcap)"
    rf"|photos/{ID}/{ID}\.[A-Za-z0-9]{{1,8}})$"
)


class ArchiveError(Exception):
    """Why an archive is refused: ``status`` (HTTP) and a message for ``detail``."""

    def __init__(self, status: int, detail: str) -> None:
        super().__init__(detail)
        self.status = status
        self.detail = detail


def check_id(value: Any, what: str) -> str:
    """``value`` if it is a plain id (safe as a file name), else 422."""
    if not isinstance(value, str) or not _ID_RX.match(value):
        raise ArchiveError(422, f"{what} {value!r} is not a valid id")
    return value


def check_name(name: str) -> str:
    """``name`` if it is a safe relative name of this layout, else 400."""
    parts = name.split("/")
    if (
        not name
        or name.startswith("/")
        or "\\" in name
        or ":" in name
        or "\x00" in name
        or any(p in ("", ".", "..") for p in parts)
    ):
        raise ArchiveError(400, f"unsafe file name in the archive: {name!r}")
    if name != MANIFEST and not LAYOUT.match(name):
        raise ArchiveError(400, f"unexpected file in the archive: {name!r}")
    return name


def parse_manifest(raw: Any) -> dict[str, Any]:
    """Check a decoded ``manifest.json``: format, version, plan id, file list (422)."""
    if not isinstance(raw, dict):
        raise ArchiveError(422, "manifest.json is not a JSON object")
    if raw.get("format") != FORMAT:
        raise ArchiveError(422, f"manifest.json: format {raw.get('format')!r} is not {FORMAT!r}")
    version = raw.get("format_version")
    if version != FORMAT_VERSION:
        raise ArchiveError(
            422,
            f"manifest.json: unknown format version {version!r}; this server reads "
            f"version {FORMAT_VERSION}",
        )
    check_id(raw.get("plan_id"), "manifest.json: plan_id")
    files = raw.get("files")
    if not isinstance(files, list):
        raise ArchiveError(422, "manifest.json: files must be a list")
    seen: set[str] = set()
    for f in files:
        if not (
            isinstance(f, dict)
            and isinstance(f.get("name"), str)
            and isinstance(f.get("sha256"), str)
            and re.fullmatch(r"[0-9a-f]{64}", f["sha256"])
            and isinstance(f.get("size"), int)
            and f["size"] >= 0
        ):
            raise ArchiveError(422, f"manifest.json: bad file entry {f!r:.200}")
        if f["name"] == MANIFEST or f["name"] in seen:
            raise ArchiveError(422, f"manifest.json: {f['name']!r} listed twice")
        check_name(f["name"])
        seen.add(f["name"])
    for required in ("plan.json", "findings.json", "audit.json"):
        if required not in seen:
            raise ArchiveError(422, f"manifest.json does not list {required}")
    return raw
