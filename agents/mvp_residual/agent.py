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

from pathlib import Path
from typing import Any

from cdr_bench.inference import CheckpointActorAgent
from cdr_bench.resolvers import with_mvp_input


class Agent(CheckpointActorAgent):
    default_checkpoint = str(Path(__file__).with_name("checkpoint.pt"))
    missing = (
        "none is shipped (no residual is safer than mvp yet; agents/mvp_residual/README.md); "
        "train one with `cdr-bench train maskable-ppo --mvp-input --teacher agents/mvp ...` and "
        "point CDR_BENCH_CHECKPOINT at its checkpoint.pt"
    )

    def refuse(self, config: Any) -> str | None:
        if config.get("kind") != "ppo" or not config.get("mvp_input"):
            return (
                f"not a PPO actor trained with --mvp-input (kind {config.get('kind')!r}, "
                f"mvp_input {config.get('mvp_input')!r})"
            )
        return None

    def features(self, observations: Any, masks: Any) -> Any:
        return with_mvp_input(observations, masks)
