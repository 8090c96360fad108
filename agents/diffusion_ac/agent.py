"""Diffusion-AC agent (cdr-bench agent protocol).

Loads ``checkpoint.pt`` beside this file, or the path in the environment variable
``CDR_BENCH_CHECKPOINT`` (that is how the ablation checkpoints in ``ablations/`` are scored with
this same file). The checkpoint is ``{"config": {...}, "state_dict": ..., "meta": {...}}`` and is
read with ``torch.load(weights_only=True)``.

Inference follows the paper (§4.2.2): y_T ~ N(0, I), T reverse steps, masked softmax (Eq. 33),
argmax. The only randomness is y_T (and the reverse-step noise), drawn from a torch generator
seeded by :meth:`reset`. Diffusion actors run on the numpy inference path
(:mod:`cdr_bench.rl.fast_policy`, same arithmetic and random stream as the PyTorch module, ~3x
faster at batch 1); the categorical actor of the "without diffusion" ablation runs in PyTorch.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch

from cdr_bench.rl.diffusion_ac import load_policy
from cdr_bench.rl.fast_policy import FastDiffusionPolicy

DEFAULT_CHECKPOINT = Path(__file__).with_name("checkpoint.pt")


class Agent:
    def __init__(self, observation_space=None, action_space=None, checkpoint: str | None = None):
        path = checkpoint or os.environ.get("CDR_BENCH_CHECKPOINT") or str(DEFAULT_CHECKPOINT)
        self.checkpoint = path
        self.policy = load_policy(path)
        self.fast = (
            FastDiffusionPolicy(self.policy) if self.policy.cfg.actor == "diffusion" else None
        )
        self.generator = torch.Generator().manual_seed(0)

    def reset(self, seed: int | None = None) -> None:
        self.generator.manual_seed(0 if seed is None else int(seed))

    def act_batch(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        if self.fast is not None:
            return self.fast.act(observations, masks, self.generator)
        obs = torch.as_tensor(np.asarray(observations, dtype=np.float32))
        mask = torch.as_tensor(np.asarray(masks, dtype=np.int8))
        with torch.no_grad():
            return self.policy.act(obs, mask, self.generator).numpy().astype(np.int64)

    def act(self, obs_dict: dict) -> int:
        a = self.act_batch(obs_dict["observation"][None], obs_dict["action_mask"][None])
        return int(a[0])
