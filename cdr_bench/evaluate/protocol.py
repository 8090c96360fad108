"""The agent protocol: what ``cdr-bench evaluate`` (and ``render --agent``) expects of an agent.

An agent is a plain Python file (or a folder holding ``agent.py`` and its checkpoint) that
defines a class ``Agent``::

    class Agent:
        def __init__(self, observation_space, action_space): ...
        def act(self, observation: dict) -> int: ...
        # optional:
        def act_batch(self, observations, masks) -> "array of ints": ...
        def reset(self, seed: int) -> None: ...
        def act_joint(self, observations, masks, episodes, aircraft) -> "array of ints": ...

* ``observation_space`` is the per-agent ``gymnasium.spaces.Dict`` of the environment
  (``observation``: ``Box(F,)`` float32, ``action_mask``: ``Box(27,)`` int8) and
  ``action_space`` is ``Discrete(27)``. The observation index table is in the env card.
* ``act(observation)`` receives the environment's per-agent dict
  ``{"observation": (F,) float32, "action_mask": (27,) int8}`` and returns an action index
  0..26 (a Python or numpy integer). See :mod:`cdr_bench.actions` for index <-> triple.
* ``act_batch(observations, masks)`` (optional, recommended): ``observations`` is (N, F)
  float32, ``masks`` (N, 27) int8, one row per aircraft to decide for (rows of many episodes,
  and of every learning aircraft of an episode); return N integer indices (a list or an integer
  array). The evaluator runs episodes in lock-step batches and calls it once per step for every
  flying aircraft; without it, ``act`` is called row by row.
* ``reset(seed)`` (optional) is called before every lock-step batch of episodes with a seed
  derived from the run's base seed, the scenario and the batch; an agent that draws random
  numbers should re-seed from it so that results do not depend on ``--workers`` or ``--resume``.

* ``act_joint(observations, masks, episodes, aircraft)`` (optional; the *joint* acting mode):
  the same rows as ``act_batch`` plus, per row, ``episodes`` (N,) int64, which episode of the
  call the row belongs to (the rows of an episode are together, in increasing order), and
  ``aircraft`` (N,) int64, which of that episode's controlled aircraft it is (0: the ownship or
  the first controlled aircraft; the PettingZoo agent order). An agent that defines it is asked
  through it instead of ``act_batch`` and ``act``: the decision of an aircraft may then depend on
  the observations of every aircraft of its episode at that step (a centralised controller, or
  aircraft that coordinate), never on another episode. Its result records ``"acting":
  "joint"``.

Without ``act_joint`` the protocol is decentralised and Markov: a decision may depend only on
the row it is given (the same agent drives the ownship and every learning intruder).

A masked action is counted as invalid and its level change is not executed; a value that is
not an integer in 0..26 (a float, NaN, a bool, an out-of-range index), an exception in the agent
or a decision that exceeds the per-decision time limit stops the run with the episode, the step
and what went wrong.

The agent runs in its own process (:mod:`cdr_bench.evaluate.remote`): it is imported and
constructed there, receives the observation and mask arrays of each step and returns actions;
it never sees the simulator or the result files, and its ``print`` goes to standard error.
Loading and construction must finish within ``--load-timeout`` (300 s) and every decision within
``--decision-timeout`` (10 s), both enforced from outside its process; an agent process that
exits or dies stops the run with the exit status. The evaluator imports nothing of torch; an
agent that needs it imports it itself and locates its checkpoint relative to its own file
(``pathlib.Path(__file__).parent``).
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray


@runtime_checkable
class Agent(Protocol):
    """The required part of the protocol (see the module docstring for the optional methods)."""

    def act(self, observation: dict[str, NDArray[Any]]) -> int:
        """One action index 0..26 for one aircraft's observation dict."""
        ...


class JointAgent(Agent, Protocol):
    """An agent that decides for the controlled aircraft of each episode together."""

    def act_joint(
        self,
        observations: NDArray[np.float32],
        masks: NDArray[np.int8],
        episodes: NDArray[np.int64],
        aircraft: NDArray[np.int64],
    ) -> NDArray[np.integer] | list[int]:
        """(N,) action indices; ``episodes`` and ``aircraft`` (N,) say whose each row is."""
        ...


class BatchAgent(Agent, Protocol):
    """An agent that also decides for many aircraft at once."""

    def act_batch(
        self, observations: NDArray[np.float32], masks: NDArray[np.int8]
    ) -> NDArray[np.integer] | list[int]:
        """(N,) action indices for (N, F) observations and (N, 27) masks."""
        ...
