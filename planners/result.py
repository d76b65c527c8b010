"""The one result contract between a planner entry point and a plan kind
(DESIGN §5).

Every kind's planner entry point returns a :class:`PlanResult`: the stored
summary (JSON-ready), the named arrays, the checks and the flat metrics.  A
kind passes it through (:meth:`server.kinds.base.KindOutput.from_result`);
it adds nothing algorithmic of its own.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Check:
    """One safety or quality check of a plan (DESIGN §4): its name, whether it
    passed, the measured value, the limit it was held to and a sentence that
    says so.  The same fields as the server's stored ``Check``."""

    name: str
    passed: bool
    value: float | str | bool | None = None
    limit: float | str | bool | None = None
    message: str = ""


def _compare(
    name: str, value: float, limit: float, what: str, unit: str, scale: float, le: bool
) -> Check:
    v, lim = float(value) * scale, float(limit) * scale
    ok = bool(math.isfinite(v) and (v <= lim if le else v >= lim))
    rel = ("≤" if ok else ">") if le else ("≥" if ok else "<")
    return Check(
        name=name,
        passed=ok,
        value=v,
        limit=lim,
        message=f"{what} {v:.6g}{unit} {rel} {lim:.6g}{unit}",
    )


def check_le(
    name: str, value: float, limit: float, what: str, unit: str = "", scale: float = 1.0
) -> Check:
    """``value <= limit`` (both multiplied by ``scale`` for display, e.g. 1e3
    for millimetres) as a :class:`Check`; a non-finite value fails."""
    return _compare(name, value, limit, what, unit, scale, le=True)


def check_ge(
    name: str, value: float, limit: float, what: str, unit: str = "", scale: float = 1.0
) -> Check:
    """``value >= limit`` (both scaled by ``scale``) as a :class:`Check`; a
    non-finite value fails."""
    return _compare(name, value, limit, what, unit, scale, le=False)


@dataclass
class PlanResult:
    """What a planner entry point hands a plan kind to store.

    ``summary`` is small and JSON-ready (numbers, strings, lists, dicts; no
    NaN: see :func:`planners.summary.json_safe`); big arrays go in ``arrays``
    under the names the scene drawer reads; ``metrics`` is flat, with units in
    the names (``route_length_m``).
    """

    summary: dict[str, Any] = field(default_factory=dict)
    arrays: dict[str, np.ndarray] = field(default_factory=dict)
    checks: list[Check] = field(default_factory=list)
    metrics: dict[str, float] = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        """Every check passed (an empty list passes)."""
        return all(c.passed for c in self.checks)
