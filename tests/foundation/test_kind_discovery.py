"""A plan kind is a module assigning ``KIND`` at top level: found, not listed."""

from __future__ import annotations

import importlib
import pkgutil
import sys
from pathlib import Path

import pytest

import server.kinds
from server.kinds import KIND_MODULES, discover_kind_modules
from server.scene.drawers import DrawerSpec, discover_drawers


def test_discovered_modules_are_exactly_those_that_define_kind() -> None:
    # Independent of the source scan: import every module of the package.
    defining = []
    for info in pkgutil.iter_modules(server.kinds.__path__):
        module = importlib.import_module(f"server.kinds.{info.name}")
        if hasattr(module, "KIND"):
            defining.append(module.__name__)
    assert sorted(KIND_MODULES) == sorted(defining)
    assert len(KIND_MODULES) == 8


def test_the_source_scan_takes_top_level_assignments_only(tmp_path: Path) -> None:
    files = {
        "alpha.py": "KIND = PlanKind(name='a')\n",
        "beta.py": "from x import PlanKind\n\nKIND: PlanKind = PlanKind(name='b')\n",
        "helpers.py": "def f():\n    KIND = 1\n    return KIND\n",
        "mentions.py": "# KIND = nothing here\nKINDS = []\n",
        "_private.py": "KIND = PlanKind(name='p')\n",
    }
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    assert discover_kind_modules(tmp_path, "site") == ["site.alpha", "site.beta"]


def test_drawers_are_read_from_their_modules_without_importing_them(tmp_path: Path) -> None:
    (tmp_path / "one.py").write_text(
        "import not_installed_anywhere\n\nDRAWS = {'k.a': ('draw', 'ara'), 'k.b': ('draw_b', None)}\n"
    )
    (tmp_path / "two.py").write_text("DRAWS: dict = {'k.c': ('paint', 'cmbot')}\n")
    (tmp_path / "three.py").write_text("def f():\n    DRAWS = {'k.x': ('f', None)}\n")
    found = discover_drawers(tmp_path, "site")
    assert found == {
        "k.a": DrawerSpec("site.one:draw", "ara"),
        "k.b": DrawerSpec("site.one:draw_b", None),
        "k.c": DrawerSpec("site.two:paint", "cmbot"),
    }
    assert "site.one" not in sys.modules  # read, not imported
    (tmp_path / "four.py").write_text("DRAWS = {'k.a': ('again', None)}\n")
    with pytest.raises(ValueError, match="two drawers"):
        discover_drawers(tmp_path, "site")
