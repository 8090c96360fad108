"""Numpy airspace simulator. Imports no PettingZoo, Gymnasium or torch (a test enforces it)."""

from cdr_bench.sim.core import (
    OUTCOME_NAMES,
    REWARD_TERMS,
    Simulator,
    SingleStepResult,
    StepResult,
)
from cdr_bench.sim.observation import feature_names, observation_bounds, observe, observe_one

__all__ = [
    "OUTCOME_NAMES",
    "REWARD_TERMS",
    "SingleStepResult",
    "Simulator",
    "StepResult",
    "feature_names",
    "observation_bounds",
    "observe",
    "observe_one",
]
