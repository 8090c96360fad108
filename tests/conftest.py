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
    """Long tests (``@pytest.mark.slow``) first, so that with one process per core
    (pytest-xdist) they do not start last and leave the other cores idle at the end."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)
