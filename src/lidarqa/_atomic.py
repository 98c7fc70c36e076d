"""The one output-writing path: every file lidarqa writes goes through :func:`atomic_output`.

What it guarantees, for every format (LAS/LAZ, CSV, GeoPackage, GeoJSON, JSON, HTML,
GeoTIFF, PLY, ...):

- the output folder is checked first (exists, is a folder, is writable) and a
  clear :class:`~lidarqa.errors.WriteError` names the problem;
- data is written to a hidden temporary file *beside* the target and renamed
  onto it only when complete, so a reader never sees a half-written file;
- the finished file gets the permissions of an ordinary new file (``0666``
  minus the umask), not the ``0600`` of a private temporary file;
- on any exception, ``KeyboardInterrupt`` (SIGINT) or SIGTERM/SIGHUP (once
  :func:`install_signal_handlers` ran, which the command line does) the
  temporary file and any side files a driver made next to it are removed.

The command line also runs each command inside :func:`output_session`: outputs
*created* by a command that then fails or is interrupted are removed as well, so
an interrupted command leaves nothing at or beside its output paths.
"""

from __future__ import annotations

import contextlib
import errno
import os
import signal
import tempfile
import threading
from collections.abc import Iterable, Iterator
from pathlib import Path

from .errors import OutputExistsError, ReadError, WriteError

__all__ = [
    "atomic_output",
    "atomic_path",
    "check_input",
    "check_output",
    "check_distinct",
    "check_output_dir",
    "check_output_folder",
    "file_mode",
    "install_signal_handlers",
    "output_session",
    "note_created",
    "register_temp",
    "unregister_temp",
    "Terminated",
]


class Terminated(BaseException):  # noqa: N818 - mirrors KeyboardInterrupt
    """Raised in the main thread when the process receives SIGTERM or SIGHUP.

    Derives from ``BaseException`` (like ``KeyboardInterrupt``) so ``except
    Exception`` blocks do not swallow it and cleanup code runs.
    """

    def __init__(self, signum: int) -> None:
        super().__init__(f"terminated by signal {signum}")
        self.signum = signum


# ----------------------------------------------------------------- temp registry
# Paths (files or folders) that must disappear if the process is stopped: the
# signal handler removes them before raising, so even a signal that arrives while
# an ``except`` block is already cleaning up leaves nothing behind.
_lock = threading.RLock()
_temps: dict[str, bool] = {}  # path -> is a glob prefix ("remove path*")
_session: list[list[Path]] = []  # stack of lists of outputs created in the session


def register_temp(path: str | os.PathLike, *, prefix: bool = False) -> None:
    """Remember a temporary file or folder to remove if the process is stopped.

    With ``prefix=True`` every file in the same folder whose name starts with the
    name of `path` is removed too (drivers such as SQLite make side files).
    """
    with _lock:
        _temps[str(path)] = prefix


def unregister_temp(path: str | os.PathLike) -> None:
    with _lock:
        _temps.pop(str(path), None)


def _remove(path: str, prefix: bool) -> None:
    import shutil

    p = Path(path)
    targets = [p]
    if prefix:
        with contextlib.suppress(OSError):
            targets += [q for q in p.parent.iterdir() if q.name.startswith(p.name)]
    for q in targets:
        with contextlib.suppress(OSError):
            if q.is_dir() and not q.is_symlink():
                shutil.rmtree(q, ignore_errors=True)
            else:
                q.unlink()


def cleanup_temps() -> None:
    """Remove every registered temporary path (idempotent)."""
    with _lock:
        items = list(_temps.items())
        _temps.clear()
    for path, prefix in items:
        _remove(path, prefix)


