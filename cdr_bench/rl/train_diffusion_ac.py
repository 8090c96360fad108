"""Diffusion-AC with DPSC (Algorithm 2) on the off-policy loop of :mod:`cdr_bench.rl.offpolicy`.

    python -m cdr_bench.rl.train_diffusion_ac --run-dir runs/dac --total-steps 200000
    cdr-bench train diffusion-ac --run-dir runs/dac --total-steps 200000

Algorithm 1 (one update) and the policy: :mod:`cdr_bench.rl.diffusion_ac`. Outputs in
``run_dir`` as every off-policy trainer; ``checkpoint.pt`` is loaded by
agents/diffusion_ac/agent.py.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from cdr_bench.rl.common import same_named
from cdr_bench.rl.curriculum import N_STAGES
from cdr_bench.rl.offpolicy import OffPolicyAlgorithm, OffPolicyArgs

if TYPE_CHECKING:
    from cdr_bench.rl.diffusion_ac import DiffusionAC

# torch is imported inside build(), so that building the ``cdr-bench`` parser (which lists this
# trainer's flags) never imports it: ``cdr-bench evaluate`` stays torch-free.
SCHEDULES = ("linear", "cosine")
"""Noise schedules (the names of :data:`cdr_bench.rl.diffusion.SCHEDULES`; a test checks)."""

ABLATIONS = ("none", "no-diffusion", "no-double-q", "no-dpsc", "no-value-guidance")
CHOICES = {
    "ablation": ABLATIONS,
    "schedule": SCHEDULES,
    "ce_input": ("y0", "noise", "none"),
    "diffusion_target": ("teacher", "sample"),
    "explore": ("sample", "argmax"),
}


@dataclass
class Args(OffPolicyArgs):
    run_dir: str = "runs/diffusion-ac"
    total_steps: int = 1_000_000
    checkpoint_every: int = 100_000
    ablation: str = "none"
    """one of: none, no-diffusion, no-double-q, no-dpsc, no-value-guidance (Table 3; no-dpsc
    turns the curriculum off)"""
    T: int = 10
    """diffusion steps"""
    schedule: str = "cosine"
    """noise schedule: "linear" (paper literal, alpha_bar_T ~ 0.90) or "cosine" (alpha_bar_T ~ 0)"""
    width: int = 128
    """denoiser width (divisible by the 8 attention heads)"""
    n_blocks: int = 2
    """residual blocks in the denoiser"""
    critic_width: int = 128
    """critic hidden width (three layers)"""
    tau_start: float = 0.5
    """teacher temperature at stage 1"""
    tau_end: float = 0.2
    """teacher temperature at stage 12 (geometric in between); also the fixed tau without DPSC"""
    tau_relative: bool = True
    """tau in units of the per-state std of Q over feasible actions (False = Eq. 37 literal)"""
    diffusion_target: str = "teacher"
    """denoiser target: teacher (Eq. 38 literal, log p*) or sample (log one-hot of a ~ p*)"""
    eps_smooth: float = 0.01
    """label smoothing epsilon of Eq. 38"""
    ce_input: str = "y0"
    """terminal-CE input: y0 (Eq. 39 literal), noise (y_T ~ N(0, I) at t = T) or none"""
    ce_weight: float = 0.1
    """lambda_CE of Eq. 39"""
    lr_actor: float = 3e-4
    """Adam step size of the denoiser"""
    lr_critic: float = 1e-3
    """Adam step size of the critics"""
    q_target_max: float = math.inf
    """clip the critics' TD target at this value (inf: off; 1.0 = the largest return the reward
    allows, the goal term)"""
    explore: str = "sample"
    """action selection while training: "sample" from the masked softmax or "argmax" (paper)"""
    extra: dict = field(default_factory=dict)
    """free-form notes stored in args.json"""

    def __post_init__(self) -> None:
        for name, allowed in CHOICES.items():
            if getattr(self, name) not in allowed:
                raise ValueError(f"{name} must be one of {allowed}, got {getattr(self, name)!r}")
        from cdr_bench.rl.diffusion_ac import PolicyConfig

        heads = PolicyConfig.n_heads  # the denoiser's attention (not the no-diffusion actor)
        if self.ablation != "no-diffusion" and self.width % heads:
            raise ValueError(
                f"--width {self.width}: must be divisible by the {heads} attention heads"
            )
        if self.ablation == "no-dpsc":
            self.curriculum = False


def teacher_tau(args: Args, stage: int | None) -> float:
    """Temperature schedule: geometric from tau_start (stage 1) to tau_end (stage 12);
    tau_end without the curriculum; infinity without value guidance."""
    if args.ablation == "no-value-guidance":
        return math.inf
    if stage is None:
        return args.tau_end
    frac = (stage - 1) / (N_STAGES - 1)
    return args.tau_start * (args.tau_end / args.tau_start) ** frac


def build(
    args: Args, obs_dim: int, rng: np.random.Generator | None = None, device: Any = "cpu"
) -> DiffusionAC:
    from cdr_bench.rl.diffusion_ac import DiffusionAC, PolicyConfig, UpdateConfig

    actor = "categorical" if args.ablation == "no-diffusion" else "diffusion"
    twin = args.ablation != "no-double-q"
    pcfg = PolicyConfig(**same_named(args, PolicyConfig, obs_dim=obs_dim, actor=actor, twin=twin))
    ucfg = UpdateConfig(**same_named(args, UpdateConfig))
    tau = functools.partial(teacher_tau, args)
    return DiffusionAC(pcfg, ucfg, seed=args.seed, explore=args.explore, tau=tau, device=device)


ALGORITHM = OffPolicyAlgorithm("diffusion-ac", "Diffusion-AC", Args, build)
add_arguments, run = ALGORITHM.add_arguments, ALGORITHM.run

if __name__ == "__main__":
    raise SystemExit(ALGORITHM.main())
