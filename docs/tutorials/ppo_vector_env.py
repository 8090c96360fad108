"""Tutorial "PPO on the vector env": single-file PPO in the style of CleanRL's ``ppo.py``, on the
native Gymnasium vector env of cdr-bench, with a masked categorical policy.

    python docs/tutorials/ppo_vector_env.py                  # the full run: 1.2M steps of high
    python docs/tutorials/ppo_vector_env.py --total-timesteps 2048 --num-envs 8 --num-steps 32

Prints one JSON line per update, saves the policy's state dict (``--save``), then scores the
greedy policy with the package's evaluator (``cdr-bench evaluate`` of ``agents/ppo_tutorial``)
on validation episodes, with Direct and MVP on the same episodes, and prints the paired
differences in clean success (``cdr-bench compare``). Needs torch (the ``train`` extra).
One torch thread (``--threads``): the networks are small, the simulator is single-threaded.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from collections import deque
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from torch import nn
from torch.distributions import Categorical

import cdr_bench  # noqa: F401  (registers the cdr_bench/* Gymnasium ids)
from cdr_bench.evaluate.api import evaluate, resolve_jobs
from cdr_bench.evaluate.compare import compare, comparison_table
from cdr_bench.evaluate.report import summary_text
from cdr_bench.evaluate.results import read_result
from cdr_bench.evaluate.seeds import SPLITS
from cdr_bench.sim.core import REWARD_TERMS

AGENT = Path(__file__).resolve().parents[2] / "agents" / "ppo_tutorial" / "agent.py"
FAILURES = ("los", "nmac", "boundary")  # outcomes that end a flight before its goal
IN_LOS = [REWARD_TERMS.index("los"), REWARD_TERMS.index("nmac")]  # columns of reward_terms


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="high", help="trained on, and scored on")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--total-timesteps", type=int, default=1_200_000)
    p.add_argument("--num-envs", type=int, default=16, help="episodes stepped together")
    p.add_argument("--num-steps", type=int, default=128, help="steps per env per rollout")
    p.add_argument("--learning-rate", type=float, default=3e-4, help="annealed linearly to 0")
    p.add_argument("--gamma", type=float, default=0.99)
    p.add_argument("--gae-lambda", type=float, default=0.95)
    p.add_argument("--num-minibatches", type=int, default=8)
    p.add_argument("--update-epochs", type=int, default=10)
    p.add_argument("--clip-coef", type=float, default=0.2)
    p.add_argument("--ent-coef", type=float, default=0.01)
    p.add_argument("--vf-coef", type=float, default=0.5)
    p.add_argument("--max-grad-norm", type=float, default=0.5)
    p.add_argument("--width", type=int, default=64, help="hidden units (two Tanh layers)")
    p.add_argument(
        "--failure-penalty",
        type=float,
        default=5.0,
        help="training only: subtracted when the flight ends in NMAC or beyond the boundary",
    )
    p.add_argument(
        "--los-penalty",
        type=float,
        default=1.0,
        help="training only: subtracted from the reward at every step the ownship is in LoS",
    )
    p.add_argument("--threads", type=int, default=1, help="torch threads of this process")
    p.add_argument("--eval-episodes", type=int, default=1000, help="validation episodes")
    p.add_argument("--save", default="runs/ppo-vector-env/policy.pt", help="state dict")
    return p.parse_args(argv)


def layer_init(layer: nn.Linear, std: float = np.sqrt(2), bias: float = 0.0) -> nn.Linear:
    nn.init.orthogonal_(layer.weight, std)
    nn.init.constant_(layer.bias, bias)
    return layer


class ActorCritic(nn.Module):
    def __init__(self, n_obs: int, n_actions: int, width: int = 64):
        super().__init__()
        self.critic = nn.Sequential(
            layer_init(nn.Linear(n_obs, width)), nn.Tanh(),
            layer_init(nn.Linear(width, width)), nn.Tanh(),
            layer_init(nn.Linear(width, 1), std=1.0),
        )  # fmt: skip
        self.actor = nn.Sequential(
            layer_init(nn.Linear(n_obs, width)), nn.Tanh(),
            layer_init(nn.Linear(width, width)), nn.Tanh(),
            layer_init(nn.Linear(width, n_actions), std=0.01),
        )  # fmt: skip

    def value(self, obs: torch.Tensor) -> torch.Tensor:
        return self.critic(obs).squeeze(-1)

    def dist(self, obs: torch.Tensor, mask: torch.Tensor) -> Categorical:
        """The masked categorical: infeasible actions (mask 0) get probability 0."""
        logits = self.actor(obs).masked_fill(~mask, -1e8)
        return Categorical(logits=logits)


def main(argv: list[str] | None = None) -> dict[str, float]:
    args = parse_args(argv)
    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)  # 1: small networks, threads cost more than they bring
    batch_size = args.num_envs * args.num_steps
    minibatch_size = batch_size // args.num_minibatches
    num_updates = max(1, args.total_timesteps // batch_size)

    # The native vector env: observations (N, 42), masks in infos["action_mask"] (N, 27),
    # same-step auto-reset (the ended episode's outcome is in infos["final_info"]), and the
    # step's reward terms in infos["reward_terms"] (N, 7): the los/nmac columns are < 0 while the
    # ownship is in LoS.
    envs = gym.make_vec(
        "cdr_bench/Ownship-v0",
        num_envs=args.num_envs,
        vectorization_mode="vector_entry_point",
        scenario=args.scenario,
    )
    n_obs = envs.single_observation_space.shape[0]
    n_actions = envs.single_action_space.n
    agent = ActorCritic(n_obs, n_actions, args.width)
    optimizer = torch.optim.Adam(agent.parameters(), lr=args.learning_rate, eps=1e-5)

    obs_buf = torch.zeros((args.num_steps, args.num_envs, n_obs))
    mask_buf = torch.zeros((args.num_steps, args.num_envs, n_actions), dtype=torch.bool)
    act_buf = torch.zeros((args.num_steps, args.num_envs), dtype=torch.long)
    logp_buf = torch.zeros((args.num_steps, args.num_envs))
    rew_buf = torch.zeros((args.num_steps, args.num_envs))
    done_buf = torch.zeros((args.num_steps, args.num_envs))
    val_buf = torch.zeros((args.num_steps, args.num_envs))

    obs_np, info = envs.reset(seed=args.seed)
    next_obs = torch.as_tensor(obs_np)
    next_mask = torch.as_tensor(info["action_mask"].astype(bool))
    next_done = torch.zeros(args.num_envs)
    episode_return = np.zeros(args.num_envs)
    had_los = np.zeros(args.num_envs, dtype=bool)  # this flight has been in LoS
    returns: deque[float] = deque(maxlen=100)
    outcomes: deque[str] = deque(maxlen=100)
    clean: deque[bool] = deque(maxlen=100)  # training log only: goal reached, never in LoS
    global_step, invalid, start = 0, 0, time.time()

    for update in range(1, num_updates + 1):
        lr_now = args.learning_rate * (1.0 - (update - 1.0) / num_updates)  # linear annealing
        optimizer.param_groups[0]["lr"] = lr_now

        # -- rollout --------------------------------------------------------------------------
        for step in range(args.num_steps):
            global_step += args.num_envs
            obs_buf[step], mask_buf[step], done_buf[step] = next_obs, next_mask, next_done
            with torch.no_grad():
                dist = agent.dist(next_obs, next_mask)
                action = dist.sample()
                val_buf[step] = agent.value(next_obs)
            act_buf[step], logp_buf[step] = action, dist.log_prob(action)
            invalid += int((~next_mask.gather(1, action[:, None])).sum())

            obs_np, reward, term, trunc, info = envs.step(action.numpy())
            done = term | trunc
            in_los = (info["reward_terms"][:, IN_LOS] < 0).any(axis=1)
            # The benchmark's reward minus the training-only LoS penalty (and, below, the
            # failure penalty when a flight ends): what is scored and what episode_return logs
            # is the benchmark's reward alone.
            shaped = reward - args.los_penalty * in_los
            rew_buf[step] = torch.as_tensor(shaped, dtype=torch.float32)
            next_obs = torch.as_tensor(obs_np)
            next_mask = torch.as_tensor(info["action_mask"].astype(bool))
            next_done = torch.as_tensor(done, dtype=torch.float32)
            episode_return += reward
            had_los |= in_los
            for e in np.flatnonzero(done):
                returns.append(float(episode_return[e]))
                outcomes.append(info["final_info"][e]["outcome"])
                if outcomes[-1] in FAILURES:
                    rew_buf[step, e] -= args.failure_penalty
                clean.append(outcomes[-1] == "success" and not had_los[e])
                episode_return[e], had_los[e] = 0.0, False

        # -- generalised advantage estimation ---------------------------------------------------
        with torch.no_grad():
            next_value = agent.value(next_obs)
            advantages = torch.zeros_like(rew_buf)
            last = torch.zeros(args.num_envs)
            for t in reversed(range(args.num_steps)):
                if t == args.num_steps - 1:
                    not_done, value_next = 1.0 - next_done, next_value
                else:
                    not_done, value_next = 1.0 - done_buf[t + 1], val_buf[t + 1]
                delta = rew_buf[t] + args.gamma * value_next * not_done - val_buf[t]
                last = delta + args.gamma * args.gae_lambda * not_done * last
                advantages[t] = last
            returns_buf = advantages + val_buf

        # -- optimise the policy and the value function ------------------------------------------
        b_obs, b_mask = obs_buf.reshape(-1, n_obs), mask_buf.reshape(-1, n_actions)
        b_act, b_logp = act_buf.reshape(-1), logp_buf.reshape(-1)
        b_adv, b_ret, b_val = advantages.reshape(-1), returns_buf.reshape(-1), val_buf.reshape(-1)
        order = np.arange(batch_size)
        for _ in range(args.update_epochs):
            np.random.default_rng(update).shuffle(order)
            for lo in range(0, batch_size, minibatch_size):
                mb = torch.as_tensor(order[lo : lo + minibatch_size])
                dist = agent.dist(b_obs[mb], b_mask[mb])
                logratio = dist.log_prob(b_act[mb]) - b_logp[mb]
                ratio = logratio.exp()
                with torch.no_grad():
                    approx_kl = ((ratio - 1) - logratio).mean()
                adv = b_adv[mb]
                adv = (adv - adv.mean()) / (adv.std() + 1e-8)
                pg_loss = torch.max(
                    -adv * ratio, -adv * ratio.clamp(1 - args.clip_coef, 1 + args.clip_coef)
                ).mean()
                value = agent.value(b_obs[mb])
                v_clipped = b_val[mb] + (value - b_val[mb]).clamp(-args.clip_coef, args.clip_coef)
                v_loss = 0.5 * torch.max((value - b_ret[mb]) ** 2, (v_clipped - b_ret[mb]) ** 2)
                v_loss = v_loss.mean()
                entropy = dist.entropy().mean()
                loss = pg_loss - args.ent_coef * entropy + args.vf_coef * v_loss
                optimizer.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(agent.parameters(), args.max_grad_norm)
                optimizer.step()

        row = {
            "update": update,
            "global_step": global_step,
            "episodes": len(returns),
            "return_mean_100": round(float(np.mean(returns)), 3) if returns else None,
            "success_100": round(outcomes.count("success") / len(outcomes), 3)
            if outcomes
            else None,
            "clean_100": round(sum(clean) / len(clean), 3) if clean else None,
            "pg_loss": round(pg_loss.item(), 5),
            "v_loss": round(v_loss.item(), 5),
            "entropy": round(entropy.item(), 4),
            "approx_kl": round(approx_kl.item(), 5),
            "sps": int(global_step / (time.time() - start)),
        }
        print(json.dumps(row), flush=True)
    envs.close()

    # -- the trained policy, scored by the package's evaluator ---------------------------------
    Path(args.save).parent.mkdir(parents=True, exist_ok=True)
    torch.save(agent.state_dict(), args.save)
    minutes = (time.time() - start) / 60
    summary = score(args.save, args.scenario, args.eval_episodes, Path(args.save).parent)
    summary.update(
        global_step=global_step, invalid_actions=invalid, train_minutes=round(minutes, 2),
        saved=args.save,
    )  # fmt: skip
    print(json.dumps(summary), flush=True)
    return summary


def score(policy: str, scenario: str, episodes: int, out: Path) -> dict:
    """The greedy policy (masked argmax: ``agents/ppo_tutorial`` loading ``policy``), Direct and
    MVP on the same ``episodes`` validation episodes of ``scenario`` (the evaluator of
    ``cdr-bench evaluate ... --split validation``), and the paired differences in clean success
    (``cdr-bench compare``: B - A per episode, 95 % bootstrap interval, McNemar's exact test)."""
    jobs, _ = resolve_jobs([scenario], None, episodes)
    for name, agent in (("ppo", AGENT), ("direct", "direct"), ("mvp", "mvp")):
        if name == "ppo":  # the agent loads this state dict instead of its shipped policy.pt
            os.environ["CDR_BENCH_CHECKPOINT"] = str(Path(policy).resolve())
        try:
            run = evaluate(
                agent, jobs, out / f"{name}.json", base_seed=SPLITS["validation"], progress=False
            )
        finally:
            os.environ.pop("CDR_BENCH_CHECKPOINT", None)
        print(summary_text(run), flush=True)
    ours = read_result(out / "ppo.json")["scenarios"][0]["metrics"]["ownship"]
    summary = {
        "eval_split": "validation",
        "eval_episodes": episodes,
        "clean_success": ours["clean_success_rate"]["value"],
        "clean_success_ci95": ours["clean_success_rate"]["ci95"],
        "success": ours["success_rate"]["value"],
        "los": ours["los_rate"]["value"],
    }
    for base in ("direct", "mvp"):
        cmp = compare(out / f"{base}.json", out / "ppo.json", metrics=["clean_success_rate"])
        print(comparison_table(cmp), flush=True)
        (row,) = [r for r in cmp["rows"] if r["aircraft"] == "ownship"]
        summary[f"{base}_clean_success"] = row["a"]
        summary[f"minus_{base}"] = row["diff"]  # ppo - base, on the same episodes
        summary[f"minus_{base}_ci95"] = row["ci95"]
    return summary


if __name__ == "__main__":
    main()
