"""A plan's history as a zip, exported from one server and imported on another.
Format and limits: :mod:`server.archive.manifest`; export:
:mod:`server.archive.export`; import and its state rule (imported plans are
``archived``, never dispatchable): :mod:`server.archive.import_`."""

from server.archive.export import export_plan
from server.archive.import_ import ImportResult, import_archive
from server.archive.manifest import FORMAT, FORMAT_VERSION, ArchiveError

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "ArchiveError",
    "ImportResult",
    "export_plan",
    "import_archive",
]
