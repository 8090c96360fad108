"""PettingZoo's own test suites over every shipped scenario."""

from __future__ import annotations

import warnings

import pytest
from pettingzoo.test import api_test, parallel_api_test, render_test, seed_test
from pettingzoo.test.seed_test import parallel_seed_test
from pettingzoo.test.state_test import state_test

import cdr_bench
from cdr_bench.scenarios import list_scenarios

SCENARIOS = list_scenarios()


@pytest.fixture(autouse=True)
def _quiet():
    # PettingZoo warns that Dict observations "probably should be" Box: ours carry the mask.
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*probably should be.*")
        warnings.filterwarnings("ignore", message="Observation is not a NumPy array")
        yield


def test_every_kind_of_scenario_is_shipped():
    assert {"low", "medium", "high"} <= set(SCENARIOS)
    assert {f"curriculum/stage-{k:02d}" for k in range(1, 13)} <= set(SCENARIOS)
    assert {f"tactical/{n}" for n in ("head-on", "crossing", "overtaking")} <= set(SCENARIOS)
    assert any(s.startswith("marl/") for s in SCENARIOS)


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_parallel_api(scenario):
    parallel_api_test(cdr_bench.parallel_env(scenario), num_cycles=120)


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_aec_api(scenario):
    api_test(cdr_bench.env(scenario), num_cycles=120)


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_seed(scenario):
    seed_test(lambda: cdr_bench.env(scenario), num_cycles=60)
    parallel_seed_test(lambda: cdr_bench.parallel_env(scenario), num_cycles=60)


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_state(scenario):
    state_test(cdr_bench.env(scenario), cdr_bench.parallel_env(scenario), num_cycles=20)


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_render(scenario):
    render_test(lambda render_mode=None: cdr_bench.env(scenario, render_mode=render_mode))
