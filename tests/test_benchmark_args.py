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


WHOLE = "expected a whole number >= 1, got 0"


@pytest.mark.parametrize(
    ("script", "args", "message"),
    [
        ("gpu_check", ("--updates", "0"), f"argument --updates: {WHOLE}"),
        ("gpu_check", ("--algorithms", "dqn"), "invalid choice: 'dqn'"),
        ("latency", ("--episodes", "0"), f"argument --episodes: {WHOLE}"),
        ("latency", ("--entries", "nobody"), "--entries: no single-agent entry nobody"),
        ("latency", ("--json", "/dev/null"), "--json /dev/null"),
        ("pytest_cpu", ("/nonexistent", "--top", "0"), f"argument --top: {WHOLE}"),
        ("time_to_clean", ("/nonexistent",), "/nonexistent: no training log there"),
    ],
)
def test_bad_arguments_end_in_one_line(script: str, args: tuple[str, ...], message: str) -> None:
    r = _run(script, *args)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert message in r.stderr, r.stderr
