"""cdr-bench: an open benchmark suite for learned air-traffic Conflict Detection and Resolution.

>>> import cdr_bench
>>> env = cdr_bench.parallel_env(scenario="medium")   # PettingZoo ParallelEnv
>>> aec = cdr_bench.env(scenario="medium")            # PettingZoo AEC form
>>> import gymnasium; g = gymnasium.make("cdr_bench/Ownship-v0", scenario="high")

``cdr_bench.sim`` and ``cdr_bench.scenarios`` also work in an interpreter without PettingZoo or
Gymnasium (the environment names are then unavailable).
"""

from __future__ import annotations

from typing import Any

from cdr_bench import actions
from cdr_bench.scenarios import ScenarioConfig, ScenarioError, list_scenarios, load_scenario

__version__ = "0.3.0"

try:  # the environment layer needs PettingZoo and Gymnasium; the simulator does not
    # Bound eagerly: the function `env` must shadow the submodule `cdr_bench.env`.
    from cdr_bench.env import CDREnv, env, parallel_env
except ImportError as _e:  # pragma: no cover - simulator-only interpreter
    _missing = _e

    def __getattr__(name: str) -> Any:
        if name in ("CDREnv", "env", "parallel_env"):
            raise ImportError(f"cdr_bench.{name} needs PettingZoo and Gymnasium: {_missing}")
        raise AttributeError(f"module 'cdr_bench' has no attribute {name!r}")
else:
    import gymnasium as _gym

    if "cdr_bench/Ownship-v0" not in _gym.registry:
        _gym.register(
            id="cdr_bench/Ownship-v0",
            entry_point="cdr_bench.gym_env:OwnshipEnv",
            vector_entry_point="cdr_bench.gym_env:OwnshipVectorEnv",
        )

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
