"""Diffusion-AC agent (cdr-bench agent protocol).

Loads ``checkpoint.pt`` beside this file, or the path in the environment variable
``CDR_BENCH_CHECKPOINT`` (that is how the ablation checkpoints in ``ablations/`` are scored with
this same file). The checkpoint is ``{"config": {...}, "state_dict": ..., "meta": {...}}`` and is
read with ``torch.load(weights_only=True)``; torch does nothing else here.

Inference follows the paper (§4.2.2): y_T ~ N(0, I), T reverse steps, masked softmax (Eq. 33),
argmax. It runs on the fixed numeric path of :mod:`cdr_bench.inference` (numba loops in a fixed
order, no BLAS, no libm, no FMA), so an episode's actions are the same bits on every x86-64 CPU;
they equal the PyTorch module's to float rounding (``tests/rl/test_fast_policy.py``). The only
randomness is y_T and the reverse-step noise, drawn from ``numpy.random.Generator(PCG64)``
re-seeded by :meth:`reset`. The categorical actor of the "without diffusion" ablation runs on
the same path (no noise).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch

from cdr_bench.inference import DiffusionActor, new_generator

DEFAULT_CHECKPOINT = Path(__file__).with_name("checkpoint.pt")


def load_checkpoint(path: str) -> tuple[dict, dict[str, np.ndarray]]:
    """(config, state dict as numpy arrays) of a weights-only checkpoint."""
    ck = torch.load(path, map_location="cpu", weights_only=True)
    return ck["config"], {k: v.detach().cpu().numpy() for k, v in ck["state_dict"].items()}


class Agent:
    def __init__(self, observation_space=None, action_space=None, checkpoint: str | None = None):
        path = checkpoint or os.environ.get("CDR_BENCH_CHECKPOINT") or str(DEFAULT_CHECKPOINT)
        self.checkpoint = path
        self.config, state = load_checkpoint(path)
        self.actor = DiffusionActor(state, self.config)
        self.rng = new_generator(0)

    def reset(self, seed: int | None = None) -> None:
        self.rng = new_generator(seed)

    def act_batch(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        return self.actor.act(observations, masks, self.rng)

    def act(self, obs_dict: dict) -> int:
        a = self.act_batch(obs_dict["observation"][None], obs_dict["action_mask"][None])
        return int(a[0])
