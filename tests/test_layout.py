"""The package's layout rules (issue #26), checked on the source with the AST.

- **No private cross-package import.** A module of one subpackage (``lidarqa.io``,
  ``lidarqa.ground``, ...) never imports a private module (``lidarqa.io._atomic``) or a
  private name (``from lidarqa.report.plots import _png``) of another: what several
  subpackages share is either a top-level private helper (``lidarqa._atomic``,
  ``lidarqa._validate``, ... belong to no subpackage) or a documented public name of
  its home package. Imports inside functions count too.
- **No import cycle** among module-level imports (``if TYPE_CHECKING:`` blocks excluded,
  as they never run). Importing ``a.b.c`` also runs ``a.b``'s ``__init__``, so that
  edge counts (but not the importer's own packages, which are already importing).

The checkers run on a small package written to ``tmp_path`` first, so a checker
that silently finds nothing fails too.
"""

from __future__ import annotations

import ast
import textwrap
from dataclasses import dataclass
from pathlib import Path

import lidarqa

PACKAGE_DIR = Path(lidarqa.__file__).parent


@dataclass(frozen=True)
class Import:
    """One imported target of an import statement."""

    importer: str  # module name
    line: int
    module: str  # the module the statement loads (a module of the package, or outside it)
    name: str | None  # the name taken from `module` (None: the module itself)
    deferred: bool  # inside a function
    type_checking: bool  # inside `if TYPE_CHECKING:`


def _modules(pkg_dir: Path) -> dict[str, Path]:
    root = pkg_dir.name
    out = {}
    for p in sorted(pkg_dir.rglob("*.py")):
        parts = [root, *p.relative_to(pkg_dir).with_suffix("").parts]
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _imports(pkg_dir: Path) -> tuple[dict[str, Path], list[Import]]:
    mods = _modules(pkg_dir)
    found: list[Import] = []
    for name, path in mods.items():
        is_pkg = path.name == "__init__.py"

        def walk(node: ast.AST, deferred: bool, tc: bool, name: str = name, is_pkg: bool = is_pkg):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = name.split(".") if is_pkg else name.split(".")[:-1]
                    base = base[: len(base) - (node.level - 1)]
                    target = ".".join(base + ([node.module] if node.module else []))
                else:
                    target = node.module or ""
                for alias in node.names:
                    sub = f"{target}.{alias.name}"
                    if sub in mods:  # `from pkg import submodule`
                        found.append(Import(name, node.lineno, sub, None, deferred, tc))
                    else:
                        found.append(Import(name, node.lineno, target, alias.name, deferred, tc))
                return
            if isinstance(node, ast.Import):
                for alias in node.names:
                    found.append(Import(name, node.lineno, alias.name, None, deferred, tc))
                return
            if isinstance(node, ast.If) and _is_type_checking(node.test):
                for child in node.body:
                    walk(child, deferred, True)
                for child in node.orelse:
                    walk(child, deferred, tc)
                return
            functions = (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)
            inner = deferred or isinstance(node, functions)
            for child in ast.iter_child_nodes(node):
                walk(child, inner, tc)

        walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path)), False, False)
    return mods, found


def _private(part: str) -> bool:
    return part.startswith("_") and not (part.startswith("__") and part.endswith("__"))


def _subpackage(module: str, mods: dict[str, Path]) -> str | None:
    """``lidarqa.io`` for any module under it; None for a top-level module."""
    parts = module.split(".")
    if len(parts) < 2:
        return None
    head = ".".join(parts[:2])
    return head if head in mods and mods[head].name == "__init__.py" else None


def private_cross_imports(pkg_dir: Path) -> list[str]:
    """Every import of another subpackage's private module or name, as readable lines."""
    mods, found = _imports(pkg_dir)
    root = pkg_dir.name
    bad = []
    for imp in found:
        if imp.module != root and not imp.module.startswith(root + "."):
            continue
        home = _subpackage(imp.module, mods)
        if home is None or _subpackage(imp.importer, mods) == home:
            continue
        private_module = any(_private(p) for p in imp.module.split(".")[1:])
        if private_module or (imp.name is not None and _private(imp.name)):
            what = imp.module + (f" import {imp.name}" if imp.name else "")
            bad.append(f"{imp.importer}:{imp.line} imports {what}")
    return sorted(set(bad))


