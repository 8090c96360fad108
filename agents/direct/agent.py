"""Reference agent ``direct``: flies straight to its goal and never resolves a conflict.

Each step it turns 5 deg toward the goal (observation index 9, ``goal_sin_rel``, and 10,
``goal_cos_rel``) unless the goal is within half a turn step of the nose; speed and level are
held (:func:`cdr_bench.resolvers.direct_actions`, which ``mvp`` also uses to fly to its goal).
It is the lower bound a resolver must beat.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cdr_bench.resolvers import direct_actions


class Agent:
    def __init__(self, observation_space: Any, action_space: Any):
        pass

    def act(self, observation: dict[str, np.ndarray]) -> int:
        o, m = observation["observation"][None], observation["action_mask"][None]
        return int(self.act_batch(o, m)[0])

    def act_batch(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        return direct_actions(observations)