@contextlib.contextmanager
def output_session() -> Iterator[list[Path]]:
    """Track outputs created inside the block; remove them if the block fails.

    Files that existed before (replaced with ``--overwrite``) are not removed:
    their old content is gone either way, and a complete new file is better
    than none.
    """
    created: list[Path] = []
    with _lock:
        _session.append(created)
    try:
        yield created
    except BaseException as exc:
        # A deliberate exit status, or an error raised *about* complete outputs (a failed
        # target, a failed analysis shown in the report), keeps them.
        deliberate = isinstance(exc, SystemExit) or type(exc).__name__ == "Exit"  # click's
        if deliberate or getattr(exc, "keep_outputs", False):
            _forget_created_on_success(created)
            raise
        for p in reversed(created):
            _remove(str(p), False)
        cleanup_temps()
        raise
    else:
        _forget_created_on_success(created)
    finally:
        with _lock:
            if _session and _session[-1] is created:
                _session.pop()


def _record_created(path: Path) -> None:
    with _lock:
        if _session:
            _session[-1].append(path)
            # the signal handler may fire before the session's except block runs
            register_temp(path)


def _forget_created_on_success(created: list[Path]) -> None:
    for p in created:
        unregister_temp(p)


_installed = False
_exit_now = False


def note_created(path: str | os.PathLike) -> None:
    """Record an output (file or folder) this process created outside :func:`atomic_output`.

    Inside an :func:`output_session` it is removed if the session fails or the
    process is stopped by a signal (a folder with everything in it).
    """
    _record_created(Path(path))


def _handler(signum: int, frame: object) -> None:
    # Ignore repeats while we clean up, remove temporaries (and outputs created by the
    # failing command) now, then unwind or exit.
    for sig in _SIGNALS:
        with contextlib.suppress(ValueError, OSError):
            signal.signal(sig, signal.SIG_IGN)
    cleanup_temps()
    if _exit_now:
        # A command-line process exits at once: raising an exception here could land in
        # native code (a compiler or driver callback) that cannot unwind it.
        what = "Interrupted" if signum == signal.SIGINT else f"Terminated (signal {signum})"
        with contextlib.suppress(OSError):
            os.write(2, f"{what}; no partial output was left behind.\n".encode())
        os._exit(128 + signum)
    if signum == signal.SIGINT:
        raise KeyboardInterrupt
    raise Terminated(signum)


_SIGNALS = tuple(
    getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name)
)


def install_signal_handlers(*, exit_immediately: bool = False) -> bool:
    """Make SIGINT, SIGTERM and SIGHUP remove temporary and unfinished outputs.

    The handler removes every registered temporary file and the outputs created
    by the running command, then raises ``KeyboardInterrupt`` / :class:`Terminated`
    or, with `exit_immediately` (the ``lidarqa`` process itself), exits with
    status 128 + signal number. Only possible from the main thread; returns
    whether the handlers are installed. Signals ignored by the parent (``nohup``)
    stay ignored.
    """
    global _installed, _exit_now
    if threading.current_thread() is not threading.main_thread():
        return False
    _exit_now = exit_immediately
    for sig in _SIGNALS:
        with contextlib.suppress(ValueError, OSError):
            if signal.getsignal(sig) is signal.SIG_IGN and sig != signal.SIGINT:
                continue
            signal.signal(sig, _handler)
    _installed = True
    return True


@contextlib.contextmanager
def _signals_blocked() -> Iterator[None]:
    """Delay SIGINT/SIGTERM/SIGHUP while a temporary file is created and registered."""
    mask = getattr(signal, "pthread_sigmask", None)
    if mask is None or threading.current_thread() is not threading.main_thread():
        yield
        return
    old = mask(signal.SIG_BLOCK, _SIGNALS)
    try:
        yield
    finally:
        mask(signal.SIG_SETMASK, old)


# ----------------------------------------------------------------- checks


def file_mode() -> int:
    """Permission bits of an ordinary new file: ``0o666`` minus the process umask."""
    umask = None
    with contextlib.suppress(OSError, ValueError):
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                umask = int(line.split()[1], 8)
                break
    if umask is None:
        with _lock:
            umask = os.umask(0o022)
            os.umask(umask)
    return 0o666 & ~umask


