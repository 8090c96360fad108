"""Safe-DQN-X agent (cdr-bench agent protocol), trained by ``cdr-bench train safe-dqn-x``.

Loads ``checkpoint.pt`` beside this file (or the path in ``CDR_BENCH_CHECKPOINT``), a plain
``{"config", "state_dict", "meta"}`` file read with ``torch.load(weights_only=True)``, into the
network rebuilt by :func:`cdr_bench.rl.safe_dqn.load_net`. Decision: the combination rule
stored in the checkpoint (:func:`cdr_bench.rl.safe_dqn.combine`) of the safety and goal Q
networks over the feasible actions only -- deterministic, and never a masked action.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch

from cdr_bench.rl.safe_dqn import load_net

DEFAULT_CHECKPOINT = Path(__file__).with_name("checkpoint.pt")


class Agent:
    def __init__(self, observation_space=None, action_space=None, checkpoint: str | None = None):
        self.checkpoint = (
            checkpoint or os.environ.get("CDR_BENCH_CHECKPOINT") or str(DEFAULT_CHECKPOINT)
        )
        self.net = load_net(self.checkpoint)

    def reset(self, seed: int | None = None) -> None:
        """Deterministic policy: nothing to re-seed."""

    def act_batch(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        obs = torch.as_tensor(np.asarray(observations, dtype=np.float32))
        mask = torch.as_tensor(np.asarray(masks, dtype=np.int8))
        return self.net.act(obs, mask).numpy().astype(np.int64)

    def act(self, obs_dict: dict) -> int:
        return int(self.act_batch(obs_dict["observation"][None], obs_dict["action_mask"][None])[0])
