"""Safe-DQN-X (:mod:`cdr_bench.rl.safe_dqn`): safety and goal Q networks on the off-policy loop
of :mod:`cdr_bench.rl.offpolicy`.

    cdr-bench train safe-dqn-x --run-dir runs/safe-dqn-x --total-steps 200000

Same environment, observation and reward as Diffusion-AC (the replay keeps the goal and the
safety part apart), gamma 0.99, width 128. Exploration is epsilon-greedy over the feasible
actions (a random feasible action with probability epsilon, annealed linearly), otherwise the
combination rule (``--combine``). ``checkpoint.pt`` is loaded by agents/safe_dqn_x/agent.py.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from cdr_bench.errors import UserError
from cdr_bench.rl.common import linear_schedule, same_named
from cdr_bench.rl.offpolicy import OffPolicyAlgorithm, OffPolicyArgs

if TYPE_CHECKING:
    from cdr_bench.rl.safe_dqn import SafeDQN

# torch is imported inside build(): building the cdr-bench parser must not import it.
RULES = ("sum", "lexicographic", "mvp-improve")
"""Combination rules (:data:`cdr_bench.rl.safe_dqn.RULES`; a test checks)."""


@dataclass
class Args(OffPolicyArgs):
    run_dir: str = "runs/safe-dqn-x"
    width: int = 128
    """hidden width of each Q network (three hidden layers)"""
    lr: float = 1e-4
    """Adam step size"""
    combine: str = "sum"
    """combination rule of the two Q networks: "sum", "lexicographic" or "mvp-improve" (one
    step of policy improvement on mvp; see safe_dqn.py)"""
    slack: float = 0.1
    """lexicographic: actions within this of the best safety Q count as safe; mvp-improve: the
    safety-Q gain over mvp's action needed to deviate from it"""
    base_policy: str = ""
    """mvp-improve only: a checkpoint.pt of an earlier improvement step (trained with --combine
    mvp-improve); the networks then evaluate and improve that policy instead of mvp alone (a
    further step of policy iteration). Empty: mvp"""
    eps_start: float = 1.0
    """epsilon of epsilon-greedy at the start"""
    eps_end: float = 0.05
    """epsilon after the annealing"""
    eps_fraction: float = 0.25
    """fraction of total_steps over which epsilon anneals linearly"""

    def __post_init__(self) -> None:
        if self.combine not in RULES:
            raise ValueError(f"--combine must be one of {RULES}, got {self.combine!r}")
        if self.base_policy and self.combine != "mvp-improve":
            raise ValueError(
                "--base-policy is a step of policy improvement: it needs "
                f"--combine mvp-improve, got --combine {self.combine}"
            )


def base_steps(path: str, obs_dim: int) -> list[dict[str, Any]]:
    """The improvement steps of the ``mvp-improve`` checkpoint at ``path``, first step first
    (its own ``"base"``, then itself): what ``--base-policy`` evaluates and improves. Each step
    is checked (rule, observation size, networks) before training starts."""
    import torch

    from cdr_bench.inference import SafeDQNQ

    if not os.path.isfile(path):
        raise UserError(
            f"--base-policy {path}: no such file (a checkpoint.pt trained with "
            "--combine mvp-improve)"
        )
    try:
        ck = torch.load(path, map_location="cpu", weights_only=True)
        steps = [*ck.get("base", []), {"config": ck["config"], "state_dict": ck["state_dict"]}]
    except Exception as e:  # a file that is not a checkpoint: say so, not a traceback
        raise UserError(f"--base-policy {path}: not a cdr-bench checkpoint.pt ({e})") from None
    for k, step in enumerate(steps, 1):
        where = f"--base-policy {path}" + (f", step {k} of {len(steps)}" if len(steps) > 1 else "")
        try:
            config, _ = dict(step["config"]), dict(step["state_dict"])  # both mappings
        except Exception:
            raise UserError(f"{where}: not a step of a cdr-bench checkpoint.pt") from None
        if config.get("rule") != "mvp-improve":
            raise UserError(
                f"{where}: not trained with --combine mvp-improve (rule {config.get('rule')!r})"
            )
        if config.get("obs_dim") != obs_dim:
            raise UserError(
                f"{where}: observations of {config.get('obs_dim')} features, this "
                f"environment's have {obs_dim}"
            )
        try:
            SafeDQNQ.from_step(step)
        except Exception as e:
            raise UserError(f"{where}: its networks do not load ({e!r})") from None
    return steps


def build(
    args: Args, obs_dim: int, rng: np.random.Generator | None = None, device: Any = "cpu"
) -> SafeDQN:
    from cdr_bench.rl.safe_dqn import SafeDQN, SafeDQNConfig

    epsilon = functools.partial(
        linear_schedule, args.eps_start, args.eps_end, args.eps_fraction * args.total_steps
    )
    cfg = SafeDQNConfig(**same_named(args, SafeDQNConfig, obs_dim=obs_dim, rule=args.combine))
    base = base_steps(args.base_policy, obs_dim) if args.base_policy else None
    return SafeDQN(
        cfg,
        **same_named(args, ("lr", "gamma", "polyak"), epsilon=epsilon, rng=rng, base_steps=base),
        device=device,
    )


ALGORITHM = OffPolicyAlgorithm("safe-dqn-x", "Safe-DQN-X", Args, build)
add_arguments, run = ALGORITHM.add_arguments, ALGORITHM.run

if __name__ == "__main__":
    raise SystemExit(ALGORITHM.main())
