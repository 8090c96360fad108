"""The benchmark scripts end bad arguments with a one-line error, never a traceback."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = (
    "env_throughput",
    "evaluate_throughput",
    "leaderboard_render",
    "read_results",
    "train_throughput",
)


def _run(script: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / f"{script}.py"), *args],
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.mark.parametrize("script", SCRIPTS)
def test_reference_that_is_not_a_commit(script: str) -> None:
    r = _run(script, "--reference", "no-such-commit", "--rounds", "1")
    assert r.returncode != 0
    assert "Traceback" not in r.stderr
    assert "--reference 'no-such-commit': not a commit of this repository" in r.stderr
    assert not (ROOT / ".bench" / "no-such-commit").exists()


@pytest.mark.parametrize("script", [*SCRIPTS, "cold_start"])
def test_zero_rounds(script: str) -> None:
    flag = "--runs" if script == "cold_start" else "--rounds"
    r = _run(script, flag, "0")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert f"argument {flag}: expected a whole number >= 1, got 0" in r.stderr


def test_gpu_check_refuses_bad_arguments_in_one_line() -> None:
    r = _run("gpu_check", "--updates", "0")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "argument --updates: expected a whole number >= 1, got 0" in r.stderr
    r = _run("gpu_check", "--algorithms", "dqn")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "invalid choice: 'dqn'" in r.stderr


def test_latency_refuses_bad_arguments_in_one_line() -> None:
    r = _run("latency", "--episodes", "0")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "argument --episodes: expected a whole number >= 1, got 0" in r.stderr
    r = _run("latency", "--entries", "nobody")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "--entries: no single-agent entry nobody" in r.stderr
    r = _run("latency", "--json", "/dev/null")
    assert r.returncode == 2 and "Traceback" not in r.stderr and "--json" in r.stderr
