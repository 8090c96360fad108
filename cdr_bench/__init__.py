"""cdr-bench: an open benchmark suite for learned air-traffic Conflict Detection and Resolution.

>>> import cdr_bench
>>> env = cdr_bench.parallel_env(scenario="medium")   # PettingZoo ParallelEnv
>>> aec = cdr_bench.env(scenario="medium")            # PettingZoo AEC form
>>> import gymnasium; g = gymnasium.make("cdr_bench/Ownship-v0", scenario="high")
"""

from __future__ import annotations

import gymnasium as _gym

from cdr_bench import actions
from cdr_bench.env import CDREnv, env, parallel_env
from cdr_bench.scenarios import ScenarioConfig, ScenarioError, list_scenarios, load_scenario

__version__ = "0.1.0"

if "cdr_bench/Ownship-v0" not in _gym.registry:
    _gym.register(id="cdr_bench/Ownship-v0", entry_point="cdr_bench.gym_env:OwnshipEnv",
                  disable_env_checker=False)

__all__ = [
    "CDREnv",
    "ScenarioConfig",
    "ScenarioError",
    "__version__",
    "actions",
    "env",
    "list_scenarios",
    "load_scenario",
    "parallel_env",
]
