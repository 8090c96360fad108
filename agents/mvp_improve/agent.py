"""One step of policy improvement on ``mvp`` (cdr-bench agent protocol), trained by

    cdr-bench train safe-dqn-x --combine mvp-improve ...

Two Q networks (safety and goal reward, :class:`cdr_bench.rl.safe_dqn.SafeDQNNet`) that
*evaluate* the geometric resolver ``mvp``. The decision is ``mvp``'s action unless some feasible
action's safety Q exceeds that of ``mvp``'s action by more than the checkpoint's ``slack``; then
the largest Q_S + Q_G among those actions (:func:`cdr_bench.rl.safe_dqn.combine`, rule
``mvp-improve``). A checkpoint of a further step (``--base-policy``) also holds the earlier steps'
networks (``"base"``): ``mvp``, then each step in turn
(:func:`cdr_bench.inference.improved_actions`). ``checkpoint.pt`` beside this file (or
``CDR_BENCH_CHECKPOINT``) holds the weights only, read with ``torch.load(weights_only=True)``;
the margin is part of the checkpoint (``sweeps/mvp_improve_margin.py`` writes copies with other
margins and chooses one on episodes other than the scored ones). The networks run on the fixed
numeric path of :mod:`cdr_bench.inference` and ``mvp`` uses only correctly rounded arithmetic,
so the decision is the same on every x86-64 CPU.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch

from cdr_bench.inference import SafeDQNQ, improved_actions
from cdr_bench.resolvers import mvp_actions

DEFAULT_CHECKPOINT = Path(__file__).with_name("checkpoint.pt")


class Agent:
    def __init__(self, observation_space=None, action_space=None, checkpoint: str | None = None):
        self.checkpoint = (
            checkpoint or os.environ.get("CDR_BENCH_CHECKPOINT") or str(DEFAULT_CHECKPOINT)
        )
        if not os.path.isfile(self.checkpoint):
            raise FileNotFoundError(
                f"no checkpoint at {self.checkpoint}: the shipped one is agents/mvp_improve/"
                "checkpoint.pt; train another with `cdr-bench train safe-dqn-x --combine "
                "mvp-improve ...` (agents/mvp_improve/README.md) and point CDR_BENCH_CHECKPOINT "
                "at its checkpoint.pt"
            )
        ck = torch.load(self.checkpoint, map_location="cpu", weights_only=True)
        config = ck["config"]
        if config.get("rule") != "mvp-improve":
            raise ValueError(
                f"{self.checkpoint}: not trained with --combine mvp-improve "
                f"(rule {config.get('rule')!r})"
            )
        steps = [*ck.get("base", []), {"config": config, "state_dict": ck["state_dict"]}]
        self.steps = [SafeDQNQ.from_step(s) for s in steps]

    def reset(self, seed: int | None = None) -> None:
        """Deterministic policy: nothing to re-seed."""

    def act_batch(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        return improved_actions(self.steps, observations, masks, mvp_actions(observations, masks))

    def act(self, obs_dict: dict) -> int:
        return int(self.act_batch(obs_dict["observation"][None], obs_dict["action_mask"][None])[0])
