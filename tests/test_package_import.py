"""``import cdr_bench`` leaves the simulator out; ``cdr_bench.env`` is the function whatever was
imported first."""

from __future__ import annotations

import subprocess
import sys

import pytest


def _run(code: str) -> str:
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return r.stdout.strip()


def test_importing_the_package_or_the_agent_host_leaves_the_simulator_and_numba_out():
    out = _run(
        "import sys, cdr_bench, cdr_bench.evaluate.agent_host, cdr_bench.leaderboard.safeload\n"
        "import gymnasium; assert 'cdr_bench/High-v0' in gymnasium.registry\n"
        "print(sorted(m for m in ('numba', 'cdr_bench.sim', 'cdr_bench.env', 'torch') "
        "if m in sys.modules))"
    )
    assert out == "[]"


@pytest.mark.parametrize(
    "first",
    [
        "import cdr_bench",
        "import cdr_bench.env",
        "from cdr_bench.env import CDREnv",
        "import cdr_bench.evaluate.runner",
        "import cdr_bench.vector_env",
    ],
)
def test_env_is_the_function_whatever_was_imported_first(first):
    out = _run(
        f"{first}\n"
        "import sys, types, cdr_bench\n"
        "from cdr_bench import env, parallel_env, CDREnv\n"
        "import cdr_bench.env as also\n"
        "assert callable(env) and not isinstance(env, types.ModuleType), env\n"
        "assert cdr_bench.env is env is also is sys.modules['cdr_bench.env'].env\n"
        "assert CDREnv is sys.modules['cdr_bench.env'].CDREnv\n"
        "p = parallel_env(scenario='low'); p.reset(seed=0)\n"
        "a = cdr_bench.env(scenario='low'); a.reset(seed=0)\n"
        "print(type(p).__name__, len(p.agents) > 0)"
    )
    assert out == "CDREnv True"


def test_an_unknown_name_is_an_attribute_error():
    out = _run(
        "import cdr_bench\n"
        "try:\n    cdr_bench.no_such_name\nexcept AttributeError as e:\n    print(e)"
    )
    assert out == "module 'cdr_bench' has no attribute 'no_such_name'"
