"""MaskablePPO agent (cdr-bench agent protocol), trained by ``cdr-bench train maskable-ppo``.

``checkpoint.pt`` beside this file (or ``CDR_BENCH_CHECKPOINT``) holds the actor's weights only,
exported from the SB3 model and read with ``torch.load(weights_only=True)`` into the layers
rebuilt by :func:`cdr_bench.rl.sb3_policies.load_actor` (no SB3 zip is shipped: those unpickle).
Decision: argmax of the masked logits (SB3's ``deterministic=True``) -- never a masked action.
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
        mask = torch.as_tensor(np.asarray(masks, dtype=np.int8))
        with torch.no_grad():
            logits = self.net(obs).masked_fill(mask == 0, -torch.inf)
        return logits.argmax(1).numpy().astype(np.int64)

    def act(self, obs_dict: dict) -> int:
        return int(self.act_batch(obs_dict["observation"][None], obs_dict["action_mask"][None])[0])
