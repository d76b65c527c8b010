"""Kinds are declarations: each kind's ``run`` turns its params
into planner dataclasses, calls one planner entry point and passes the
:class:`planners.result.PlanResult` through.  Checked on the source with
:mod:`ast`, so a kind that grows its own result shaping again fails here."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from server.kinds import KIND_MODULES, registry

ROOT = Path(__file__).resolve().parents[2]
#: Longest ``run`` a declaration needs: params → dataclasses, one call, pass-through.
MAX_RUN_LINES = 40


def _run_def(module: str) -> ast.FunctionDef:
    path = ROOT / (module.replace(".", "/") + ".py")
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and node.name == "run":
            return node
    raise AssertionError(f"{module} has no top-level run()")


def _calls(fn: ast.FunctionDef) -> set[str]:
    out = set()
    for node in ast.walk(fn):
        if isinstance(node, ast.Call):
            f = node.func
            if isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name):
                out.add(f"{f.value.id}.{f.attr}")
            elif isinstance(f, ast.Name):
                out.add(f.id)
    return out


def test_every_built_in_kind_module_is_checked() -> None:
    assert len(KIND_MODULES) == len({k.run.__module__ for k in registry().values()}) >= 7


@pytest.mark.parametrize("module", KIND_MODULES)
def test_run_is_short_and_passes_the_planner_result_through(module: str) -> None:
    fn = _run_def(module)
    assert fn.end_lineno is not None
    n = fn.end_lineno - fn.lineno + 1
    assert n <= MAX_RUN_LINES, f"{module}.run is {n} lines (a declaration needs ≤ {MAX_RUN_LINES})"
    assert "KindOutput.from_result" in _calls(fn), (
        f"{module}.run must return KindOutput.from_result(<planner's PlanResult>)"
    )
    # it builds no checks of its own: those come from the planner
    assert not {"Check", "check_le", "check_ge"} & _calls(fn), f"{module}.run builds checks"
