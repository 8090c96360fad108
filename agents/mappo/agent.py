"""MAPPO agent (cdr-bench agent protocol): one shared actor for every controlled aircraft, trained
by ``cdr-bench train mappo`` (:mod:`cdr_bench.rl.mappo`; README.md beside this file).

``checkpoint.pt`` beside this file (or ``CDR_BENCH_CHECKPOINT``, e.g. ``seeds/2/checkpoint.pt``)
holds the actor's weights only (Linear+Tanh x layers, Linear -> 27 logits), read with
``torch.load(weights_only=True)``; the centralised critic was used in training only. Each
aircraft decides on its own observation (decentralised execution). Decision: argmax of the
masked logits -- never a masked action -- computed on the fixed numeric path of
:mod:`cdr_bench.inference` (same bits on every x86-64 CPU; torch only reads the file).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch

from cdr_bench.inference import MLP, masked_argmax

DEFAULT_CHECKPOINT = Path(__file__).with_name("checkpoint.pt")
ALGORITHM = "mappo"


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
        if config.get("algorithm") != ALGORITHM:
            raise ValueError(
                f"{self.checkpoint}: not a {ALGORITHM} actor (algorithm "
                f"{config.get('algorithm')!r})"
            )
        self.net = MLP.from_state_dict(state, "", "tanh")

    def reset(self, seed: int | None = None) -> None:
        """Deterministic policy: nothing to re-seed."""

    def act_batch(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        return masked_argmax(self.net(observations), masks)

    def act(self, obs_dict: dict) -> int:
        return int(self.act_batch(obs_dict["observation"][None], obs_dict["action_mask"][None])[0])
