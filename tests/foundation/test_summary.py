"""planners.summary: the helpers that shape a stored summary, against hand cases."""

from __future__ import annotations

import json
import math

import numpy as np

from planners.summary import finite_or_none, json_safe, plot, thin


def test_thin_keeps_the_ends_and_at_most_k() -> None:
    for n in (1, 2, 7, 400, 401, 10_000):
        for k in (2, 50, 400, 600):
            idx = thin(n, k)
            assert idx[0] == 0 and idx[-1] == n - 1
            assert len(idx) <= min(n, k) and np.all(np.diff(idx) > 0)
    assert thin(5, 400).tolist() == [0, 1, 2, 3, 4]  # short series are kept whole
    assert len(thin(0)) == 0


def test_json_safe_nulls_non_finite_numbers_everywhere() -> None:
    src = {
        1: np.array([1.0, np.nan, np.inf]),
        "t": (np.float32(2.5), np.int64(3), np.bool_(True)),
        "nested": [{"x": -math.inf}, "text", None],
    }
    out = json_safe(src)
    assert out == {
        "1": [1.0, None, None],
        "t": [2.5, 3, True],
        "nested": [{"x": None}, "text", None],
    }
    json.dumps(out, allow_nan=False)  # strict JSON
    assert finite_or_none(float("nan")) is None and finite_or_none(2.0) == 2.0


def test_plot_is_the_stored_form() -> None:
    p = plot(
        "title",
        np.array([0.0, 1.0]),
        {"a": np.array([1.0, np.nan]), "b": [None, 2]},
        x_label="s",
        y_label="m",
    )
    assert p == {
        "title": "title",
        "x": [0.0, 1.0],
        "x_label": "s",
        "y_label": "m",
        "series": {"a": [1.0, None], "b": [None, 2.0]},
    }
    json.dumps(p, allow_nan=False)
