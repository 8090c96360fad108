"""TD3 agent (cdr-bench agent protocol), trained by ``cdr-bench train td3``.

``checkpoint.pt`` beside this file (or ``CDR_BENCH_CHECKPOINT``) holds the actor's weights only,
exported from the SB3 model (:func:`cdr_bench.rl.sb3_policies.export_actor`: Linear+ReLU x 3,
Linear, Tanh) and read with ``torch.load(weights_only=True)``; no SB3 zip is shipped (those
unpickle). Decision (paper §5.2): the deterministic actor's (a_psi, a_v, a_h) in [-1, 1]^3,
computed on the fixed numeric path of :mod:`cdr_bench.inference` (same bits on every x86-64
CPU; torch only reads the file), each component rounded to -1 / 0 / +1 (thresholds at -0.5 and
+0.5) and encoded as the action index (:func:`cdr_bench.rl.baselines.continuous_to_index`).

Unmasked, as the paper's TD3: a rounded climb at level 2 (or descent at level 0) is executed
without its level change and counted by the evaluator as an invalid action.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch

from cdr_bench.inference import MLP
from cdr_bench.rl.baselines import continuous_to_index

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
        if config.get("kind") != "td3":
            raise ValueError(f"{self.checkpoint}: not a TD3 actor (kind {config.get('kind')!r})")
        self.net = MLP.from_state_dict(state, "", "relu", out_activation="tanh")

    def reset(self, seed: int | None = None) -> None:
        """Deterministic policy: nothing to re-seed."""

    def act_batch(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        return continuous_to_index(self.net(observations))

    def act(self, obs_dict: dict) -> int:
        return int(self.act_batch(obs_dict["observation"][None], obs_dict["action_mask"][None])[0])
