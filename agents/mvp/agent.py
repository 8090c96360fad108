"""Reference agent ``mvp``: a geometric resolver in the style of Modified Voltage Potential
(Hoekstra's MVP, the resolution method of BlueSky) adapted to the 27 discrete actions.

It sees what every agent sees: the observation vector (own state, goal, the K nearest aircraft
with relative position, velocity and level) and the action mask. The decision (detection at
the closest point of approach, a free adjacent level if there is one, else the MVP velocity
change rounded to the nearest discrete heading/speed change, else fly to the goal) is
:func:`cdr_bench.resolvers.mvp_actions`, documented there; the trainers' ``--mvp-input`` and
``agents/mvp_residual`` call the same function.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cdr_bench.resolvers import mvp_actions


class Agent:
    def __init__(self, observation_space: Any, action_space: Any):
        pass

    def act(self, observation: dict[str, np.ndarray]) -> int:
        o, m = observation["observation"][None], observation["action_mask"][None]
        return int(self.act_batch(o, m)[0])

    def act_batch(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        return mvp_actions(observations, masks)
