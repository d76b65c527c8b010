"""The read-only view of a stored plan that compilers (``server.kinds``) and
scene drawers (``server.scene``) both take.

It lives below both layers so that a drawer can name the type without
importing the kinds (the scene never imports ``server.kinds``, DESIGN §2);
:mod:`server.kinds.base` re-exports it.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol

import numpy as np


class PlanView(Protocol):
    """A stored plan as drawers and compilers see it (read-only)."""

    id: str
    kind: str
    state: str
    params: dict[str, Any]
    result: dict[str, Any]
    metrics: dict[str, float]
    checks: list[dict[str, Any]]

    @property
    def arrays(self) -> Mapping[str, str]:
        """The stored arrays' names (→ where each is stored); test membership here."""

    def array(self, name: str) -> np.ndarray:
        """Load one of the plan's stored arrays."""
