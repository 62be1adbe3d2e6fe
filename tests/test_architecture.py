"""The package's layers: what each sub-package of ``mocapedit`` may import.

Read from the sources (every import, those inside functions included), so a new import
that crosses a layer fails here before it tangles the code. The rules are the ones each
sub-package's ``__init__`` states, and the README's Architecture section.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "python" / "mocapedit"

# sub-package -> (mocapedit sub-packages it may import, may import pxr, may import _solver)
LAYERS = {
    "model": (set(), False, False),
    "formats": ({"model", "geometry"}, False, False),
    "geometry": ({"model"}, False, True),
    "solve": ({"model", "geometry"}, False, True),
    "inspect": ({"model", "geometry", "solve"}, False, False),
    "usd": ({"model", "geometry", "formats"}, True, False),
    "pipeline": ({"model", "geometry", "solve", "inspect", "usd"}, False, False),
    "tools": ({"model", "geometry", "solve", "inspect", "usd", "formats", "pipeline"}, True, False),
    "cli": ({"model", "geometry", "solve", "inspect", "usd", "formats", "pipeline", "tools"}, False, False),
    "data": ({"model", "geometry", "solve", "usd", "formats"}, True, False),
}
TOP_LEVEL = {"__init__.py"}   # the only modules directly in mocapedit/ (besides the built _solver)


def _modules():
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE)
        yield rel, path


def _from_module(node: ast.ImportFrom, package: list[str]) -> str:
    """The absolute module of a ``from ... import``, relative ones resolved against ``package``."""
    if node.level:
        base = package[:len(package) - (node.level - 1)]
        return ".".join(base + ([node.module] if node.module else []))
    return node.module or ""


def _imports(path: Path) -> list[tuple[int, str]]:
    """(line, absolute dotted name) of every import in a module, relative ones resolved."""
    package = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)[:-1]
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            module = _from_module(node, package)
            names = [f"{module}.{a.name}" for a in node.names]
            # `from mocapedit import x` names a sub-package; `from pxr import Usd` names pxr.
            out += [(node.lineno, n) for n in names] if module in ("mocapedit", "") else [(node.lineno, module)]
    return out


def _violations() -> list[str]:
    found = []
    for rel, path in _modules():
        if len(rel.parts) == 1:
            if rel.name not in TOP_LEVEL:
                found.append(f"{rel}: a module directly in mocapedit/; put it in a sub-package")
            continue
        layer = rel.parts[0]
        if layer not in LAYERS:
            found.append(f"{rel}: sub-package {layer!r} has no rule in LAYERS")
            continue
        may, pxr, solver = LAYERS[layer]
        for line, name in _imports(path):
            head = name.split(".")
            if head[0] == "pxr" and not pxr:
                found.append(f"{rel}:{line}: imports pxr ({layer}/ may not)")
            elif head[0] == "mocapedit" and len(head) > 1:
                sub = head[1]
                if sub == "_solver":
                    if not solver:
                        found.append(f"{rel}:{line}: imports _solver ({layer}/ may not)")
                elif sub in LAYERS and sub != layer and sub not in may:
                    found.append(f"{rel}:{line}: imports mocapedit.{sub} ({layer}/ may import "
                                 f"{', '.join(sorted(may)) or 'no other sub-package'})")
    return found


def test_every_sub_package_keeps_to_its_layer():
    found = sorted(set(_violations()))
    assert found == []


def test_every_sub_package_says_what_it_holds_and_may_import():
    for layer in LAYERS:
        doc = ast.get_docstring(ast.parse((PACKAGE / layer / "__init__.py").read_text()))
        assert doc and "May import" in doc, f"{layer}/__init__.py: say what lives there and what it may import"


def test_the_rules_catch_a_crossing(tmp_path, monkeypatch):
    fake = tmp_path / "mocapedit"
    for layer in LAYERS:
        (fake / layer).mkdir(parents=True)
        (fake / layer / "__init__.py").write_text('"""x\n\nMay import: nothing."""\n')
    (fake / "__init__.py").write_text("")
    (fake / "model" / "bad.py").write_text("from pxr import Usd\nfrom ..solve import path_edit\n")
    (fake / "solve" / "ok.py").write_text("from .. import _solver\nfrom ..geometry import ground\n")
    (fake / "loose.py").write_text("")
    monkeypatch.setattr(__import__(__name__), "PACKAGE", fake)
    found = _violations()
    assert any("model/bad.py:1: imports pxr" in f for f in found)
    assert any("model/bad.py:2: imports mocapedit.solve" in f for f in found)
    assert any("loose.py" in f for f in found)
    assert not any("solve/ok.py" in f for f in found)


def _private_uses(path: Path) -> list[str]:
    """``from x import _name`` and ``x._name`` where ``x`` is another mocapedit module (the
    compiled ``_solver`` and dunder names excepted)."""
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = list(rel.parts)
    package = parts[:-1]
    this = ".".join(parts if parts[-1] != "__init__" else parts[:-1])
    tree = ast.parse(path.read_text(), str(path))
    modules: dict[str, str] = {}   # local name -> mocapedit module it is bound to
    found = []

    def private(name: str) -> bool:
        return name.startswith("_") and not name.startswith("__") and name != "_solver"

    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            module = _from_module(node, package)
            if not module.startswith("mocapedit"):
                continue
            for a in node.names:
                if private(a.name) and module != this:
                    found.append(f"{path.relative_to(PACKAGE)}:{node.lineno}: imports {module}.{a.name}")
                modules[a.asname or a.name] = f"{module}.{a.name}"
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("mocapedit") and a.asname:
                    modules[a.asname] = a.name
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) \
                and node.value.id in modules and private(node.attr) and modules[node.value.id] != this:
            found.append(f"{path.relative_to(PACKAGE)}:{node.lineno}: uses {modules[node.value.id]}.{node.attr}")
    return found


def test_no_module_uses_another_modules_private_names():
    found = [f for _, path in _modules() for f in _private_uses(path)]
    assert found == []


def test_the_private_check_catches_a_private_use(tmp_path, monkeypatch):
    fake = tmp_path / "mocapedit"
    (fake / "usd").mkdir(parents=True)
    (fake / "tools").mkdir()
    (fake / "usd" / "writer.py").write_text("def _over(): pass\nx = _over()\n")
    (fake / "tools" / "bad.py").write_text("from mocapedit.usd import writer\nfrom mocapedit.usd.writer import _over\n"
                                           "writer._over()\n")
    (fake / "tools" / "ok.py").write_text("from mocapedit import _solver, __version__\n_solver.solve()\n")
    monkeypatch.setattr(__import__(__name__), "PACKAGE", fake)
    bad = _private_uses(fake / "tools" / "bad.py")
    assert any("bad.py:2: imports mocapedit.usd.writer._over" in f for f in bad)
    assert any("bad.py:3: uses mocapedit.usd.writer._over" in f for f in bad)
    assert _private_uses(fake / "tools" / "ok.py") == []
    assert _private_uses(fake / "usd" / "writer.py") == []
