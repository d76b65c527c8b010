"""Helpers that turn a planner's result into the stored summary of a
:class:`planners.result.PlanResult` ("shared helpers live
once"): thinning a long series for a console plot, the plot dict itself,
and a JSON-safe copy of a result (non-finite floats become ``null``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np


def thin(n: int, k: int = 400) -> np.ndarray:
    """At most ``k`` increasing indices into ``range(n)``, evenly spread and
    always holding the first and the last (a console plot needs no more)."""
    if n <= 0:
        return np.zeros(0, dtype=int)
    return np.unique(np.linspace(0, n - 1, min(n, k)).astype(int))


def finite_or_none(v: float) -> float | None:
    """``float(v)``, or ``None`` for NaN/±inf (JSON has no such numbers)."""
    return float(v) if math.isfinite(v) else None


def json_safe(v: Any) -> Any:
    """JSON-safe copy: non-finite floats become ``None``, arrays and tuples
    lists, numpy scalars Python numbers, mapping keys strings."""
    if isinstance(v, Mapping):
        return {str(k): json_safe(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [json_safe(x) for x in v]
    if isinstance(v, np.ndarray):
        return json_safe(v.tolist())
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.bool_):
        return bool(v)
    if isinstance(v, float | np.floating):
        return finite_or_none(float(v))
    return v


def plot(
    title: str,
    x: Sequence[float] | np.ndarray,
    series: Mapping[str, Sequence[float | None] | np.ndarray],
    *,
    x_label: str,
    y_label: str,
) -> dict[str, Any]:
    """One console plot in the stored form (``result["plots"]`` items):
    ``x`` and each series as JSON lists, non-finite values as ``null``."""
    return {
        "title": title,
        "x": json_safe(np.asarray(x, dtype=float)),
        "x_label": x_label,
        "y_label": y_label,
        "series": {str(name): json_safe(_column(ys)) for name, ys in series.items()},
    }


def _column(ys: Sequence[float | None] | np.ndarray) -> np.ndarray:
    if isinstance(ys, np.ndarray):
        return ys.astype(float)
    return np.asarray([np.nan if v is None else v for v in ys], dtype=float)
