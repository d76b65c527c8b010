"""Input validation shared by the point-cloud primitives."""

from __future__ import annotations

import numpy as np

from planners.errors import EmptyInputError, InvalidInputError


def as_points(
    points: object,
    name: str = "points",
    *,
    dims: int | tuple[int, ...] = 3,
    finite: bool = True,
    allow_empty: bool = True,
) -> np.ndarray:
    """Return ``points`` as a float64 (N, D) array or raise a planner error.

    ``dims`` is the accepted column count (or a tuple of them); ``finite``
    rejects NaN/inf rows (use :func:`planners.pointcloud.drop_nonfinite` first).
    """
    try:
        arr = np.asarray(points, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"{name} must be a numeric (N, D) array ({exc})") from exc
    ok_dims = (dims,) if isinstance(dims, int) else tuple(dims)
    if arr.ndim != 2 or arr.shape[1] not in ok_dims:
        want = " or ".join(f"(N, {d})" for d in ok_dims)
        raise InvalidInputError(f"{name} must have shape {want}, got {arr.shape}")
    if not allow_empty and arr.shape[0] == 0:
        raise EmptyInputError(f"{name} is empty; at least one point is needed")
    if finite and not np.all(np.isfinite(arr)):
        bad = int(np.count_nonzero(~np.all(np.isfinite(arr), axis=1)))
        raise InvalidInputError(
            f"{name} has {bad} row(s) with NaN/inf; drop them first (drop_nonfinite)"
        )
    return arr


def positive(value: object, name: str) -> float:
    """A finite float > 0, or :class:`InvalidInputError`."""
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError) as exc:
        raise InvalidInputError(f"{name} must be a positive number, got {value!r}") from exc
    if not np.isfinite(v) or v <= 0:
        raise InvalidInputError(f"{name} must be a positive finite number, got {value!r}")
    return v
