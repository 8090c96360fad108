"""Tutorial "PPO on the vector env": single-file PPO in the style of CleanRL's ``ppo.py``, on the
native Gymnasium vector env of cdr-bench, with a masked categorical policy.

    python docs/tutorials/ppo_vector_env.py                  # 400k steps of medium
    python docs/tutorials/ppo_vector_env.py --total-timesteps 2048 --num-envs 8 --num-steps 32

Prints one JSON line per update, then the greedy policy's success rate on fresh episodes, and
saves the policy's state dict (``--save``). Needs torch (the ``train`` extra).
"""

from __future__ import annotations

import argparse
import json
import time
from collections import deque
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from torch import nn
from torch.distributions import Categorical

import cdr_bench  # noqa: F401  (registers the cdr_bench/* Gymnasium ids)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="medium")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--total-timesteps", type=int, default=400_000)
    p.add_argument("--num-envs", type=int, default=16, help="episodes stepped together")
    p.add_argument("--num-steps", type=int, default=128, help="steps per env per rollout")
    p.add_argument("--learning-rate", type=float, default=3e-4)
    p.add_argument("--gamma", type=float, default=0.99)
    p.add_argument("--gae-lambda", type=float, default=0.95)
    p.add_argument("--num-minibatches", type=int, default=8)
    p.add_argument("--update-epochs", type=int, default=10)
    p.add_argument("--clip-coef", type=float, default=0.2)
    p.add_argument("--ent-coef", type=float, default=0.0)
    p.add_argument("--vf-coef", type=float, default=0.5)
    p.add_argument("--max-grad-norm", type=float, default=0.5)
    p.add_argument("--eval-episodes", type=int, default=200, help="greedy episodes at the end")
    p.add_argument("--save", default="runs/ppo-vector-env/policy.pt", help="state dict")
    return p.parse_args(argv)


def layer_init(layer: nn.Linear, std: float = np.sqrt(2), bias: float = 0.0) -> nn.Linear:
    nn.init.orthogonal_(layer.weight, std)
    nn.init.constant_(layer.bias, bias)
    return layer


class ActorCritic(nn.Module):
    def __init__(self, n_obs: int, n_actions: int):
        super().__init__()
        self.critic = nn.Sequential(
            layer_init(nn.Linear(n_obs, 64)), nn.Tanh(),
            layer_init(nn.Linear(64, 64)), nn.Tanh(),
            layer_init(nn.Linear(64, 1), std=1.0),
        )  # fmt: skip
        self.actor = nn.Sequential(
            layer_init(nn.Linear(n_obs, 64)), nn.Tanh(),
            layer_init(nn.Linear(64, 64)), nn.Tanh(),
            layer_init(nn.Linear(64, n_actions), std=0.01),
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
    torch.set_num_threads(1)  # small networks: threads cost more than they bring
    batch_size = args.num_envs * args.num_steps
    minibatch_size = batch_size // args.num_minibatches
    num_updates = max(1, args.total_timesteps // batch_size)

    # The native vector env: observations (N, 42), masks in infos["action_mask"] (N, 27),
    # same-step auto-reset (the ended episode's outcome is in infos["final_info"]).
    envs = gym.make_vec(
        "cdr_bench/Ownship-v0",
        num_envs=args.num_envs,
        vectorization_mode="vector_entry_point",
        scenario=args.scenario,
    )
    n_obs = envs.single_observation_space.shape[0]
    n_actions = envs.single_action_space.n
    agent = ActorCritic(n_obs, n_actions)
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
    returns: deque[float] = deque(maxlen=100)
    outcomes: deque[str] = deque(maxlen=100)
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
            rew_buf[step] = torch.as_tensor(reward, dtype=torch.float32)
            next_obs = torch.as_tensor(obs_np)
            next_mask = torch.as_tensor(info["action_mask"].astype(bool))
            next_done = torch.as_tensor(done, dtype=torch.float32)
            episode_return += reward
            for e in np.flatnonzero(done):
                returns.append(float(episode_return[e]))
                outcomes.append(info["final_info"][e]["outcome"])
                episode_return[e] = 0.0

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
            "pg_loss": round(pg_loss.item(), 5),
            "v_loss": round(v_loss.item(), 5),
            "entropy": round(entropy.item(), 4),
            "approx_kl": round(approx_kl.item(), 5),
            "sps": int(global_step / (time.time() - start)),
        }
        print(json.dumps(row), flush=True)
    envs.close()

    # -- the trained policy, greedy (masked argmax), on fresh episodes -----------------------------
    Path(args.save).parent.mkdir(parents=True, exist_ok=True)
    torch.save(agent.state_dict(), args.save)
    summary = evaluate(agent, args.scenario, args.eval_episodes, seed=args.seed + 10_000)
    summary.update(global_step=global_step, invalid_actions=invalid, saved=args.save)
    print(json.dumps(summary), flush=True)
    return summary


def evaluate(agent: ActorCritic, scenario: str, episodes: int, seed: int) -> dict[str, float]:
    """Greedy success rate on ``episodes`` fresh episodes, stepped together."""
    envs = gym.make_vec(
        "cdr_bench/Ownship-v0",
        num_envs=episodes,
        vectorization_mode="vector_entry_point",
        scenario=scenario,
    )
    obs, info = envs.reset(seed=seed)
    outcome: list[str | None] = [None] * episodes
    while any(o is None for o in outcome):
        with torch.no_grad():
            logits = agent.dist(torch.as_tensor(obs), torch.as_tensor(info["action_mask"] > 0))
            action = logits.probs.argmax(-1).numpy()
        obs, _, term, trunc, info = envs.step(action)
        for e in np.flatnonzero(term | trunc):
            if outcome[e] is None:  # the first episode of each slot only
                outcome[e] = info["final_info"][e]["outcome"]
    envs.close()
    return {"eval_episodes": episodes, "eval_success_rate": outcome.count("success") / episodes}


if __name__ == "__main__":
    main()
