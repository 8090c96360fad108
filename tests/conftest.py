"""One thread per library in every test process and in what it starts (the environment is
inherited): pytest-xdist runs one test process per core, and a library that starts a thread per
core in each of them (PyTorch's and OpenBLAS's pools) oversubscribes the machine; a test that
needs another setting sets it."""

from __future__ import annotations

import os
from typing import Any

for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import pytest  # noqa: E402 - after the thread settings, before numpy loads

from cdr_bench.scenarios import ScenarioConfig, load_scenario  # noqa: E402


def make_config(**overrides: Any) -> ScenarioConfig:
    """The base scenario with nested overrides (no airway traffic unless asked)."""
    overrides.setdefault("traffic", {"routes": 0})
    return load_scenario("_base", **overrides)


@pytest.fixture
def config_factory():
    return make_config


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Long tests (``@pytest.mark.slow``) first, so that with one process per core
    (pytest-xdist) they do not start last and leave the other cores idle at the end."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)
