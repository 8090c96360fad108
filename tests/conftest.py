from __future__ import annotations

from typing import Any

import pytest

from cdr_bench.scenarios import ScenarioConfig, load_scenario


def make_config(**overrides: Any) -> ScenarioConfig:
    """The base scenario with nested overrides (no airway traffic unless asked)."""
    overrides.setdefault("traffic", {"routes": 0})
    return load_scenario("_base", **overrides)


@pytest.fixture
def config_factory():
    return make_config


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Long tests (``@pytest.mark.slow``) first, so that with several test processes
    (pytest-xdist) they do not start last and leave the other processes idle at the end."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


def pytest_xdist_auto_num_workers(config: pytest.Config) -> int:
    """``-n auto``: two test processes more than cores. A quarter of the suite's time is spent
    waiting (agent processes starting, time-outs being reached, a Ray cluster coming up,
    headless Chromium), which the extra processes fill; measured with ``.ci/run`` on 2 cores."""
    import os

    return (os.cpu_count() or 1) + 2
