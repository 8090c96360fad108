"""Reference agent ``direct``: flies straight to its goal and never resolves a conflict.

Each step it turns 5 deg toward the goal (observation index 9, ``goal_sin_rel``, and 10,
``goal_cos_rel``) unless the goal is within half a turn step of the nose; speed and level are
held. It is the lower bound a resolver must beat.
"""

from __future__ import annotations

from typing import Any

import numpy as np

HALF_TURN_DEG = 2.5  # half of the 5 deg heading step: closer than this, a turn overshoots
GOAL_SIN, GOAL_COS = 9, 10


def steer_to_goal(obs: np.ndarray) -> np.ndarray:
    """(N,) heading factor a_psi in {-1, 0, +1} that turns toward the goal."""
    rel = np.degrees(np.arctan2(obs[:, GOAL_SIN], obs[:, GOAL_COS]))  # + = goal to the right
    return np.where(rel > HALF_TURN_DEG, 1, np.where(rel < -HALF_TURN_DEG, -1, 0))


class Agent:
    def __init__(self, observation_space: Any, action_space: Any):
        pass

    def act(self, observation: dict[str, np.ndarray]) -> int:
        return int(
            self.act_batch(observation["observation"][None], observation["action_mask"][None])[0]
        )

    def act_batch(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        a_psi = steer_to_goal(observations)
        return 9 * (a_psi + 1) + 3 * 1 + 1  # (a_psi, hold speed, hold level)
