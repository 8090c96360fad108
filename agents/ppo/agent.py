"""PPO agent (cdr-bench agent protocol), trained by ``cdr-bench train ppo``.

``checkpoint.pt`` beside this file (or ``CDR_BENCH_CHECKPOINT``) holds the actor's weights only,
exported from the SB3 model (:func:`cdr_bench.rl.sb3_policies.export_actor`: Linear+Tanh x 3,
Linear -> 27 logits) and read with ``torch.load(weights_only=True)``; no SB3 zip is shipped
(those unpickle). Decision: argmax of the logits (SB3's ``deterministic=True``), computed on the
fixed numeric path of :mod:`cdr_bench.inference` (same bits on every x86-64 CPU; torch only
reads the file).

Unmasked, as the paper's PPO: the mask is ignored, so at level 2 the policy may pick a climb
(or a descent at level 0). The environment then executes the heading and speed parts, not the
level change, and the evaluator counts the decision as invalid (``invalid_action_rate``).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch

from cdr_bench.inference import MLP, masked_argmax

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
        if config.get("kind") != "ppo":
            raise ValueError(f"{self.checkpoint}: not a PPO actor (kind {config.get('kind')!r})")
        self.net = MLP.from_state_dict(state, "", "tanh")

    def reset(self, seed: int | None = None) -> None:
        """Deterministic policy: nothing to re-seed."""

    def act_batch(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        return masked_argmax(self.net(observations), None)

    def act(self, obs_dict: dict) -> int:
        return int(self.act_batch(obs_dict["observation"][None], obs_dict["action_mask"][None])[0])
