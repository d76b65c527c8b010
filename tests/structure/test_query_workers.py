"""The stages' batch KD-tree queries run on ``QUERY_WORKERS`` threads; the
model must not depend on the count (each query point is answered alone)."""

from __future__ import annotations

import numpy as np
import pytest

import planners.structure.features as features
import planners.structure.lines as lines
import planners.structure.sparse as sparse
from planners.structure import model_structure
from planners.structure.synthetic import make_scan


@pytest.mark.parametrize(("kind", "spacing"), [("warren", 0.02), ("grillage", 0.1)])
def test_one_thread_and_two_give_the_same_model(monkeypatch, kind: str, spacing: float) -> None:
    scan = make_scan(kind, 3, spacing_m=spacing)
    pts = scan.points / scan.scale
    models = []
    for workers in (1, 2):
        for module in (features, lines, sparse):
            monkeypatch.setattr(module, "QUERY_WORKERS", workers)
        models.append(model_structure(pts))
    one, two = models
    assert len(one.members) > 5
    np.testing.assert_array_equal(one.labels, two.labels)
    np.testing.assert_array_equal(
        np.array([m.axis for m in one.members]), np.array([m.axis for m in two.members])
    )
    assert [j.members for j in one.joints] == [j.members for j in two.joints]
