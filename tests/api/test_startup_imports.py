"""A server start (``steelpath serve``, every server a test spawns, a restart
after a crash) imports the app: the libraries only some requests need load
with their first such request."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

#: matplotlib draws report pictures (0.3 s to import); OMPL, trimesh and viser
#: come with the planners' workers and the scene.
DEFERRED = ("matplotlib", "ompl", "trimesh", "viser")


def test_the_app_imports_without_the_libraries_few_requests_need() -> None:
    code = f"import sys, server.app\nprint(' '.join(m for m in {DEFERRED!r} if m in sys.modules))\n"
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == [], f"importing server.app imports {out.stdout.strip()}"
