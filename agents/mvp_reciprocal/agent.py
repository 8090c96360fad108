"""Reference agent ``mvp-reciprocal``: the cooperative variant of ``mvp`` for sectors in which
every aircraft is controlled and runs it (the multi-agent track's reciprocal baseline).

Each aircraft decides on its own observation, as ``mvp`` does, but assumes the other aircraft
of a conflict resolves too: it takes half of MVP's velocity change, and the vertical escape is
shared by direction (eastbound aircraft may only climb, westbound ones only descend), so two
aircraft in conflict never escape to the same level. :func:`cdr_bench.resolvers.mvp_actions`
with ``reciprocal=True`` documents the rule; the same numbers on every CPU.
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
        return mvp_actions(observations, masks, reciprocal=True)
