"""cdr-bench: an open benchmark suite for learned air-traffic Conflict Detection and Resolution.

>>> import cdr_bench
>>> env = cdr_bench.parallel_env(scenario="medium")   # PettingZoo ParallelEnv
>>> aec = cdr_bench.env(scenario="medium")            # PettingZoo AEC form
>>> import gymnasium; g = gymnasium.make("cdr_bench/Ownship-v0", scenario="high")

``cdr_bench.sim`` and ``cdr_bench.scenarios`` also work in an interpreter without PettingZoo or
Gymnasium (the environment names are then unavailable).
"""

from __future__ import annotations

import importlib
import sys
import types
from typing import TYPE_CHECKING, Any

from cdr_bench import actions
from cdr_bench.scenarios import ScenarioConfig, ScenarioError, list_scenarios, load_scenario

__version__ = "0.3.0"

_DENSITIES = ("low", "medium", "high")
_ENCOUNTERS = (("HeadOn", "head-on"), ("Crossing", "crossing"), ("Overtaking", "overtaking"))
"""The density scenarios and the tactical families with their ids' stems (``HeadOn``)."""

GYMNASIUM_TASKS: list[tuple[str, dict[str, Any], int | None]] = [
    ("cdr_bench/Ownship-v0", {}, None),  # any scenario: make(..., scenario="high")
    *((f"cdr_bench/{d.capitalize()}-v0", {"scenario": d}, 1000) for d in _DENSITIES),
    *((f"cdr_bench/{i}-v1", {"scenario": f"tactical/{s}"}, 60) for i, s in _ENCOUNTERS),
    *((f"cdr_bench/{i}Fixed-v0", {"scenario": f"tactical/{s}-fixed"}, 60) for i, s in _ENCOUNTERS),
    # The tactical ids' version 0 was the fixed encounter: it stays what it was.
    *((f"cdr_bench/{i}-v0", {"scenario": f"tactical/{s}-fixed"}, 60) for i, s in _ENCOUNTERS),
    *(
        (f"cdr_bench/CurriculumStage{i:02d}-v0", {"scenario": f"curriculum/stage-{i:02d}"}, 1000)
        for i in range(1, 13)
    ),
]
"""Gymnasium ids registered on import (the ownship's task; learning intruders, if any, hold):
one per shipped single-agent task, ``max_episode_steps`` = the scenario's horizon (the env also
ends the episode there, as ``timeout``). An id's version is its scenario's ``version`` minus 3
(``-v0``: version 3), so it goes up whenever its scenario's does: ``HeadOn-v1``,
``Crossing-v1``, ``Overtaking-v1`` are the tactical families of version 4 (docs/model.md §8.3);
their ``-v0`` stays the fixed encounter it always was (also ``HeadOnFixed-v0`` etc.), and
Gymnasium says so when it is made. Multi-agent scenarios (``marl/*``) are PettingZoo tasks."""

_ENV_NAMES = ("CDREnv", "env", "parallel_env")
"""Bound on first use (:class:`_Package`): most processes that import this package never make
an environment (a confined agent, a checkpoint check), and ``cdr_bench.env`` imports the
simulator and numba, a third of the package's import time."""

if TYPE_CHECKING:
    from cdr_bench.env import CDREnv, env, parallel_env


class _Package(types.ModuleType):
    """This package's module: ``cdr_bench.env`` is the function, not the submodule.

    Importing the submodule ``cdr_bench.env`` would bind it as this package's attribute ``env``
    and hide the function; that binding is refused (the submodule stays in ``sys.modules``),
    and the three names of :data:`_ENV_NAMES` are bound from it on first use."""

    def __setattr__(self, name: str, value: Any) -> None:
        if name == "env" and isinstance(value, types.ModuleType):
            return
        super().__setattr__(name, value)

    def __getattr__(self, name: str) -> Any:
        if name not in _ENV_NAMES:
            raise AttributeError(f"module 'cdr_bench' has no attribute {name!r}")
        try:  # the environment layer needs PettingZoo and Gymnasium; the simulator does not
            module = importlib.import_module("cdr_bench.env")
        except ImportError as e:
            raise ImportError(f"cdr_bench.{name} needs PettingZoo and Gymnasium: {e}") from None
        for n in _ENV_NAMES:
            super().__setattr__(n, getattr(module, n))
        return getattr(module, name)


sys.modules[__name__].__class__ = _Package

try:
    import gymnasium as _gym
except ImportError:  # pragma: no cover - simulator-only interpreter
    pass
else:
    for _id, _kwargs, _steps in GYMNASIUM_TASKS:
        if _id not in _gym.registry:
            _gym.register(
                id=_id,
                entry_point="cdr_bench.gym_env:OwnshipEnv",
                vector_entry_point="cdr_bench.gym_env:OwnshipVectorEnv",
                max_episode_steps=_steps,
                kwargs=_kwargs,
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
