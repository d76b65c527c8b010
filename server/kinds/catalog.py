"""The plan-kind catalogue: which modules are kinds, and the registry built from them.

A plan kind is one module of this package that assigns ``KIND = PlanKind(...)``
at top level; the catalogue finds such modules by reading their source (so
adding a kind is adding its module, no list to edit) and imports them when
the registry is first asked for.  Kinds whose module fails to import (e.g. a
planner still being written) are reported by :func:`import_errors` rather
than breaking the service.
"""

from __future__ import annotations

import importlib
import logging
import os
import re
from functools import lru_cache
from pathlib import Path

from server.kinds.base import PlanKind

_KIND_ASSIGNMENT = re.compile(r"^KIND\s*(?::[^=]+)?=", re.MULTILINE)


def discover_kind_modules(package_dir: Path, package: str) -> list[str]:
    """Modules of ``package`` (at ``package_dir``) that assign ``KIND`` at top level, by name."""
    found = []
    for path in sorted(package_dir.glob("*.py")):
        if path.name.startswith("_"):
            continue
        if _KIND_ASSIGNMENT.search(path.read_text(encoding="utf-8")):
            found.append(f"{package}.{path.stem}")
    return found


#: The built-in kind modules, found in this package.
KIND_MODULES: list[str] = discover_kind_modules(Path(__file__).resolve().parent, "server.kinds")

log = logging.getLogger(__name__)

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
