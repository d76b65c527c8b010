"""Coarse-then-fine minimum of a Lipschitz signal against evaluating every sample."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from planners.motion.lipschitz import interiors, lipschitz_minimum


@settings(max_examples=200, deadline=None, derandomize=True)
@given(
    seed=st.integers(0, 2**31 - 1),
    n=st.integers(1, 400),
    stride=st.integers(1, 20),
    limit=st.floats(-1.0, 1.0),
    slack=st.floats(1.0, 3.0),
)
def test_minimum_and_everything_at_or_below_the_limit_are_exact(seed, n, stride, limit, slack):
    """Random signals whose steps are bounded (by ``slack`` × the true step):
    the minimum, its first position and every sample ≤ the limit equal the
    dense values; the other samples are lower bounds above max(limit, min);
    fewer evaluations than samples whenever it could skip."""
    rng = np.random.default_rng(seed)
    true_steps = rng.exponential(0.02, max(n - 1, 0)) * rng.choice([-1.0, 1.0], max(n - 1, 0))
    signal = rng.uniform(-0.5, 1.0) + np.r_[0.0, np.cumsum(true_steps)]
    calls: list[int] = []

    def evaluate(idx: np.ndarray) -> np.ndarray:
        calls.append(len(idx))
        return signal[idx]

    values, evaluated = lipschitz_minimum(
        evaluate, np.abs(true_steps) * slack, limit, stride=stride
    )
    assert values.min() == signal.min()
    assert np.argmin(values) == np.argmin(signal)
    assert np.all(values <= signal + 1e-12)
    np.testing.assert_array_equal(values[evaluated], signal[evaluated])
    low = signal <= max(limit, signal.min())
    assert evaluated[low].all()
    assert np.all(values[~evaluated] > max(limit, signal.min()))
    assert sum(calls) == evaluated.sum() <= n


def test_a_too_small_step_bound_can_miss_the_minimum():
    """The bound is what makes it exact: with steps understated, a dip between
    two coarse samples is skipped (so the test above can fail)."""
    signal = np.linspace(1.0, 2.0, 17)
    signal[8] = -1.0
    values, evaluated = lipschitz_minimum(lambda i: signal[i], np.full(16, 1e-3), 0.0, stride=16)
    assert not evaluated[8] and values.min() == 1.0


def test_interiors():
    np.testing.assert_array_equal(interiors(np.array([0, 5]), np.array([3, 6])), [1, 2])
    assert len(interiors(np.array([], dtype=int), np.array([], dtype=int))) == 0