def check_input(path: str | os.PathLike, *, error: type[ReadError] = ReadError) -> Path:
    """Return `path` as a Path after checking it is an existing, readable, non-empty file.

    Raises `error` (a :class:`ReadError` subclass) naming the problem: missing,
    a directory, a FIFO/device rather than a regular file, a symlink loop, not
    readable, or 0 bytes.
    """
    import stat

    p = Path(path)
    try:
        st = p.stat()
    except FileNotFoundError:
        raise error(f"input {p} does not exist") from None
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise error(f"input {p} is a symbolic link loop") from None
        raise error(f"input {p} cannot be accessed: {exc.strerror or exc}") from None
    except ValueError as exc:  # embedded NUL byte and the like
        raise error(f"input {path!r} is not a valid path: {exc}") from None
    if stat.S_ISDIR(st.st_mode):
        raise error(f"input {p} is a directory, not a file")
    if not stat.S_ISREG(st.st_mode):
        raise error(f"input {p} is not a regular file (a FIFO, socket or device?)")
    if st.st_size == 0:
        raise error(f"input {p} is empty (0 bytes)")
    if not os.access(p, os.R_OK):
        raise error(f"input {p} is not readable (permission denied)")
    return p


def check_output_dir(folder: Path, *, what: str = "output") -> None:
    """Check that `folder` exists, is a folder and can be written; WriteError otherwise."""
    try:
        exists = folder.exists()
    except OSError as exc:
        raise WriteError(f"{what} folder {folder} cannot be accessed: {exc.strerror}") from None
    if not exists:
        # name the first missing ancestor or the file standing in the way
        for anc in [folder, *folder.parents]:
            if anc.exists() or anc.is_symlink():
                if not anc.is_dir():
                    raise WriteError(f"{what} folder {folder}: {anc} is a file, not a folder")
                break
        raise WriteError(f"{what} folder {folder} does not exist")
    if not folder.is_dir():
        raise WriteError(f"{what} folder {folder} is a file, not a folder")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise WriteError(f"{what} folder {folder} is not writable (permission denied)")


def check_output_folder(out: str | os.PathLike, names: Iterable[str], *,
                        overwrite: bool = False) -> Path:
    """Refuse an output folder that holds a previous run's `names` (unless `overwrite`).

    The folder may not exist yet (it is created later): its nearest existing ancestor
    must be a writable folder. :class:`WriteError` for an empty name or a file in the
    way, :class:`OutputExistsError` for an earlier run's output.
    """
    if str(out).strip() == "":
        raise WriteError("the output folder name is empty")
    d = Path(out)
    if d.exists() and not d.is_dir():
        raise WriteError(f"output {d} exists and is not a folder")
    anc = d
    while not anc.exists() and anc != anc.parent:
        anc = anc.parent
    check_output_dir(anc if anc.exists() else Path("."))
    for name in () if overwrite else names:
        if (d / name).exists():
            raise OutputExistsError(f"output {d / name} exists; pass --overwrite "
                                    "(overwrite=True) to replace it")
    return d


# Cloud Optimized Point Cloud: laspy (the LAS library) reads it but cannot write it.
COPC_SUFFIX = ".copc.laz"


