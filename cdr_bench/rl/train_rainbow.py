"""Rainbow-DQN with action masks (:mod:`cdr_bench.rl.rainbow`) on the off-policy loop of
:mod:`cdr_bench.rl.offpolicy`.

    cdr-bench train rainbow --run-dir runs/rainbow --total-steps 200000

Same environment, observation and reward as Diffusion-AC, gamma 0.99, width 128; prioritised
n-step replay; the noisy nets explore. ``checkpoint.pt`` is loaded by agents/rainbow/agent.py.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from cdr_bench.rl.common import same_named
from cdr_bench.rl.offpolicy import OffPolicyAlgorithm, OffPolicyArgs
from cdr_bench.rl.replay import ReplayConfig

if TYPE_CHECKING:
    from cdr_bench.rl.rainbow import Rainbow

# torch is imported inside build(): building the cdr-bench parser must not import it.


@dataclass
class Args(OffPolicyArgs):
    run_dir: str = "runs/rainbow"
    width: int = 128
    """hidden width (three hidden layers)"""
    n_atoms: int = 51
    """C51 atoms"""
    v_min: float = -20.0
    """lowest atom of the return support"""
    v_max: float = 5.0
    """highest atom of the return support"""
    sigma0: float = 0.5
    """noisy-net initial noise scale"""
    n_step: int = 3
    """n of the n-step return"""
    alpha: float = 0.5
    """prioritised replay exponent"""
    beta_start: float = 0.4
    """importance-sampling exponent at the start, annealed linearly to 1 at total_steps"""
    lr: float = 1e-4
    """Adam step size"""

    def __post_init__(self) -> None:
        if not self.v_min < self.v_max:
            raise ValueError(f"--v-min {self.v_min:g} must be below --v-max {self.v_max:g}")


def build(
    args: Args, obs_dim: int, rng: np.random.Generator | None = None, device: Any = "cpu"
) -> Rainbow:
    from cdr_bench.rl.rainbow import Rainbow, RainbowConfig

    cfg = RainbowConfig(**same_named(args, RainbowConfig, obs_dim=obs_dim))
    return Rainbow(cfg, **same_named(args, ("lr", "polyak")), device=device)


def replay(args: Args) -> ReplayConfig:
    return ReplayConfig(n_step=args.n_step, alpha=args.alpha, beta_start=args.beta_start)


ALGORITHM = OffPolicyAlgorithm("rainbow", "Rainbow-DQN", Args, build, replay)
add_arguments, run = ALGORITHM.add_arguments, ALGORITHM.run

if __name__ == "__main__":
    raise SystemExit(ALGORITHM.main())
