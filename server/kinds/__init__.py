"""The plan-kind registry.

Each plan kind is one module here defining ``KIND = PlanKind(...)``; adding a
kind means adding its module and one line to :data:`KIND_MODULES`.  Kinds
whose module fails to import (e.g. a planner still being written) are
reported by :func:`import_errors` rather than breaking the service.
"""

from __future__ import annotations

import importlib
import logging
import os
from functools import lru_cache

from server.kinds.base import Check, JobContext, KindOutput, PlanKind, PlanView

__all__ = [
    "KIND_MODULES",
    "Check",
    "JobContext",
    "KindOutput",
    "PlanKind",
    "PlanView",
    "get_kind",
    "import_errors",
    "registry",
    "sample_names",
]

log = logging.getLogger(__name__)

KIND_MODULES: list[str] = [
    "server.kinds.demo_route",
    "server.kinds.sbg_inspect",
    "server.kinds.ara_navigate",
    "server.kinds.blast",
    "server.kinds.ara_switch",
    "server.kinds.cmbot_climb",
    "server.kinds.cmbot_manipulate",
]

_errors: dict[str, str] = {}


@lru_cache(maxsize=1)
def registry() -> dict[str, PlanKind]:
    kinds: dict[str, PlanKind] = {}
    # STEELPATH_EXTRA_KINDS: comma-separated modules of site-specific kinds
    # (inherited by worker processes, which rebuild the registry).
    extra = [m.strip() for m in os.environ.get("STEELPATH_EXTRA_KINDS", "").split(",") if m.strip()]
    for modname in KIND_MODULES + extra:
        try:
            kind = importlib.import_module(modname).KIND
        except Exception as exc:  # a broken kind must not take the service down
            _errors[modname] = f"{type(exc).__name__}: {exc}"
            log.error("plan kind module %s failed to load: %s", modname, exc)
            continue
        if kind.name in kinds:
            raise RuntimeError(f"plan kind {kind.name!r} registered twice ({modname})")
        kinds[kind.name] = kind
    return kinds


def import_errors() -> dict[str, str]:
    registry()
    return dict(_errors)


class UnknownKindError(KeyError):
    def __str__(self) -> str:
        return str(self.args[0])


def get_kind(name: str) -> PlanKind:
    kinds = registry()
    if name not in kinds:
        raise UnknownKindError(
            f"unknown plan kind {name!r}; known kinds: {', '.join(sorted(kinds)) or 'none'}"
        )
    return kinds[name]


def sample_names() -> dict[str, str]:
    """Sample cloud name → the kind that provides it."""
    out: dict[str, str] = {}
    for kind in registry().values():
        for name in kind.samples:
            out[name] = kind.name
    return out