def check_output(path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Return `path` as a Path after checking it can be written.

    Raises :class:`OutputExistsError` if it exists and `overwrite` is false, and
    :class:`WriteError` if it is a directory or special file, or its folder is
    missing, a file, or not writable, or it names a COPC file (``*.copc.laz``),
    which lidarqa cannot write.
    """
    try:
        p = Path(path)
        if str(path) == "" or p.name in ("", ".", ".."):
            raise WriteError(f"output {str(path)!r} is not a file name")
        is_dir = p.is_dir()
        exists = p.exists() or p.is_symlink()
    except ValueError as exc:
        raise WriteError(f"output {path!r} is not a valid path: {exc}") from None
    except OSError as exc:
        raise WriteError(f"output {path} cannot be accessed: {exc.strerror or exc}") from None
    if is_dir:
        raise WriteError(f"output {p} is a directory")
    if p.name.lower().endswith(COPC_SUFFIX):
        raise WriteError(
            f"output {p}: lidarqa cannot write COPC (laspy only reads it); write a plain "
            f"{p.name[: -len(COPC_SUFFIX)]}.laz and convert it with e.g. "
            "'pdal translate IN.laz OUT.copc.laz' or untwine"
        )
    check_output_dir(p.parent if str(p.parent) else Path("."))
    if exists and not overwrite:
        raise OutputExistsError(
            f"output {p} exists; pass --overwrite (overwrite=True) to replace it"
        )
    if exists and not p.is_file():
        raise WriteError(f"output {p} exists and is not a regular file; not replaced")
    if len(p.name.encode()) > 200:
        raise WriteError(f"output file name {p.name[:40]}... is too long")
    return p


def check_distinct(output: str | os.PathLike, *inputs: str | os.PathLike) -> None:
    """Refuse an output path that names one of the inputs: inputs are never modified."""
    out = Path(output)
    for inp in inputs:
        i = Path(inp)
        same = False
        with contextlib.suppress(OSError, ValueError, RuntimeError):
            same = i.resolve() == out.resolve()
            if not same and i.exists() and out.exists():
                same = os.path.samefile(i, out)
        if same:
            raise WriteError(f"output {output} is also an input; lidarqa never modifies its inputs")


def _write_error(target: Path, exc: OSError) -> WriteError:
    if exc.errno == errno.ENOSPC:
        return WriteError(f"cannot write {target}: no space left on the device")
    if exc.errno == errno.EDQUOT:
        return WriteError(f"cannot write {target}: disk quota exceeded")
    if exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        return WriteError(f"cannot write {target}: permission denied or read-only file system")
    return WriteError(f"cannot write {target}: {exc.strerror or exc}")


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike, *, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary path next to `path`; rename it onto `path` on success.

    The one way lidarqa writes a file. Write the whole output to the yielded
    path (any writer: a stream, GDAL/OGR, rasterio, ...); when the block ends
    without an exception the file gets ordinary permissions (``0666`` minus the
    umask) and is renamed onto `path` in one step. On any exception,
    ``KeyboardInterrupt`` or a handled SIGTERM, the temporary file and files
    beside it whose names start with its name (driver side files) are removed
    and `path` is left as it was. ``OSError`` inside the block (disk full,
    permission denied) becomes :class:`WriteError`.

    The yielded name ends in ``.part``; drivers that choose the format from the
    extension may write ``tmp.with_suffix(".tif")`` and the like instead and
    rename it onto the yielded path, or simply write there: any file that starts
    with the temporary name is cleaned up.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> with atomic_output(d / "out.txt") as tmp:
    ...     _ = tmp.write_text("hello")
    >>> (d / "out.txt").read_text()
    'hello'
    """
    target = check_output(path, overwrite=overwrite)
    existed = target.exists()
    with _signals_blocked():
        try:
            fd, tmp_name = tempfile.mkstemp(
                prefix=f".{target.name}.", suffix=".part", dir=target.parent
            )
        except OSError as exc:
            raise _write_error(target, exc) from None
        os.close(fd)
        tmp = Path(tmp_name)
        stem = tmp.with_suffix("")  # ".out.laz.abc123": side files start with it
        register_temp(stem, prefix=True)
    try:
        try:
            yield tmp
        except OSError as exc:
            if isinstance(exc, WriteError | ReadError):
                raise
            raise _write_error(target, exc) from exc
        # Re-check: another process may have created the file meanwhile.
        if not existed and (target.exists() or target.is_symlink()) and not overwrite:
            raise OutputExistsError(f"output {target} appeared while writing; not replaced")
        try:
            os.chmod(tmp, file_mode())
            with _signals_blocked():
                os.replace(tmp, target)
                if not existed:
                    _record_created(target)
        except OSError as exc:
            raise _write_error(target, exc) from exc
    except BaseException:
        _remove(str(stem), True)
        raise
    finally:
        unregister_temp(stem)


# Historical name, kept for callers written before atomic_output.
atomic_path = atomic_output
