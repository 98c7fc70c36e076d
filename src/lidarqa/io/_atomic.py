"""Atomic output files: write to a temporary file beside the target, then rename."""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

from ..errors import OutputExistsError, ReadError, WriteError

__all__ = ["atomic_path", "check_input", "check_output", "check_distinct"]


def check_input(path: str | os.PathLike, *, error: type[ReadError] = ReadError) -> Path:
    """Return `path` as a Path after checking it is an existing, non-empty file.

    Raises `error` (a :class:`ReadError` subclass) naming the problem: missing,
    a directory, or 0 bytes.
    """
    p = Path(path)
    if not p.exists():
        raise error(f"input {p} does not exist")
    if p.is_dir():
        raise error(f"input {p} is a directory, not a file")
    if p.stat().st_size == 0:
        raise error(f"input {p} is empty (0 bytes)")
    return p


def check_output(path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Return `path` as a Path after checking it can be written.

    Raises :class:`OutputExistsError` if it exists and `overwrite` is false, and
    :class:`WriteError` if it is a directory or its folder does not exist.
    """
    p = Path(path)
    if p.is_dir():
        raise WriteError(f"output {p} is a directory")
    if p.exists() and not overwrite:
        raise OutputExistsError(
            f"output {p} exists; pass --overwrite (overwrite=True) to replace it"
        )
    if not p.parent.exists():
        raise WriteError(f"output folder {p.parent} does not exist")
    return p


def check_distinct(output: str | os.PathLike, *inputs: str | os.PathLike) -> None:
    """Refuse an output path that names one of the inputs: inputs are never modified."""
    out = Path(output).resolve()
    for inp in inputs:
        if Path(inp).resolve() == out:
            raise WriteError(f"output {output} is also an input; lidarqa never modifies its inputs")


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary path next to `path`; rename it onto `path` on success.

    On any exception (including ``KeyboardInterrupt``) the temporary file is
    removed and `path` is left as it was.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> with atomic_path(d / "out.txt") as tmp:
    ...     _ = tmp.write_text("hello")
    >>> (d / "out.txt").read_text()
    'hello'
    """
    target = check_output(path, overwrite=overwrite)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".part", dir=target.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        # Re-check: another process may have created the file meanwhile.
        if target.exists() and not overwrite:
            raise OutputExistsError(f"output {target} appeared while writing; not replaced")
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
