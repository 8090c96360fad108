"""A learned residual on top of ``mvp`` (cdr-bench agent protocol): a MaskablePPO actor whose
input is the observation with the one-hot of ``mvp``'s action appended
(:func:`cdr_bench.resolvers.with_mvp_input`, the same function the trainer used), trained by

    cdr-bench train maskable-ppo --mvp-input --teacher agents/mvp ...

It starts as a copy of ``mvp`` (behaviour cloning on the one-hot input) and RL decides where to
deviate from it. ``checkpoint.pt`` beside this file (or ``CDR_BENCH_CHECKPOINT``) holds the
actor's weights only (config ``mvp_input: true``), read with ``torch.load(weights_only=True)``.
Decision: argmax of the masked logits on the fixed numeric path of :mod:`cdr_bench.inference`;
``mvp`` itself uses only correctly rounded arithmetic, so the whole decision is the same on every
x86-64 CPU.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch

from cdr_bench.inference import MLP, masked_argmax
from cdr_bench.resolvers import with_mvp_input

DEFAULT_CHECKPOINT = Path(__file__).with_name("checkpoint.pt")


class Agent:
    def __init__(self, observation_space=None, action_space=None, checkpoint: str | None = None):
        self.checkpoint = (
            checkpoint or os.environ.get("CDR_BENCH_CHECKPOINT") or str(DEFAULT_CHECKPOINT)
        )
        if not os.path.isfile(self.checkpoint):
            raise FileNotFoundError(
                f"no checkpoint at {self.checkpoint}: none is shipped (no residual is safer than "
                "mvp yet; agents/mvp_residual/README.md); train one with `cdr-bench train "
                "maskable-ppo --mvp-input --teacher agents/mvp ...` and point "
                "CDR_BENCH_CHECKPOINT at its checkpoint.pt"
            )
        ck = torch.load(self.checkpoint, map_location="cpu", weights_only=True)
        config = ck["config"]
        if config.get("kind") != "ppo" or not config.get("mvp_input"):
            raise ValueError(
                f"{self.checkpoint}: not a PPO actor trained with --mvp-input "
                f"(kind {config.get('kind')!r}, mvp_input {config.get('mvp_input')!r})"
            )
        state = {k: v.detach().cpu().numpy() for k, v in ck["state_dict"].items()}
        self.net = MLP.from_state_dict(state, "", "tanh")

    def reset(self, seed: int | None = None) -> None:
        """Deterministic policy: nothing to re-seed."""

    def act_batch(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        return masked_argmax(self.net(with_mvp_input(observations, masks)), masks)

    def act(self, obs_dict: dict) -> int:
        return int(self.act_batch(obs_dict["observation"][None], obs_dict["action_mask"][None])[0])
