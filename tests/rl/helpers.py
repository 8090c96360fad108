"""Shared by the tests of the trainers: ``cdr-bench`` in a subprocess, the scripts of
``sweeps/`` as modules."""

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[2]


def sweep_script(name: str) -> ModuleType:
    """``sweeps/<name>.py`` imported as a module."""
    spec = importlib.util.spec_from_file_location(name, ROOT / "sweeps" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


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
