"""The import rules between layers (DESIGN §2–§3) and the planners'
error contract (DESIGN §5), checked on the source with :mod:`ast`.

Every import statement counts — at module level, inside functions and under
``if TYPE_CHECKING:`` — because a lazy import is still a dependency: it only
moves the cycle from import time to call time.  ``importlib.import_module``
calls with a literal module name count too.
"""

from __future__ import annotations

import ast
import builtins
import inspect
from collections.abc import Iterator
from pathlib import Path

import pytest

import planners.errors

ROOT = Path(__file__).resolve().parents[2]


def _module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _resolve(node: ast.ImportFrom, module: str, is_package: bool) -> str:
    """The absolute module an ``ImportFrom`` names (relative imports resolved)."""
    if node.level == 0:
        return node.module or ""
    base = module.split(".") if is_package else module.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join([*base, node.module] if node.module else base)


def imports_of(path: Path, module: str | None = None) -> Iterator[tuple[int, str]]:
    """(line, absolute module) for every import in ``path``.

    ``from a import b`` yields both ``a`` and ``a.b`` so that importing a
    submodule by name (``from server import kinds``) is caught as well.
    """
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    module = module or _module_name(path)
    is_package = path.name == "__init__.py"
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            base = _resolve(node, module, is_package)
            yield node.lineno, base
            for alias in node.names:
                yield node.lineno, f"{base}.{alias.name}" if base else alias.name
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute | ast.Name)
            and (node.func.attr if isinstance(node.func, ast.Attribute) else node.func.id)
            == "import_module"
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)
        ):
            yield node.lineno, node.args[0].value


def _within(module: str, banned: str) -> bool:
    return module == banned or module.startswith(banned + ".")


def violations(folder: str, banned: list[str]) -> list[str]:
    out = []
    for path in sorted((ROOT / folder).rglob("*.py")):
        for line, module in imports_of(path):
            for b in banned:
                if _within(module, b):
                    out.append(f"{path.relative_to(ROOT)}:{line} imports {module}")
    return sorted(set(out))


RULES = {
    # planners are pure: robot models arrive as arguments; no service, no hardware.
    "planners": ["server", "robots.adapters", "robots.emulator", "robots.protocol"],
    # robot descriptions sit below the planners that use them.
    "robots": ["planners", "server"],
    # the scene looks drawers up by kind name; it never needs the registry ...
    "server/scene": ["server.kinds"],
    # ... and a kind never reaches for its drawer.
    "server/kinds": ["server.scene"],
}


@pytest.mark.parametrize("folder", sorted(RULES))
def test_one_way_imports(folder: str) -> None:
    assert violations(folder, RULES[folder]) == []


def test_nothing_in_server_imports_the_app_or_cli() -> None:
    """``server.app`` / ``server.cli`` are the top: nothing below imports them."""
    out = [
        v
        for v in violations("server", ["server.app", "server.cli"])
        if not v.startswith(("server/app.py", "server/cli.py"))
    ]
    assert out == []


def test_the_checker_sees_lazy_relative_and_dynamic_imports(tmp_path: Path) -> None:
    """The walker itself: a regression here would make the rules above vacuous."""
    src = (
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n    from server.kinds import registry\n"
        "def f():\n    from ..server import scene\n"
        "    import importlib\n    importlib.import_module('robots.protocol')\n"
    )
    probe = tmp_path / "probe.py"
    probe.write_text(src, encoding="utf-8")
    found = {m for _, m in imports_of(probe, "planners.probe")}
    assert {"server.kinds", "server.scene", "robots.protocol"} <= found


# ------------------------------------------------------------------ errors
ERROR_CLASSES = {
    name
    for name, obj in vars(planners.errors).items()
    if inspect.isclass(obj)
    and issubclass(obj, BaseException)
    and obj.__module__ == "planners.errors"
}
BUILTIN_EXCEPTIONS = {
    name
    for name, obj in vars(builtins).items()
    if inspect.isclass(obj) and issubclass(obj, BaseException)
}


def _raised_name(exc: ast.expr) -> str | None:
    """The class a ``raise`` names, or None for a re-raise of a caught object."""
    target = exc.func if isinstance(exc, ast.Call) else exc
    if isinstance(target, ast.Attribute):
        return target.attr
    if isinstance(target, ast.Name):
        # ``raise exc`` re-raises what an ``except ... as exc`` caught; a bare
        # class name (``raise ValueError``) is a new exception and is checked.
        if isinstance(exc, ast.Call) or target.id in BUILTIN_EXCEPTIONS | ERROR_CLASSES:
            return target.id
        return None
    return "<expression>"


