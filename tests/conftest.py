"""One thread per library in every test process and in what it starts (the environment is
inherited): pytest-xdist runs a test process per core (and one more), and a library that starts
a thread per core in each of them (PyTorch's and OpenBLAS's pools) oversubscribes the machine; a
test that needs another setting sets it.

One folder of drawn leaderboard plots per test run (``CDR_BENCH_PLOT_CACHE``, shared by the test
processes and what they start, removed at the end), not the user's: the tests run dozens of
leaderboard builds of the same miniature leaderboard, and each drew the same plots again. Its
``sb3-logs`` is ``SB3_LOGDIR``: Stable-Baselines3 makes a log folder (in ``/tmp`` unless told)
for every model that trains without a logger of its own."""

from __future__ import annotations

import os
import shutil
import tempfile
from typing import Any

for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import pytest  # noqa: E402 - after the thread settings, before numpy loads

from cdr_bench.leaderboard.plots import PLOT_CACHE_ENV  # noqa: E402
from cdr_bench.scenarios import ScenarioConfig, load_scenario  # noqa: E402


def make_config(**overrides: Any) -> ScenarioConfig:
    """The base scenario with nested overrides (no airway traffic unless asked)."""
    overrides.setdefault("traffic", {"routes": 0})
    return load_scenario("_base", **overrides)


@pytest.fixture
def config_factory():
    return make_config


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Long tests (``@pytest.mark.slow``) first in every test process, so that none starts
    last and leaves the other cores idle at the end.

    pytest-xdist's ``worksteal`` hands each of the W processes one contiguous part of this list
    (sizes n // W, then what is left // (W - 1), ...), and a process that runs out takes the
    second half of the longest queue. With the long tests all at the head of the list, they
    were all in the first process's part, one after the other, and the last of them ran alone
    at the end (measured: the Ray sweep tests from 234 to 326 s of a 344 s run). So the long
    tests are dealt round-robin to the parts, each part starting with its share."""
    slow = [i for i in items if i.get_closest_marker("slow") is not None]
    rest = [i for i in items if i.get_closest_marker("slow") is None]
    w = max(1, int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")))
    out, left, taken = [], len(items), 0
    for k in range(w):
        size = left // (w - k)
        left -= size
        head = slow[k::w]
        more = max(0, size - len(head))
        out += head + rest[taken : taken + more]
        taken += more
    items[:] = out + rest[taken:]


def pytest_xdist_auto_num_workers(config: pytest.Config) -> int:
    """``-n auto`` (pyproject's addopts): one test process more than this process may use cores.
    A third of a test process's time is spent waiting on the subprocesses it starts (sandboxed
    scorers and agents, CLI runs, Ray), a core the extra process fills: on the 2-core machine
    the suite alone took 365 s with 3 processes against 382 s with 2, at 724 busy CPU-s."""
    return len(os.sched_getaffinity(0)) + 1


def pytest_configure(config: pytest.Config) -> None:
    """The run's plot folder (module docstring), made by the process that starts the test
    processes (they inherit its environment)."""
    if "PYTEST_XDIST_WORKER" in os.environ or PLOT_CACHE_ENV in os.environ:
        return
    folder = tempfile.mkdtemp(prefix="cdr-bench-plots-")
    os.environ[PLOT_CACHE_ENV] = folder
    os.environ.setdefault("SB3_LOGDIR", os.path.join(folder, "sb3-logs"))
    config.stash[_PLOTS] = folder


def pytest_unconfigure(config: pytest.Config) -> None:
    folder = config.stash.get(_PLOTS, None)
    if folder is not None:
        shutil.rmtree(folder, ignore_errors=True)
        os.environ.pop(PLOT_CACHE_ENV, None)


_PLOTS = pytest.StashKey[str]()
