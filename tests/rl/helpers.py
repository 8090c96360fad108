"""Shared by the tests of the trainers: ``cdr-bench`` in this process, the scripts of
``sweeps/`` and the shipped ``agent.py`` files as modules."""

import contextlib
import importlib.util
import io
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


def agent_module(folder: str) -> ModuleType:
    """``agents/<folder>/agent.py`` imported afresh (it reads ``CDR_BENCH_CHECKPOINT`` when an
    ``Agent`` is built)."""
    spec = importlib.util.spec_from_file_location(
        f"agent_{folder}", ROOT / "agents" / folder / "agent.py"
    )
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def cdr_bench(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    """``cdr-bench ARGS`` from the repository root, run by :func:`cdr_bench.cli.main` in this
    process with the variables ``env`` set for the call: its exit code and what it printed (the
    agent's own process, where a command starts one, prints elsewhere)."""
    from cdr_bench.cli import main

    out, err = io.StringIO(), io.StringIO()
    saved_env, saved_cwd = dict(os.environ), os.getcwd()
    os.environ.update(env or {})
    os.chdir(ROOT)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(list(args))
            except SystemExit as e:  # argparse's own errors and --help, as Python exits
                code = e.code if isinstance(e.code, int) else int(e.code is not None)
                if isinstance(e.code, str):
                    print(e.code, file=sys.stderr)
    finally:
        os.chdir(saved_cwd)
        os.environ.clear()
        os.environ.update(saved_env)
    return subprocess.CompletedProcess(list(args), code, out.getvalue(), err.getvalue())


def summary(stdout: str) -> dict:
    """The JSON summary a training run prints last."""
    return json.loads(stdout[stdout.index("{") :])
