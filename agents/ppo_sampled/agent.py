"""PPO that samples its action from the policy's categorical distribution (SB3's
``deterministic=False``) instead of taking the argmax as ``agents/ppo`` does.

It reads the PPO checkpoint (``agents/ppo/checkpoint.pt``, or ``CDR_BENCH_CHECKPOINT``): the
actor's weights only, read with ``torch.load(weights_only=True)``. It exists so that PPO's
multimodality (docs/model.md §10.4) is also measured on the policy PPO was trained with: the
argmax of a categorical policy has no randomness at all and reaches one manoeuvre per state by
construction. Draws come from ``numpy.random.Generator(PCG64(seed))`` re-seeded by
``reset(seed)``, the softmax weights on the fixed numeric path
(:func:`cdr_bench.inference.masked_sample`), so the same seed gives the same actions on every
CPU. Unmasked like ``agents/ppo``: masked level changes are not executed and are counted as
invalid.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch

from cdr_bench.inference import MLP, masked_sample

DEFAULT_CHECKPOINT = Path(__file__).resolve().parents[1] / "ppo" / "checkpoint.pt"


class Agent:
    def __init__(self, observation_space=None, action_space=None, checkpoint: str | None = None):
        self.checkpoint = (
            checkpoint or os.environ.get("CDR_BENCH_CHECKPOINT") or str(DEFAULT_CHECKPOINT)
        )
        ck = torch.load(self.checkpoint, map_location="cpu", weights_only=True)
        if ck["config"].get("kind") != "ppo":
            raise ValueError(
                f"{self.checkpoint}: not a PPO actor (kind {ck['config'].get('kind')!r})"
            )
        state = {k: v.detach().cpu().numpy() for k, v in ck["state_dict"].items()}
        self.net = MLP.from_state_dict(state, "", "tanh")
        self.rng = np.random.default_rng(0)

    def reset(self, seed: int | None = None) -> None:
        self.rng = np.random.default_rng(seed)

    def act_batch(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        return masked_sample(self.net(observations), None, self.rng)

    def act(self, obs_dict: dict) -> int:
        return int(self.act_batch(obs_dict["observation"][None], obs_dict["action_mask"][None])[0])
