"""The policy of the tutorial "PPO on the vector env" (``docs/tutorials/ppo_vector_env.py``) as a
cdr-bench agent.

``policy.pt`` beside this file (or the file named by ``CDR_BENCH_CHECKPOINT``, which the
tutorial sets to score the policy it has just trained) is the state dict of the tutorial's
``ActorCritic``, read with ``torch.load(weights_only=True)``. Only the actor is used: its
``actor.<i>`` Linear layers (Tanh between them) give 27 logits, and the decision is the argmax
of the masked logits (never a masked action), computed with :mod:`cdr_bench.inference` (numpy,
the same bits on every x86-64 CPU; torch only reads the file, on one thread).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import torch

from cdr_bench.inference import MLP, masked_argmax

DEFAULT_CHECKPOINT = Path(__file__).with_name("policy.pt")


class Agent:
    def __init__(self, observation_space: Any = None, action_space: Any = None):
        torch.set_num_threads(1)  # one thread per process (the evaluator runs one per worker)
        path = os.environ.get("CDR_BENCH_CHECKPOINT") or str(DEFAULT_CHECKPOINT)
        state = torch.load(path, map_location="cpu", weights_only=True)
        actor = {k: v.numpy() for k, v in state.items() if k.startswith("actor.")}
        self.net = MLP.from_state_dict(actor, "actor.", "tanh")

    def reset(self, seed: int | None = None) -> None:
        """Deterministic policy: nothing to re-seed."""

    def act_batch(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        return masked_argmax(self.net(observations), masks)

    def act(self, observation: dict[str, np.ndarray]) -> int:
        o, m = observation["observation"][None], observation["action_mask"][None]
        return int(self.act_batch(o, m)[0])
