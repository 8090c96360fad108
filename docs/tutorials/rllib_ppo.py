"""Tutorial "Train with RLlib": multi-agent PPO with one shared, action-masked policy for the
ownship and the learning intruders of ``marl/low-2``, on cdr-bench's RLlib adapter
(:class:`cdr_bench.scale.rllib_env.CDRMultiAgentEnv`); then a checkpoint, and the trained policy
flown greedily on fresh episodes. Needs the ray extra (``pip install -e ".[ray]"``).

    python docs/tutorials/rllib_ppo.py                                    # 50 iterations
    python docs/tutorials/rllib_ppo.py --iterations 1 --batch 128 --eval-episodes 2   # smoke run
"""

from __future__ import annotations

import argparse
import collections
import json
from pathlib import Path
from typing import Any

import numpy as np
import ray
import torch
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.core.columns import Columns
from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
from ray.rllib.core.rl_module.rl_module import RLModuleSpec
from ray.rllib.examples.rl_modules.classes.action_masking_rlm import ActionMaskingTorchRLModule
from ray.tune.logger import UnifiedLogger

from cdr_bench.scale.rllib_env import CDRMultiAgentEnv


def ppo_config(scenario: str, batch: int, minibatch: int, seed: int) -> PPOConfig:
    return (
        PPOConfig()
        # The adapter: every possible agent has a space; observations are
        # {"observations": (42,) float32, "action_mask": (27,) float32}, the keys of RLlib's
        # action-masking module (infeasible actions get a logit of -inf).
        .environment(CDRMultiAgentEnv, env_config={"scenario": scenario})
        .env_runners(num_env_runners=0, rollout_fragment_length="auto")  # sample in-process
        .multi_agent(
            policies={"shared"},
            # parameter sharing: the ownship and every intruder act through one module
            policy_mapping_fn=lambda agent_id, episode, **kwargs: "shared",
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
        .training(train_batch_size_per_learner=batch, minibatch_size=minibatch, num_epochs=4)
        .debugging(seed=seed)
    )


def fly(module: Any, scenario: str, episodes: int, seed: int) -> dict[str, dict[str, int]]:
    """Outcomes per agent of ``episodes`` episodes flown by the module's greedy (masked) action."""
    env = CDRMultiAgentEnv({"scenario": scenario})
    outcomes: dict[str, collections.Counter[str]] = collections.defaultdict(collections.Counter)
    for episode in range(episodes):
        obs, infos = env.reset(seed=seed + episode)
        done = {"__all__": False}
        while not done["__all__"]:
            agents = sorted(obs)
            batch = {
                Columns.OBS: {
                    key: torch.as_tensor(np.stack([obs[a][key] for a in agents]))
                    for key in ("observations", "action_mask")
                }
            }
            with torch.no_grad():
                logits = module.forward_inference(batch)[Columns.ACTION_DIST_INPUTS]
            actions = dict(zip(agents, logits.argmax(-1).tolist(), strict=True))
            obs, rewards, done, truncated, infos = env.step(actions)
            done = {"__all__": done["__all__"] or truncated["__all__"]}
            for agent, info in infos.items():
                if "outcome" in info:
                    outcomes[agent][info["outcome"]] += 1
            obs = {a: o for a, o in obs.items() if a in env.agents}
    return {agent: dict(counts) for agent, counts in sorted(outcomes.items())}


def main(argv: list[str] | None = None) -> dict[str, Any]:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="marl/low-2", help="a scenario with learning intruders")
    p.add_argument("--iterations", type=int, default=50)
    p.add_argument("--batch", type=int, default=4000, help="env steps per iteration")
    p.add_argument(
        "--minibatch", type=int, default=None, help="SGD minibatch (default: 256, at most --batch)"
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--eval-episodes", type=int, default=20)
    p.add_argument("--out", default="runs/rllib-tutorial", help="RLlib's logs and the checkpoint")
    a = p.parse_args(argv)
    minibatch = min(256, a.batch) if a.minibatch is None else a.minibatch
    if not 0 < minibatch <= a.batch:
        p.error(f"--minibatch must be in 1..--batch ({a.batch}), got {minibatch}")
    out = Path(a.out).resolve()
    out.mkdir(parents=True, exist_ok=True)

    torch.set_num_threads(1)  # one thread: sampling and the learner run in this process
    ray.init(num_cpus=1, include_dashboard=False, logging_level="ERROR", log_to_driver=False)
    algo = ppo_config(a.scenario, a.batch, minibatch, a.seed).build_algo(
        logger_creator=lambda cfg: UnifiedLogger(cfg, str(out / "logs"), loggers=None)
    )
    try:
        for i in range(1, a.iterations + 1):
            r = algo.train()
            runners = r["env_runners"]
            row = {
                "iteration": i,
                "env_steps": r["num_env_steps_sampled_lifetime"],
                "episode_return_mean": runners.get("episode_return_mean"),
                "episode_len_mean": runners.get("episode_len_mean"),
                "agent_return_mean": runners.get("agent_episode_returns_mean"),
            }
            print(json.dumps(row), flush=True)
        checkpoint = algo.save(str(out / "checkpoint")).checkpoint.path
        module = algo.get_module("shared")
        outcomes = fly(module, a.scenario, a.eval_episodes, seed=a.seed + 10_000)
    finally:
        algo.stop()
        ray.shutdown()
    summary = {"env_steps": row["env_steps"], "checkpoint": checkpoint, "outcomes": outcomes}
    print(json.dumps(summary), flush=True)
    return summary


if __name__ == "__main__":
    main()