def bad_raises(folder: Path, root: Path = ROOT) -> list[str]:
    out = []
    for path in sorted(folder.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if not isinstance(node, ast.Raise) or node.exc is None:
                continue  # bare ``raise``: a re-raise
            name = _raised_name(node.exc)
            if name is not None and name not in ERROR_CLASSES:
                out.append(f"{path.relative_to(root)}:{node.lineno} raises {name}")
    return out


def test_error_classes_are_value_errors() -> None:
    assert ERROR_CLASSES and "PlannerError" in ERROR_CLASSES
    assert all(issubclass(getattr(planners.errors, n), ValueError) for n in ERROR_CLASSES)


def test_planners_raise_only_planners_errors() -> None:
    """DESIGN §5: every exception a planner raises is a ``planners.errors`` class."""
    assert bad_raises(ROOT / "planners") == []


def test_the_raise_checker_flags_builtins(tmp_path: Path) -> None:
    (tmp_path / "m.py").write_text(
        "from planners.errors import InfeasibleError\n"
        "def f(x):\n"
        "    try:\n        g()\n    except KeyError as exc:\n        raise exc\n"
        "    if x:\n        raise ValueError('bad')\n"
        "    if not x:\n        raise RuntimeError\n"
        "    raise InfeasibleError('no plan') from None\n",
        encoding="utf-8",
    )
    found = bad_raises(tmp_path, tmp_path)
    assert found == ["m.py:8 raises ValueError", "m.py:10 raises RuntimeError"]


# ------------------------------------------------------------------ drawers
def test_every_built_in_kind_has_a_drawer_and_the_same_robot() -> None:
    """The scene's kind-name table agrees with the kinds it draws (they share no import)."""
    import importlib

    from server.kinds import KIND_MODULES
    from server.scene.drawers import DRAWERS, drawer_for, robot_for

    kinds = [importlib.import_module(m).KIND for m in KIND_MODULES]
    assert sorted(DRAWERS) == sorted(k.name for k in kinds)
    for kind in kinds:
        assert robot_for(kind.name) == kind.robot, kind.name
        assert callable(drawer_for(kind.name)), kind.name
    assert drawer_for("no.such.kind") is None and robot_for("no.such.kind") is None


def test_a_site_kind_registers_its_own_drawer() -> None:
    from server.scene import drawers

    def draw(ctx: object, plan: object) -> None:
        pass

    with pytest.raises(ValueError, match="built-in drawer"):
        drawers.register_drawer("blast", draw)
    drawers.register_drawer("site.kind", draw, robot="ara")
    try:
        assert drawers.drawer_for("site.kind") is draw
        assert drawers.robot_for("site.kind") == "ara"
        assert "site.kind" in drawers.drawable_kinds()
    finally:
        drawers._registered.pop("site.kind")


# ------------------------------------------------------------------ kinds are declarations
#: What a kind module may not use: the libraries that do
#: geometry, search or point-cloud work, and numpy's linear algebra.  A kind
#: holds a params model, a short ``run`` that calls one planner entry point
#: and turns its result into the stored form, and ``compile``; a kind that
#: needs one of these holds an algorithm, which belongs in ``planners/``.
ALGORITHM_MODULES = [
    "scipy",
    "shapely",
    "sklearn",
    "networkx",
    "open3d",
    "trimesh",
    "coal",
    "pinocchio",
    "ompl",
    "planners.pointcloud",
]
ALGORITHM_ATTRIBUTES = {("np", "linalg"), ("numpy", "linalg"), ("np", "fft"), ("numpy", "fft")}


def algorithm_uses(folder: Path, root: Path = ROOT) -> list[str]:
    """``path:line what`` for every banned import or ``np.linalg``-style use."""
    out = []
    for path in sorted(folder.glob("*.py")):
        rel = path.relative_to(root)
        for line, module in imports_of(path, _module_name(path) if root == ROOT else path.stem):
            if any(_within(module, b) for b in ALGORITHM_MODULES) or module in {
                "numpy.linalg",
                "numpy.fft",
            }:
                out.append(f"{rel}:{line} imports {module}")
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Attribute)
                and isinstance(node.value, ast.Name)
                and (node.value.id, node.attr) in ALGORITHM_ATTRIBUTES
            ):
                out.append(f"{rel}:{node.lineno} uses {node.value.id}.{node.attr}")
    return sorted(set(out))


def test_kinds_are_declarations() -> None:
    """No kind module does geometry itself (plane fits, footprint sweeps, graph search)."""
    assert algorithm_uses(ROOT / "server" / "kinds") == []


def test_the_declaration_checker_flags_algorithms(tmp_path: Path) -> None:
    (tmp_path / "k.py").write_text(
        "import numpy as np\n"
        "def run(p, ctx):\n"
        "    from shapely import Polygon\n"
        "    from planners.pointcloud.ransac import detect_planes\n"
        "    return np.linalg.svd(p)\n"
        "from scipy.spatial import cKDTree\n",
        encoding="utf-8",
    )
    found = algorithm_uses(tmp_path, tmp_path)
    assert "k.py:3 imports shapely" in found
    assert "k.py:4 imports planners.pointcloud.ransac" in found
    assert "k.py:5 uses np.linalg" in found
    assert "k.py:6 imports scipy.spatial" in found
