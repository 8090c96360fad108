"""A small agent for the tutorial "Evaluate your agent": fly to the goal, and change level when
an observed aircraft at the own level is predicted to lose separation.

It implements the agent protocol (``cdr_bench/evaluate/protocol.py``): a class ``Agent``
constructed with the per-agent spaces, ``act`` for one aircraft and ``act_batch`` for many.
"""

from __future__ import annotations

from typing import Any

import numpy as np

GOAL_SIN, GOAL_COS = 9, 10  # observation indices: sin / cos of the bearing to the goal
OWN, PER_NEIGHBOUR = 12, 10  # own features, then 10 features per observed aircraft
PRESENT, DLEVEL, CONFLICT = 0, 5, 9  # neighbour features: slot used, level difference, conflict
HALF_TURN_DEG = 2.5  # half of the 5 deg heading step


class Agent:
    def __init__(self, observation_space: Any, action_space: Any):
        n_obs = int(observation_space["observation"].shape[0])  # F = 12 + 10 K
        self.k = (n_obs - OWN) // PER_NEIGHBOUR
        assert int(action_space.n) == 27

    def act(self, observation: dict[str, np.ndarray]) -> int:
        obs, mask = observation["observation"][None], observation["action_mask"][None]
        return int(self.act_batch(obs, mask)[0])

    def act_batch(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        n = observations.shape[0]
        nb = observations[:, OWN : OWN + PER_NEIGHBOUR * self.k].reshape(n, self.k, PER_NEIGHBOUR)
        # Heading: turn 5 deg toward the goal unless it is within half a step of the nose.
        bearing = np.degrees(np.arctan2(observations[:, GOAL_SIN], observations[:, GOAL_COS]))
        a_psi = np.where(bearing > HALF_TURN_DEG, 1, np.where(bearing < -HALF_TURN_DEG, -1, 0))
        # Level: on a predicted conflict, climb if the mask allows it, else descend.
        conflict = ((nb[..., PRESENT] > 0.5) & (nb[..., CONFLICT] > 0.5)).any(axis=1)
        climb_ok = masks[:, 9 * 1 + 3 * 1 + 2] > 0  # is (0, 0, +1) feasible at this level?
        a_h = np.where(conflict, np.where(climb_ok, 1, -1), 0)
        # The action index of (a_psi, a_v = 0, a_h); see cdr_bench.actions.
        return 9 * (a_psi + 1) + 3 * 1 + (a_h + 1)
