"""Every command that writes a file checks its path first: a folder given as the file, or a
file where a folder must be, is a one-line error (exit 2) before any work, and no temporary
file is left behind; a path the system refuses at write time is one too."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
RESULT = str(ROOT / "leaderboard" / "results" / "mvp.json")
MVP = str(ROOT / "agents" / "mvp")
COMMANDS = {
    "report": ["report", RESULT],
    "evaluate": ["evaluate", MVP, "--scenario", "low", "--episodes", "2"],
    "multimodal": ["multimodal", MVP, "--episodes", "1", "--samples", "2"],
    "latency": ["latency", MVP, "--batch-sizes", "1", "--decisions", "4"],
    "certify": ["scenarios", "certify", "tactical/crossing", "--episodes", "2", "--agent", "none"],
    "render": ["render", "low"],
}


def _run(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "cdr_bench", *args], capture_output=True, text=True, cwd=cwd
    )


@pytest.mark.parametrize("command", list(COMMANDS))
def test_bad_output_paths_are_one_line_errors(tmp_path: Path, command: str) -> None:
    (tmp_path / "file").write_text("x")
    (tmp_path / "dir.out").mkdir()
    ext = ".gif" if command == "render" else ".json"
    for out, words in [
        (tmp_path / "file" / f"x{ext}", f"{tmp_path / 'file'} is a file, not a folder"),
        (tmp_path / "dir.out", "is a folder; expected a file path"),
    ]:
        if command == "render" and out.suffix != ".gif":
            continue  # render first insists on a .gif name
        r = _run(*COMMANDS[command], "--out", str(out), cwd=tmp_path)
        assert r.returncode == 2, r.stderr
        assert "Traceback" not in r.stderr
        assert f"--out {out}: {words}" in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dir.out", "file"]  # nothing else
    assert list((tmp_path / "dir.out").iterdir()) == []


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux /proc")
def test_a_write_the_system_refuses_is_a_one_line_error(tmp_path: Path) -> None:
    """/proc passes the access check (as root too) but refuses new files: the write fails."""
    for command in ("report", "latency"):
        r = _run(*COMMANDS[command], "--out", "/proc/cdr-bench-x.json", cwd=tmp_path)
        assert r.returncode == 2 and "Traceback" not in r.stderr
        assert "/proc/cdr-bench-x.json: cannot write it" in r.stderr
