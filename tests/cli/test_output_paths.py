"""Every command that writes a file checks its path first: a folder given as the file, or a
file where a folder must be, is a one-line error (exit 2) before any work, and no temporary
file is left behind; a path the system refuses at write time is one too. The commands run in
this process (:func:`cdr_bench.cli.main`)."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

from cdr_bench.cli import main

ROOT = Path(__file__).resolve().parents[2]
RESULT = "<result>"  # stands for a small result of the mvp agent (fixture ``result``)
MVP = str(ROOT / "agents" / "mvp")
COMMANDS = {
    "report": ["report", RESULT],
    "evaluate": ["evaluate", MVP, "--scenario", "low", "--episodes", "2"],
    "multimodal": ["multimodal", MVP, "--episodes", "1", "--samples", "2"],
    "latency": ["latency", MVP, "--batch-sizes", "1", "--decisions", "4"],
    "certify": ["scenarios", "certify", "tactical/crossing", "--episodes", "2", "--agent", "none"],
    "render": ["render", "low"],
}


@pytest.fixture(scope="module")
def result(tmp_path_factory: pytest.TempPathFactory) -> str:
    from cdr_bench.evaluate.api import evaluate, resolve_jobs

    out = tmp_path_factory.mktemp("result") / "mvp.json"
    jobs, _ = resolve_jobs(["low"], None, 2)
    evaluate(MVP, jobs, out, batch_size=2, progress=False)
    return str(out)


@pytest.fixture
def cdr(capsys: pytest.CaptureFixture[str], request: pytest.FixtureRequest):
    """``cdr(*args, cwd)``: ``cdr-bench ARGS`` run in ``cwd``: (exit code, standard error)."""

    def run(*args: str, cwd: Path) -> tuple[int, str]:
        if RESULT in args:
            args = tuple(request.getfixturevalue("result") if a == RESULT else a for a in args)
        capsys.readouterr()
        before = os.getcwd()
        os.chdir(cwd)
        try:
            code = main(list(args))
        finally:
            os.chdir(before)
        return code, capsys.readouterr().err

    return run


@pytest.mark.parametrize("command", list(COMMANDS))
def test_bad_output_paths_are_one_line_errors(cdr, tmp_path: Path, command: str) -> None:
    (tmp_path / "file").write_text("x")
    (tmp_path / "dir.out").mkdir()
    ext = ".gif" if command == "render" else ".json"
    for out, words in [
        (tmp_path / "file" / f"x{ext}", f"{tmp_path / 'file'} is a file, not a folder"),
        (tmp_path / "dir.out", "is a folder; expected a file path"),
    ]:
        if command == "render" and out.suffix != ".gif":
            continue  # render first insists on a .gif name
        code, err = cdr(*COMMANDS[command], "--out", str(out), cwd=tmp_path)
        assert code == 2, err
        assert "Traceback" not in err
        assert f"--out {out}: {words}" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dir.out", "file"]  # nothing else
    assert list((tmp_path / "dir.out").iterdir()) == []


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux /proc")
def test_a_write_the_system_refuses_is_a_one_line_error(cdr, tmp_path: Path) -> None:
    """/proc passes the access check (as root too) but refuses new files: the write fails."""
    for command in ("report", "latency"):
        code, err = cdr(*COMMANDS[command], "--out", "/proc/cdr-bench-x.json", cwd=tmp_path)
        assert code == 2 and "Traceback" not in err
        assert "/proc/cdr-bench-x.json: cannot write it" in err


WRITERS = {  # every flag of every command that names a file to write, and the command
    **{f"{name} --out": [*argv, "--out"] for name, argv in COMMANDS.items()},
    "compare --json": ["compare", RESULT, RESULT, "--json"],
    "sweep-plot --out": ["sweep-plot", "<tmp>", "--out"],
    "sweep-plot --json": ["sweep-plot", "<tmp>", "--json"],
}


def _not_files(tmp_path: Path, ext: str) -> dict[str, Path]:
    """A named pipe, and a symbolic link to /dev/null (the old writer replaced what was there:
    the link, never /dev/null itself, so a regression cannot harm the machine)."""
    fifo, null = tmp_path / f"fifo{ext}", tmp_path / f"null{ext}"
    os.mkfifo(fifo)
    null.symlink_to("/dev/null")
    return {"a named pipe (FIFO)": fifo, "a character device": null}


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")
@pytest.mark.parametrize("writer", list(WRITERS))
def test_devices_and_pipes_are_refused_as_outputs_before_any_work(cdr, tmp_path, writer):
    """`report --out /dev/full` (as root) replaced the device with a regular file and exited 0:
    every writer refuses what is not a regular file, with one line, and leaves it as it was."""
    ext = ".gif" if writer.startswith("render") else ".json"
    for kind, target in _not_files(tmp_path, ext).items():
        argv = [str(tmp_path) if a == "<tmp>" else a for a in WRITERS[writer]]
        code, err = cdr(*argv, str(target), cwd=tmp_path)
        flag = writer.split()[1]
        assert code == 2, err
        assert "Traceback" not in err and err.count("\n") == 1
        assert f"{flag} {target}: is {kind}, not a regular file" in err
    assert (tmp_path / f"fifo{ext}").is_fifo()
    assert os.readlink(tmp_path / f"null{ext}") == "/dev/null"
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"fifo{ext}", f"null{ext}"]


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")
def test_the_atomic_writer_never_replaces_what_is_not_a_regular_file(tmp_path) -> None:
    """The last line of defence, for writers that did not check first (and for a pipe that
    appears after the check): atomic_write_text refuses, leaves no temporary file."""
    from cdr_bench.errors import UserError
    from cdr_bench.evaluate.results import atomic_write_text

    targets = _not_files(tmp_path, ".json")
    (tmp_path / "dir").mkdir()
    targets["a folder"] = tmp_path / "dir"
    for kind, target in targets.items():
        with pytest.raises(UserError, match=re.escape(f"is {kind}, not a regular file; refusing")):
            atomic_write_text(target, "x")
    assert (tmp_path / "fifo.json").is_fifo()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dir", "fifo.json", "null.json"]
    atomic_write_text(tmp_path / "ok.json", "x")  # a regular file (new or old) is written
    atomic_write_text(tmp_path / "ok.json", "y")
    assert (tmp_path / "ok.json").read_text() == "y"
