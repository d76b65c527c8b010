"""The minimum of a Lipschitz signal along a sampled path, without evaluating
every sample (coarse-then-fine; the same bound as the CMBOT gate's
:class:`planners.cmbot.simulate.CoarseFineClearance`).

A clearance along a motion changes between samples j and j+1 by at most
``steps[j]``, the farthest any point of the robot moves between them (the
distance to a fixed obstacle, and to another moving point, is 1-Lipschitz in
each point; a pair moving together counts both steps, which the caller folds
into ``steps``).  Between two evaluated samples a < b, with P(a, b) the summed
steps, every sample j has

    d_j ≥ max(d_a − P(a, j), d_b − P(j, b)) ≥ (d_a + d_b − P(a, b)) / 2.

Every ``stride``-th sample (and the last) is evaluated; the samples between
two of them are evaluated too only when that bound reaches the threshold
``max(limit, smallest value seen)``.  A sample left out is therefore strictly
above the limit and above the path's minimum: the minimum, where it is, and
every sample at or below the limit are exact.  Left-out samples hold their
lower bound.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

#: Slack on the bound against rounding (far below any clearance margin).
_SLACK = 1e-9


def interiors(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """All integers strictly between a[i] and b[i], concatenated (a < b)."""
    lens = b - a - 1
    if not len(a) or lens.sum() <= 0:
        return np.zeros(0, dtype=int)
    offs = np.arange(int(lens.sum())) - np.repeat(np.cumsum(lens) - lens, lens)
    return np.repeat(a + 1, lens) + offs


def lipschitz_minimum(
    evaluate: Callable[[np.ndarray], np.ndarray],
    steps: np.ndarray,
    limit: float,
    *,
    stride: int = 8,
) -> tuple[np.ndarray, np.ndarray]:
    """Values of a signal at ``len(steps) + 1`` samples and which were evaluated.

    ``evaluate(indices)`` returns the exact values at those samples;
    ``steps[j]`` ≥ |value(j+1) − value(j)|.  Returns (values, evaluated):
    exact where evaluated, a lower bound above ``max(limit, minimum)`` elsewhere.
    """
    steps = np.asarray(steps, dtype=float)
    n = len(steps) + 1
    values = np.full(n, np.nan)
    evaluated = np.zeros(n, dtype=bool)
    coarse = np.unique(np.r_[np.arange(0, n, max(1, int(stride))), n - 1])
    values[coarse] = evaluate(coarse)
    evaluated[coarse] = True
    threshold = max(float(limit), float(np.min(values[coarse]))) + _SLACK
    path = np.r_[0.0, np.cumsum(steps)]
    a, b = coarse[:-1], coarse[1:]
    with np.errstate(invalid="ignore"):  # inf + inf − finite stays inf; nothing is inf − inf
        bound = (values[a] + values[b] - (path[b] - path[a])) / 2.0
    gaps = b - a - 1
    refine = (bound <= threshold) & (gaps > 0)
    fine = interiors(a[refine], b[refine])
    if len(fine):
        values[fine] = evaluate(fine)
        evaluated[fine] = True
    skip = ~refine & (gaps > 0)
    values[interiors(a[skip], b[skip])] = np.repeat(bound[skip], gaps[skip])
    return values, evaluated
