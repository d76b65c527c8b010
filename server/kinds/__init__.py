"""Plan kinds: one module a kind (``KIND = PlanKind(...)``), found by :mod:`server.kinds.catalog`.

Adding a kind is adding its module here; see docs/DEVELOPING.md, "Adding a robot".
"""

from server.kinds.base import Check, JobContext, KindOutput, PlanKind, PlanView
from server.kinds.catalog import (
    KIND_MODULES,
    UnknownKindError,
    discover_kind_modules,
    get_kind,
    import_errors,
    registry,
    sample_names,
)

__all__ = [
    "KIND_MODULES",
    "Check",
    "JobContext",
    "KindOutput",
    "PlanKind",
    "PlanView",
    "UnknownKindError",
    "discover_kind_modules",
    "get_kind",
    "import_errors",
    "registry",
    "sample_names",
]
