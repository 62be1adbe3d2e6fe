"""The checked-in type stubs (python/mocapedit/_solver.pyi) against the built module: every
public name of one is in the other, at the top level and on each class, so the stub cannot
fall behind the bindings unnoticed (`make stubs` regenerates it)."""
from __future__ import annotations

import ast
import inspect
from pathlib import Path

import pytest

from mocapedit import _solver

STUB = Path(_solver.__file__).with_name("_solver.pyi")
if not STUB.exists():  # an editable install: the extension is built outside the package folder
    STUB = Path(__file__).resolve().parents[2] / "python" / "mocapedit" / "_solver.pyi"


def _stub() -> dict[str, set[str] | None]:
    """Top-level names of the stub; for a class, the public names of its body."""
    tree = ast.parse(STUB.read_text())
    names: dict[str, set[str] | None] = {}
    for node in tree.body:
        if isinstance(node, ast.ClassDef):
            names[node.name] = {n.name for n in node.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))
                                and not n.name.startswith("_")}
        elif isinstance(node, ast.FunctionDef):
            names[node.name] = None
    return names


def _public(names) -> set[str]:
    return {n for n in names if not n.startswith("_")}


def _module() -> dict[str, set[str] | None]:
    names: dict[str, set[str] | None] = {}
    for name in _public(dir(_solver)):
        value = getattr(_solver, name)
        if inspect.isclass(value):
            names[name] = _public(vars(value))
        elif callable(value):
            names[name] = None
    return names


def test_the_stub_names_every_public_name_of_the_module_and_no_other():
    stub, module = _stub(), _module()
    assert sorted(set(module) - set(stub)) == [], "bound but not in _solver.pyi: run `make stubs`"
    assert sorted(set(stub) - set(module)) == [], "in _solver.pyi but no longer bound: run `make stubs`"


@pytest.mark.parametrize("name", sorted(n for n, v in _module().items() if v is not None))
def test_the_stub_names_every_member_of_each_class(name):
    stub, module = _stub(), _module()
    assert sorted(module[name] ^ stub[name]) == [], f"{name}: members differ from _solver.pyi: run `make stubs`"


def test_the_stub_lists_the_exception_family():
    for name in ("SolverError", "InvalidInput", "NumericalError", "ContradictionError", "TimeWarpConflict"):
        assert issubclass(getattr(_solver, name), _solver.SolverError)
    assert issubclass(_solver.InvalidInput, ValueError) and issubclass(_solver.NumericalError, RuntimeError)
    assert issubclass(_solver.ContradictionError, _solver.InvalidInput)
    assert issubclass(_solver.TimeWarpConflict, _solver.InvalidInput)
