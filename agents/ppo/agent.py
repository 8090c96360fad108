"""PPO agent (cdr-bench agent protocol), trained by ``cdr-bench train ppo``.

``checkpoint.pt`` beside this file (or ``CDR_BENCH_CHECKPOINT``) holds the actor's weights only,
exported from the SB3 model and read with ``torch.load(weights_only=True)`` into the layers
rebuilt by :func:`cdr_bench.rl.sb3_policies.load_actor` (no SB3 zip is shipped: those unpickle).
Decision: argmax of the logits (SB3's ``deterministic=True``).

Unmasked, as the paper's PPO: the mask is ignored, so at level 2 the policy may pick a climb
(or a descent at level 0). The environment then executes the heading and speed parts, not the
level change, and the evaluator counts the decision as invalid (``invalid_action_rate``).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch

from cdr_bench.rl.sb3_policies import load_actor

DEFAULT_CHECKPOINT = Path(__file__).with_name("checkpoint.pt")


class Agent:
    def __init__(self, observation_space=None, action_space=None, checkpoint: str | None = None):
        self.checkpoint = (
            checkpoint or os.environ.get("CDR_BENCH_CHECKPOINT") or str(DEFAULT_CHECKPOINT)
        )
        self.net, _ = load_actor(self.checkpoint)

    def reset(self, seed: int | None = None) -> None:
        """Deterministic policy: nothing to re-seed."""

    def act_batch(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        obs = torch.as_tensor(np.asarray(observations, dtype=np.float32))
        with torch.no_grad():
            return self.net(obs).argmax(1).numpy().astype(np.int64)

    def act(self, obs_dict: dict) -> int:
        return int(self.act_batch(obs_dict["observation"][None], obs_dict["action_mask"][None])[0])
