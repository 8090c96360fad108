"""Safe-DQN-X agent (cdr-bench agent protocol), trained by ``cdr-bench train safe-dqn-x``.

Loads ``checkpoint.pt`` beside this file (or the path in ``CDR_BENCH_CHECKPOINT``), a plain
``{"config", "state_dict", "meta"}`` file of :class:`cdr_bench.rl.safe_dqn.SafeDQNNet` read with
``torch.load(weights_only=True)``. Decision: the combination rule stored in the checkpoint (as
:func:`cdr_bench.rl.safe_dqn.combine`) of the safety and goal Q networks over the feasible
actions only -- deterministic, and never a masked action. Computed on the fixed numeric path of
:mod:`cdr_bench.inference` (same bits on every x86-64 CPU; torch only reads the file).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch

from cdr_bench.inference import SafeDQNQ

DEFAULT_CHECKPOINT = Path(__file__).with_name("checkpoint.pt")


def load_checkpoint(path: str) -> tuple[dict, dict[str, np.ndarray]]:
    """(config, state dict as numpy arrays) of a weights-only checkpoint."""
    ck = torch.load(path, map_location="cpu", weights_only=True)
    return ck["config"], {k: v.detach().cpu().numpy() for k, v in ck["state_dict"].items()}


class Agent:
    def __init__(self, observation_space=None, action_space=None, checkpoint: str | None = None):
        self.checkpoint = (
            checkpoint or os.environ.get("CDR_BENCH_CHECKPOINT") or str(DEFAULT_CHECKPOINT)
        )
        config, state = load_checkpoint(self.checkpoint)
        self.net = SafeDQNQ(state, config)

    def reset(self, seed: int | None = None) -> None:
        """Deterministic policy: nothing to re-seed."""

    def act_batch(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        return self.net.act(observations, masks)

    def act(self, obs_dict: dict) -> int:
        return int(self.act_batch(obs_dict["observation"][None], obs_dict["action_mask"][None])[0])
