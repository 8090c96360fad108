"""The airspace simulator: numba-compiled loops over episodes and aircraft, one implementation
for every batch size. Imports no PettingZoo, Gymnasium or torch (a test enforces it)."""

from cdr_bench.sim import kernels
from cdr_bench.sim.core import OUTCOME_NAMES, REWARD_TERMS, Simulator, StepResult
from cdr_bench.sim.observation import feature_names, observation_bounds, observe

__all__ = [
    "OUTCOME_NAMES",
    "REWARD_TERMS",
    "Simulator",
    "StepResult",
    "feature_names",
    "kernels",
    "observation_bounds",
    "observe",
]
