"""Hostile inputs and the reliability property, shared by the fuzz suite (tests/fuzz).

The property every command and public entry point must keep, whatever the input:

- it returns within a time bound (no hang);
- it succeeds, or fails with one clear line and a documented non-zero exit
  status (never "Internal error", never a traceback);
- it leaves nothing half-written: no temporary file at or beside an output
  path, and no new output at all when it failed.

The generators below make the inputs: byte-level corruptions of valid LAS/LAZ
files (every public-header field set to extremes, truncation at every field,
bit flips), malformed text tables and TOML, special files (folders, FIFOs,
symlink loops, empty files).
"""

from __future__ import annotations

import contextlib
import os
import signal
import struct
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

TIME_LIMIT = 10.0  # seconds per case

# (name, offset, struct format) of the LAS 1.4 public header fields
LAS_FIELDS = [
    ("signature", 0, "4s"),
    ("file_source_id", 4, "<H"),
    ("global_encoding", 6, "<H"),
    ("version_major", 24, "<B"),
    ("version_minor", 25, "<B"),
    ("header_size", 94, "<H"),
    ("offset_to_point_data", 96, "<I"),
    ("number_of_vlrs", 100, "<I"),
    ("point_format", 104, "<B"),
    ("point_record_length", 105, "<H"),
    ("legacy_point_count", 107, "<I"),
    ("x_scale", 131, "<d"),
    ("y_scale", 139, "<d"),
    ("z_scale", 147, "<d"),
    ("x_offset", 155, "<d"),
    ("z_offset", 171, "<d"),
    ("max_x", 179, "<d"),
    ("min_x", 187, "<d"),
    ("max_z", 211, "<d"),
    ("min_z", 219, "<d"),
    ("waveform_start", 227, "<Q"),
    ("first_evlr_start", 235, "<Q"),
    ("number_of_evlrs", 243, "<I"),
    ("point_count_14", 247, "<Q"),
]


