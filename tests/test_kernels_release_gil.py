"""Every compiled kernel releases the GIL (``@njit(..., nogil=True)``).

With ``--workers N`` the calling process computes chunks beside its Dask worker processes
and also hosts their scheduler and client threads. A kernel that holds the GIL for half a
second there keeps a worker that finished its chunk waiting that long for the next one
(measured with kernels of 0.5 s on eight 6 s items: 30.7 s against 25.5 s with the GIL
released). Checked on the source with the AST.
"""

from __future__ import annotations

import ast
from pathlib import Path

import lidarqa

PACKAGE_DIR = Path(lidarqa.__file__).parent
JIT_NAMES = {"njit", "jit"}


def _holding_kernels(source: str, name: str) -> tuple[list[str], int]:
    """(kernels decorated with njit/jit without nogil=True, number of kernels) in `source`."""
    bad, n = [], 0
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.FunctionDef):
            continue
        for dec in node.decorator_list:
            call = dec if isinstance(dec, ast.Call) else None
            func = call.func if call is not None else dec
            fname = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", None)
            if fname not in JIT_NAMES:
                continue
            n += 1
            keywords = {k.arg: k.value for k in call.keywords} if call is not None else {}
            nogil = keywords.get("nogil")
            if not (isinstance(nogil, ast.Constant) and nogil.value is True):
                bad.append(f"{name}:{node.lineno} {node.name}")
    return bad, n


def test_the_checker_finds_a_kernel_that_holds_the_gil():
    source = (
        "from numba import njit\nimport numba\n"
        "@njit(cache=True)\ndef a(x): return x\n"
        "@numba.njit\ndef b(x): return x\n"
        "@njit(cache=True, nogil=True)\ndef c(x): return x\n"
    )
    bad, n = _holding_kernels(source, "m.py")
    assert n == 3
    assert [b.split()[-1] for b in bad] == ["a", "b"]


def test_every_kernel_releases_the_gil():
    bad, n = [], 0
    for path in sorted(PACKAGE_DIR.rglob("*.py")):
        name = str(path.relative_to(PACKAGE_DIR))
        b, k = _holding_kernels(path.read_text(encoding="utf-8"), name)
        bad += b
        n += k
    assert n >= 40  # the package's kernels were found
    assert not bad, "kernels holding the GIL: " + ", ".join(bad)
