"""Shared by the tests of the trainers: ``cdr-bench`` in a subprocess."""

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def cdr_bench(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    """``python -m cdr_bench ARGS`` from the repository root (one torch thread)."""
    return subprocess.run(
        [sys.executable, "-m", "cdr_bench", *args],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env={**os.environ, "OMP_NUM_THREADS": "1", **(env or {})},
        timeout=300,
    )


def summary(stdout: str) -> dict:
    """The JSON summary a training run prints last."""
    return json.loads(stdout[stdout.index("{") :])