def extremes(fmt: str) -> list:
    """Values that break readers which trust a field of this struct format."""
    if fmt.endswith("d"):
        return [float("nan"), float("inf"), -float("inf"), 1e308, -1e308, 0.0, -1.0, 1e-300]
    if fmt.endswith("s"):
        return [b"LASE", b"\x00\x00\x00\x00"]
    bits = struct.calcsize(fmt) * 8
    top = 2**bits - 1
    return sorted(v for v in {0, 1, 2, top, top - 1, top // 2, 227, 375} if v <= top)


def set_field(data: bytes, offset: int, fmt: str, value) -> bytes:
    size = struct.calcsize(fmt)
    if offset + size > len(data):
        return data
    return data[:offset] + struct.pack(fmt, value) + data[offset + size :]


def flip_bits(data: bytes, positions: list[int]) -> bytes:
    b = bytearray(data)
    for pos in positions:
        b[(pos // 8) % len(b)] ^= 1 << (pos % 8)
    return bytes(b)


def text_cases() -> dict[str, bytes]:
    """Malformed text tables (point lists, segments, observations, clouds)."""
    big = b"1," * 300_000
    return {
        "nan": b"id,x,y,z\n1,nan,0,0\n2,1,1,1\n",
        "inf": b"id,x,y,z\n1,inf,0,0\n2,1,1,1\n",
        "huge-number": b"id,x,y,z\n1,1e999,0,0\n",
        "dup-column": b"id,x,x,y,z\n1,1,1,1,1\n",
        "empty-column": b"id,,x,y,z\n1,5,1,1,1\n",
        "header-only": b"id,x,y,z\n",
        "ragged": b"id,x,y,z\n1,2\n3,4,5,6,7\n",
        "latin1": b"id,x,y,z,comment\n1,1,2,3,caf\xe9\n2,2,3,4,ok\n",
        "utf16": "id,x,y,z\n1,1,2,3\n".encode("utf-16"),
        "nul": b"id,x,y,z\n1,1\x00,2,3\n",
        "huge-line": b"id,x,y,z\n" + big + b"\n",
        "huge-field": b'id,x,y,z\n1,"' + b"a" * 300_000 + b'",2,3\n',
        "text": b"hello world\n",
        "binary": bytes(range(256)) * 8,
        "dup-id": b"id,x,y,z\n1,1,2,3\n1,2,3,4\n",
        "strings": b"id,x,y,z\na,b,c,d\n",
        "one-row": b"id,x,y,z\n1,1,2,3\n",
        "huge-int-id": b"id,x,y,z\n" + b"9" * 5000 + b",1,2,3\n",
        "unquoted-quote": b'id,x,y,z\n1,"1,2,3\n',
        "semicolons": b"id;x;y;z\n1;1,5;2;3\n",
    }


_GROUND = b'[inputs.clouds]\ntile = "scene.las"\n[ground]\ncloud = "tile"\n'


def toml_cases() -> dict[str, bytes]:
    return {
        "deep": b"a = " + b"[" * 3000 + b"]" * 3000 + b"\n",
        "deep-table": b"a = " + b"{b = " * 500 + b"1" + b"}" * 500 + b"\n",
        "bigint": b"title = " + b"9" * 5000 + b"\n",
        "bigint-4000": b"title = " + b"9" * 4000 + b"\n",
        "utf16": 'title = "x"\n'.encode("utf-16"),
        "latin1": b'title = "caf\xe9"\n',
        "not-toml": b"[[[\n",
        "wrong-type": b'[inputs.clouds]\ntile = 5\n',
        "unknown-key": b'bogus = 1\n',
        "nan-target": _GROUND + b"target_total = nan\n",
        "missing-input": b'[inputs.clouds]\ntile = "nope.las"\n[info]\ncloud = "tile"\n',
        "empty": b"\n",
        "huge-string": b'title = "' + b"x" * 2_000_000 + b'"\n',
        "array-of-tables": b"[[inputs]]\na = 1\n",
        "neg-target": _GROUND + b"target_total = -1e308\n",
    }


def make_special(kind: str, where: Path, good: Path | None = None) -> Path:
    """A special path of `kind` inside folder `where` (created fresh)."""
    where.mkdir(parents=True, exist_ok=True)
    suffix = good.suffix if good is not None else ".las"
    p = where / f"{kind}{suffix}"
    if kind == "missing":
        return p
    if kind == "directory":
        p.mkdir()
    elif kind == "fifo":
        os.mkfifo(p)
    elif kind == "symlink-loop":
        os.symlink(p, p)
    elif kind == "dangling-symlink":
        os.symlink(where / "nowhere", p)
    elif kind == "empty":
        p.write_bytes(b"")
    elif kind == "one-byte":
        p.write_bytes(b"L")
    elif kind == "random":
        p.write_bytes(np.random.default_rng(0).bytes(4096))
    elif kind == "lasf-random":
        p.write_bytes(b"LASF" + np.random.default_rng(1).bytes(4096))
    elif kind == "truncated" and good is not None:
        data = good.read_bytes()
        p.write_bytes(data[: len(data) // 2])
    elif kind == "header-only" and good is not None:
        p.write_bytes(good.read_bytes()[:227])
    else:
        raise ValueError(kind)
    return p


SPECIAL_KINDS = [
    "missing",
    "directory",
    "fifo",
    "symlink-loop",
    "dangling-symlink",
    "empty",
    "one-byte",
    "random",
    "lasf-random",
    "truncated",
    "header-only",
]


class Hang(BaseException):  # noqa: N818 - not an Exception: nothing may catch it
    """A case ran past its time limit."""


@contextlib.contextmanager
def time_limit(seconds: float = TIME_LIMIT) -> Iterator[None]:
    """Raise :class:`Hang` if the block runs longer than `seconds` (main thread, POSIX)."""

    def on_alarm(signum, frame):
        raise Hang(f"no result after {seconds} s")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def listing(folder: Path) -> set[str]:
    out = set()
    for root, dirs, files in os.walk(folder):
        for name in files + dirs:
            out.add(str(Path(root, name).relative_to(folder)))
    return out


def run_cli(argv: list, *, out_dir: Path, limit: float = TIME_LIMIT):
    """Run ``lidarqa ARGV`` in-process and assert the reliability property.

    Returns the click result. `out_dir` is the folder outputs are written to;
    it is compared before and after.
    """
    from click.testing import CliRunner

    from lidarqa.cli.main import cli

    out_dir.mkdir(parents=True, exist_ok=True)
    before = listing(out_dir)
    t0 = time.perf_counter()
    cwd = os.getcwd()
    os.chdir(out_dir)  # a relative or empty output path lands here, where it is seen
    try:
        with time_limit(limit):
            r = CliRunner().invoke(cli, [str(a) for a in argv], catch_exceptions=True)
    finally:
        os.chdir(cwd)
    elapsed = time.perf_counter() - t0
    after = listing(out_dir)
    text = r.output
    context = f"argv={argv!r} exit={r.exit_code} output={text[-600:]!r}"
    assert elapsed < limit, context
    assert r.exception is None or isinstance(r.exception, SystemExit), (
        f"uncaught {r.exception!r}; {context}"
    )
    assert "Traceback" not in text and "Internal error" not in text, context
    assert r.exit_code in (0, 1, 2, 3, 4), context
    if r.exit_code == 2:
        assert "Usage:" in text, context  # 2 without usage text would be an internal error
    if r.exit_code in (1, 3):
        errors = [ln for ln in r.stderr.splitlines() if ln.startswith("Error")]
        assert len(errors) == 1, context
    new = after - before
    assert not [n for n in new if n.endswith(".part") or "/." in "/" + n], (new, context)
    if r.exit_code == 1 and "analysis(es) failed" in r.stderr:
        # assess: a failed analysis is shown in a complete report (documented)
        assert any(n.endswith("report.html") for n in new), context
    elif r.exit_code not in (0, 4):
        assert not new, f"failed run left {sorted(new)}; {context}"
    return r
