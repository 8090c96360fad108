"""Multi-agent PPO with parameter sharing on a scenario with learning intruders (RLlib).

The ownship and every learning intruder act through one shared, action-masked policy
(RLlib's ``ActionMaskingTorchRLModule`` on the new API stack), on the RLlib adapter
:class:`cdr_bench.scale.rllib_env.CDRMultiAgentEnv`. Needs the ray extra::

    pip install -e ".[ray]"
    python examples/rllib_ppo_shared.py --iterations 20            # ~ minutes on 2 CPUs
    python examples/rllib_ppo_shared.py --iterations 1 --batch 256  # a smoke run

Prints one line per iteration (mean episode return over all agents, episode length).
"""

from __future__ import annotations

import argparse
import json
from typing import Any


def build_config(scenario: str, batch: int, minibatch: int, seed: int) -> Any:
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec
    from ray.rllib.examples.rl_modules.classes.action_masking_rlm import (
        ActionMaskingTorchRLModule,
    )

    from cdr_bench.scale.rllib_env import CDRMultiAgentEnv

    return (
        PPOConfig()
        .environment(CDRMultiAgentEnv, env_config={"scenario": scenario})
        .env_runners(num_env_runners=0, rollout_fragment_length="auto")
        .multi_agent(
            policies={"shared"},
            # parameter sharing: every agent (ownship and intruders) maps to one module
            policy_mapping_fn=lambda agent_id, episode, **kw: "shared",
        )
        .rl_module(
            rl_module_spec=MultiRLModuleSpec(
                rl_module_specs={
                    "shared": RLModuleSpec(
                        module_class=ActionMaskingTorchRLModule,
                        model_config={"head_fcnet_hiddens": [64, 64]},
                    )
                }
            )
        )
        .training(train_batch_size_per_learner=batch, minibatch_size=minibatch, num_epochs=2)
        .debugging(seed=seed)
    )


def train(
    scenario: str = "marl/low-2",
    iterations: int = 1,
    batch: int = 256,
    minibatch: int = 64,
    seed: int = 0,
    logdir: str = "runs/rllib-ppo-shared",
) -> list[dict[str, Any]]:
    """Run PPO (RLlib's result logs in ``logdir``, not ~/ray_results); return one summary per
    iteration."""
    from pathlib import Path

    import ray
    from ray.tune.logger import UnifiedLogger

    started = not ray.is_initialized()
    if started:
        ray.init(num_cpus=1, include_dashboard=False, logging_level="ERROR", log_to_driver=False)
    Path(logdir).mkdir(parents=True, exist_ok=True)
    algo = build_config(scenario, batch, minibatch, seed).build_algo(
        logger_creator=lambda cfg: UnifiedLogger(cfg, logdir, loggers=None)
    )
    rows = []
    try:
        for i in range(iterations):
            r = algo.train()
            runners = r.get("env_runners", {})
            rows.append(
                {
                    "iteration": i + 1,
                    "env_steps": r.get("num_env_steps_sampled_lifetime"),
                    "episode_return_mean": runners.get("episode_return_mean"),
                    "episode_len_mean": runners.get("episode_len_mean"),
                    "agents": sorted(runners.get("agent_episode_returns_mean", {})),
                }
            )
            print(json.dumps(rows[-1]), flush=True)
    finally:
        algo.stop()
        if started:
            ray.shutdown()
    return rows


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="marl/low-2", help="a scenario with learning intruders")
    p.add_argument("--iterations", type=int, default=20)
    p.add_argument("--batch", type=int, default=2000, help="env steps per iteration")
    p.add_argument("--minibatch", type=int, default=128)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--logdir", default="runs/rllib-ppo-shared", help="RLlib's result logs")
    a = p.parse_args()
    train(a.scenario, a.iterations, a.batch, a.minibatch, a.seed, a.logdir)
