"""Which libraries importing a module loads, measured in a fresh interpreter."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def loaded_by(module: str, candidates: Sequence[str]) -> list[str]:
    """The ``candidates`` that are in ``sys.modules`` after ``import module``
    in a new Python process (this one has imported everything already)."""
    code = (
        f"import sys, {module}\n"
        f"print(' '.join(m for m in {tuple(candidates)!r} if m in sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr
    return out.stdout.split()
