"""Reference agent ``random``: an action drawn uniformly among the feasible ones (the mask).

Re-seeded by ``reset(seed)`` before every lock-step batch, so its episodes do not depend on
``--workers`` or ``--resume``.
"""

from __future__ import annotations

from typing import Any

import numpy as np


class Agent:
    def __init__(self, observation_space: Any, action_space: Any):
        self.rng = np.random.default_rng(0)

    def reset(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)

    def act(self, observation: dict[str, np.ndarray]) -> int:
        return int(
            self.act_batch(observation["observation"][None], observation["action_mask"][None])[0]
        )

    def act_batch(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        # uniform over the feasible actions: the arg-max of masked uniform noise
        noise = self.rng.random(masks.shape)
        return np.argmax(np.where(masks > 0, noise, -1.0), axis=1)