def module_import_cycles(pkg_dir: Path) -> list[list[str]]:
    """The import cycles of module-level imports: strongly connected groups of modules."""
    mods, found = _imports(pkg_dir)
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for imp in found:
        if imp.deferred or imp.type_checking or imp.module not in mods:
            continue
        own = imp.importer.split(".")
        own_packages = {".".join(own[:i]) for i in range(1, len(own) + 1)}
        parts = imp.module.split(".")
        for i in range(1, len(parts) + 1):  # the target and the packages it loads
            target = ".".join(parts[:i])
            if target in mods and target not in own_packages:
                graph[imp.importer].add(target)
    # Tarjan's strongly connected components, iteratively
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    groups: list[list[str]] = []
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                group = []
                while True:
                    m = stack.pop()
                    on_stack.discard(m)
                    group.append(m)
                    if m == node:
                        break
                if len(group) > 1:
                    groups.append(sorted(group))
    return sorted(groups)


# ------------------------------------------------------------------------ the checkers


def _write_package(tmp_path: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        p = tmp_path / "pkg" / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(textwrap.dedent(text))
    return tmp_path / "pkg"


def test_checkers_find_planted_violations(tmp_path):
    pkg = _write_package(
        tmp_path,
        {
            "__init__.py": "",
            "_shared.py": "X = 1\n",  # top level: shared, allowed
            "a/__init__.py": "from .mod import f\n",
            "a/_impl.py": "def g():\n    return 1\n",
            "a/mod.py": """\
                from typing import TYPE_CHECKING
                from .._shared import X
                from ._impl import g
                from ..b import helper
                if TYPE_CHECKING:
                    from ..b.other import T
                def f():
                    from ..b.other import _private_name
                    from ..b import _kernels
                    return X, g, helper, _private_name, _kernels
                """,
            "b/__init__.py": "from .other import helper\n",
            "b/_kernels.py": "",
            "b/other.py": """\
                import pkg.a._impl
                from ..a import mod

                def helper():
                    return mod

                def _private_name():
                    return 0

                class T:
                    pass
                """,
            "c/__init__.py": "",
            "c/x.py": "from .y import Y\nZ = 1\n",
            "c/y.py": "Y = 2\n\ndef later():\n    from .x import Z\n    return Z\n",
        },
    )
    assert private_cross_imports(pkg) == [
        "pkg.a.mod:8 imports pkg.b.other import _private_name",
        "pkg.a.mod:9 imports pkg.b._kernels",
        "pkg.b.other:1 imports pkg.a._impl",
    ]
    # a.mod -> b (its __init__ imports b.other) -> a.mod: a module-level cycle through
    # the package a.mod's import loads; c.x <-> c.y is deferred and TYPE_CHECKING is skipped
    assert module_import_cycles(pkg) == [["pkg.a", "pkg.a.mod", "pkg.b", "pkg.b.other"]]


def test_no_private_cross_package_imports():
    mods, found = _imports(PACKAGE_DIR)
    assert len(mods) > 50 and len(found) > 500  # the scan sees the package
    bad = private_cross_imports(PACKAGE_DIR)
    assert not bad, (
        "private modules or names imported across subpackages (move a helper several "
        "subpackages share to a top-level lidarqa/_*.py module, or make it a documented "
        "public name of its package):\n  " + "\n  ".join(bad)
    )


def test_no_module_level_import_cycles():
    cycles = module_import_cycles(PACKAGE_DIR)
    assert not cycles, "module-level import cycles:\n  " + "\n  ".join(
        " <-> ".join(c) for c in cycles
    )


def _exception_classes(package_dir: Path) -> list[tuple[str, str]]:
    """(module path, class name) of every class that looks like an exception or warning."""
    found = []
    for path in sorted(package_dir.rglob("*.py")):
        rel = path.relative_to(package_dir).as_posix()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.ClassDef):
                continue
            bases = [
                b.id if isinstance(b, ast.Name) else getattr(b, "attr", "") for b in node.bases
            ]
            if any(b.endswith(("Error", "Exception", "Warning")) for b in bases):
                found.append((rel, node.name))
    return found


def test_exceptions_live_in_errors_py(tmp_path):
    # the checker finds a planted public exception outside errors.py, and lets a private one be
    (tmp_path / "errors.py").write_text("class AError(Exception):\n    pass\n")
    (tmp_path / "mod.py").write_text(
        "from errors import AError\n\nclass BError(AError):\n    pass\n\n"
        "class _Signal(Exception):\n    pass\n"
    )
    planted = [
        c for c in _exception_classes(tmp_path) if c[0] != "errors.py" and not c[1].startswith("_")
    ]
    assert planted == [("mod.py", "BError")]
    # the package: every public exception or warning class is defined in lidarqa/errors.py;
    # private control-flow signals of private modules (lidarqa._atomic.Terminated) may stay
    stray = [
        f"{mod}: {name}"
        for mod, name in _exception_classes(PACKAGE_DIR)
        if mod != "errors.py"
        and not name.startswith("_")
        and not any(part.startswith("_") and part != "__init__.py" for part in mod.split("/"))
    ]
    assert not stray, "exceptions outside errors.py: " + ", ".join(stray)
