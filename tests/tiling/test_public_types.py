"""The public signatures of ``lidarqa.tiling`` name their types (issue #29): no ``Any``.

Parameters and return annotations of public functions and methods, and the annotated
fields of public classes, are read from the source with :mod:`ast` (annotations are
strings under ``from __future__ import annotations``, so nothing is imported).
"""

from __future__ import annotations

import ast
from pathlib import Path

import lidarqa.tiling

TILING = Path(lidarqa.tiling.__file__).parent

PENDING: set[str] = set()  # modules whose public signatures are still being typed


def _public(name: str) -> bool:
    return not name.startswith("_") or (name.startswith("__") and name.endswith("__"))


def _uses_any(node: ast.expr | None) -> bool:
    if node is None:
        return False
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        node = ast.parse(node.value, mode="eval").body
    return any(isinstance(n, ast.Name) and n.id == "Any"
               or isinstance(n, ast.Attribute) and n.attr == "Any" for n in ast.walk(node))


def _any_in(tree: ast.AST, prefix: str = "") -> list[str]:
    found: list[str] = []
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and _public(node.name):
            a = node.args
            params = [*a.posonlyargs, *a.args, *a.kwonlyargs, a.vararg, a.kwarg]
            if any(_uses_any(p.annotation) for p in params if p is not None) \
                    or _uses_any(node.returns):
                found.append(prefix + node.name)
        elif isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
            found += [f"{prefix}{node.name}.{ast.unparse(st.target)}" for st in node.body
                      if isinstance(st, ast.AnnAssign) and _uses_any(st.annotation)]
            found += _any_in(node, f"{prefix}{node.name}.")
        elif isinstance(node, ast.If):  # if TYPE_CHECKING: blocks
            found += _any_in(node, prefix)
    return found


def test_the_check_sees_any():
    src = ("from typing import Any\n"
           "def f(x: Any) -> int: ...\n"
           "def g(x: int) -> 'list[Any]': ...\n"
           "def _h(x: Any) -> Any: ...\n"
           "class C:\n    y: Any\n    def m(self, *a: int, **k: Any) -> None: ...\n"
           "class D:\n    z: int\n    def n(self) -> dict[str, object]: ...\n")
    assert _any_in(ast.parse(src)) == ["f", "g", "C.y", "C.m"]


def test_no_any_in_public_tiling_signatures():
    files = sorted(p for p in TILING.glob("*.py") if p.name not in PENDING)
    assert len(files) >= 10
    found = {p.name: names for p in files
             if (names := _any_in(ast.parse(p.read_text(encoding="utf-8"))))}
    assert found == {}


def test_pending_modules_still_exist():
    # a module renamed or removed by #26 must leave this list (else it hides nothing)
    assert PENDING <= {p.name for p in TILING.glob("*.py")}
