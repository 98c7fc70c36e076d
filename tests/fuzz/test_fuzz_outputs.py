"""Hostile output paths for every command that writes: a clear error, inputs untouched,
nothing at or beside the output, and ordinary permissions on success."""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

import pytest
from hostile import listing, run_cli

pytestmark = pytest.mark.fuzz

WRITERS = ["polar", "ground", "planes", "edges", "corners", "lines", "checkpoints", "heights",
           "assess", "info"]


def _with_output(argv: list, new: Path) -> list:
    """Replace the output of a baseline invocation (or add --json for `info`)."""
    argv = list(argv)
    for flag in ("-o", "--pairs"):
        if flag in argv:
            argv[argv.index(flag) + 1] = new
            return argv
    return [*argv, "--json", new]


def _output(argv: list) -> Path:
    for flag in ("-o", "--pairs"):
        if flag in argv:
            return Path(argv[argv.index(flag) + 1])
    return Path(argv[-1])


def _suffix(command: str) -> str:
    return {"ground": ".laz", "assess": "", "info": ".json"}.get(command, ".csv")


@pytest.mark.parametrize("command", WRITERS)
def test_hostile_output_paths(command, baseline, world, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    argv = baseline(out)[command]
    sfx = _suffix(command)
    (out / "afile").write_text("x")
    (out / "adir").mkdir()
    inputs_before = {p: p.read_bytes() for p in world["dir"].iterdir() if p.is_file()}
    cases = {
        "parent-is-file": out / "afile" / f"x{sfx}",
        "missing-folder": out / "missing" / "deeper" / f"x{sfx}",
        "empty-name": "",
    }
    if command != "assess":  # assess writes into a folder: an existing one is fine
        cases["is-directory"] = out / "adir"
        cases["same-as-input"] = argv[1]
        cases["exists"] = out / "afile"
        cases["fifo"] = out / f"fifo{sfx}"
        os.mkfifo(cases["fifo"])
    for name, target in cases.items():
        r = run_cli(["-q", *_with_output(argv, target)], out_dir=out)
        if name == "missing-folder" and command == "assess":
            continue  # assess creates its report folder (and its parents)
        assert r.exit_code in (1, 2), (name, r.output)
    assert (out / "afile").read_text() == "x"
    for p, data in inputs_before.items():
        assert p.read_bytes() == data, f"{p} was modified"


@pytest.mark.parametrize("command", WRITERS)
def test_outputs_get_umask_permissions(command, baseline, tmp_path):
    out = tmp_path / "out"
    old = os.umask(0o027)
    try:
        argv = baseline(out)[command]
        r = run_cli(["-q", *(argv if command != "info" else [*argv, "--json", out / "i.json"])],
                    out_dir=out)
    finally:
        os.umask(old)
    assert r.exit_code == 0, r.output
    files = [out / n for n in listing(out) if (out / n).is_file()]
    assert files
    for f in files:
        assert stat.S_IMODE(f.stat().st_mode) == 0o640, (f, oct(f.stat().st_mode))


@pytest.mark.parametrize("command", ["ground", "polar", "checkpoints", "info", "assess"])
def test_disk_full(command, baseline, tmp_path, monkeypatch):
    """The temporary output is /dev/full: every write fails with ENOSPC."""
    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full")
    import lidarqa._atomic as atomic

    real = atomic.tempfile.mkstemp

    def full_mkstemp(*a, **k):
        fd, name = real(*a, **k)
        os.close(fd)
        os.unlink(name)
        os.symlink("/dev/full", name)
        return os.open(os.devnull, os.O_RDONLY), name

    monkeypatch.setattr(atomic.tempfile, "mkstemp", full_mkstemp)
    out = tmp_path / "out"
    argv = baseline(out)[command]
    argv = argv if command != "info" else [*argv, "--json", out / "i.json"]
    r = run_cli(["-q", *argv], out_dir=out)
    assert r.exit_code == 1 and "space" in r.stderr.lower(), r.output


@pytest.mark.parametrize("err", [errno.EACCES, errno.EROFS, errno.ENOSPC, errno.EIO])
def test_unwritable_folder(err, baseline, tmp_path, monkeypatch):
    """Creating the temporary file fails (read-only folder, read-only file system, ...)."""
    import lidarqa._atomic as atomic

    def refuse(*a, **k):
        raise OSError(err, os.strerror(err))

    monkeypatch.setattr(atomic.tempfile, "mkstemp", refuse)
    out = tmp_path / "out"
    r = run_cli(["-q", *baseline(out)["ground"]], out_dir=out)
    assert r.exit_code == 1 and r.stderr.startswith("Error: cannot write"), r.output


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_read_only_folder(baseline, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    out.chmod(0o555)
    try:
        r = run_cli(["-q", *baseline(out)["ground"]], out_dir=out)
    finally:
        out.chmod(0o755)
    assert r.exit_code == 1 and "not writable" in r.stderr, r.output


def test_demo_hostile_outputs(tmp_path):
    """`demo` and `warmup` have no input to corrupt: only their outputs can be hostile
    (refused before any work)."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "afile").write_text("x")
    os.mkfifo(out / "fifo")
    cases = [
        ["-o", out / "afile" / "rep"],
        ["-o", out / "fifo"],
        ["-o", ""],
        ["-o", out / "rep", "--json", out / "afile" / "r.json"],
        ["-o", out / "rep", "--json", out / "fifo"],
    ]
    cases += [
        ["warmup", "--json", out / "afile" / "w.json"],
        ["warmup", "--json", out / "fifo"],
        ["warmup", "--json", out / "afile"],
        ["warmup", "--json", ""],
    ]
    for args in cases:
        argv = args if args[0] == "warmup" else ["demo", *args]
        r = run_cli(["-q", *argv], out_dir=out)
        assert r.exit_code in (1, 2), (args, r.output)
        assert listing(out) == {"afile", "fifo"}, (args, listing(out))
