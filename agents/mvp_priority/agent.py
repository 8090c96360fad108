"""Reference agent ``mvp-priority``: MVP for every controlled aircraft, coordinated by a joint
controller that gives each conflict between two controlled aircraft to one of them (the
multi-agent track's joint baseline; the *joint* acting mode of the agent protocol).

The controller sees the observations of every controlled aircraft of an episode at once
(``act_joint``). Two of them see each other when each is among the other's observed
neighbours: aircraft ``i`` observes ``j`` at the relative position and level at which ``j``
observes ``i``, reversed (the same numbers with the opposite sign: the simulator computes them
from one difference). For such a pair the aircraft with the lower index has the right of way
and keeps its course against the other, which resolves the conflict alone with the full MVP
manoeuvre (:func:`cdr_bench.resolvers.mvp_actions` with ``right_of_way``); a conflict with an
aircraft that does not see it, or with background traffic, is resolved as ``mvp`` does. One
resolves instead of two: no manoeuvre is doubled or cancelled by the other's.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cdr_bench.resolvers import mvp_actions

N_OWN, N_FEATURES = 12, 10  # own features; features per observed neighbour


def right_of_way(observations: np.ndarray, episodes: np.ndarray, aircraft: np.ndarray) -> Any:
    """(N, K) bool: neighbour k of row i is a controlled aircraft of the same episode that sees
    row i too and has a higher index (row i keeps its course against it)."""
    obs = np.asarray(observations, dtype=np.float32)
    n = obs.shape[0]
    k = (obs.shape[1] - N_OWN) // N_FEATURES
    nb = obs[:, N_OWN : N_OWN + N_FEATURES * k].reshape(n, k, N_FEATURES)
    present = nb[..., 0] > 0.5
    rel = nb[..., [1, 2, 5]].tolist()  # dx, dy, dlevel: exact opposites seen from the other side
    seen: dict[tuple[int, float, float, float], list[tuple[int, int]]] = {}
    for i, a in zip(*np.nonzero(present), strict=True):
        dx, dy, dl = rel[i][a]
        seen.setdefault((int(episodes[i]), dx, dy, dl), []).append((int(i), int(a)))
    out = np.zeros((n, k), dtype=bool)
    for i, a in zip(*np.nonzero(present), strict=True):
        dx, dy, dl = rel[i][a]
        other = seen.get((int(episodes[i]), -dx, -dy, -dl), [])
        if len(other) == 1 and aircraft[other[0][0]] > aircraft[i]:  # j sees i, and yields
            out[i, a] = True
    return out


class Agent:
    def __init__(self, observation_space: Any, action_space: Any):
        pass

    def act(self, observation: dict[str, np.ndarray]) -> int:
        """One aircraft alone (no other controlled aircraft to coordinate with): ``mvp``."""
        o, m = observation["observation"][None], observation["action_mask"][None]
        return int(mvp_actions(o, m)[0])

    def act_joint(
        self,
        observations: np.ndarray,
        masks: np.ndarray,
        episodes: np.ndarray,
        aircraft: np.ndarray,
    ) -> np.ndarray:
        row = right_of_way(observations, episodes, aircraft)
        return mvp_actions(observations, masks, right_of_way=row)
