"""PPO, MaskablePPO and TD3 with Stable-Baselines3 / sb3-contrib (paper §5.2).

    cdr-bench train ppo --run-dir runs/ppo --total-steps 200000
    cdr-bench train maskable-ppo --run-dir runs/maskable-ppo --total-steps 200000
    cdr-bench train td3 --run-dir runs/td3 --total-steps 200000

Same environment, observation and reward as Diffusion-AC: an SB3 ``VecEnv`` over the batched
simulator with the DPSC curriculum, failure penalty 5 and the 200-step training cut
(:mod:`cdr_bench.rl.sb3_vecenv`). Networks: three hidden layers of 128 (PPO: separate actor and
critic, Tanh, clip 0.2, GAE 0.95; TD3: ReLU, continuous (a_psi, a_v, a_h) rounded to the discrete
triple), gamma 0.99. PPO and TD3 are unmasked as in the paper (a masked level change is not
executed by the env and counts as invalid); MaskablePPO masks in acting and in its loss.

Outputs in ``run_dir``: ``log.jsonl``, ``state.zip`` + ``state.json`` (SB3 model for
``--resume``; never shipped, SB3 zips unpickle on load), ``checkpoint.pt`` (the actor's weights,
loaded by agents/<name>/agent.py with ``weights_only=True``), ``curve.png``, ``args.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from cdr_bench.rl.baselines import (
    JsonlLog,
    SplitTrainEnv,
    add_dataclass_arguments,
    from_namespace,
    outcome_charts,
    plot_curve,
    write_args,
)
from cdr_bench.rl.vecenv import Curriculum

ALGORITHMS = ("ppo", "maskable-ppo", "td3")
TITLES = {"ppo": "PPO", "maskable-ppo": "MaskablePPO", "td3": "TD3"}

# SB3 and torch are imported inside train(): building the cdr-bench parser must not import them.


@dataclass
class Args:
    run_dir: str = "runs/sb3"
    """directory for logs, checkpoints and the curve"""
    seed: int = 1
    """seed of torch, numpy and the episode-seed stream"""
    total_steps: int = 200_000
    """budget in environment transitions (one flying aircraft, one step)"""
    max_wall_minutes: float = 0.0
    """stop (and finish normally) after this wall time; 0 = no limit"""
    n_envs: int = 16
    """parallel episodes in the batched simulator (SB3 sub-environments)"""
    curriculum: bool = True
    """DPSC on (stages 1..12) or off (train on ``scenario``)"""
    scenario: str = "medium"
    """training scenario without the curriculum"""
    width: int = 128
    """hidden width (three hidden layers)"""
    gamma: float = 0.99
    """discount"""
    lr: float = 3e-4
    """Adam step size (TD3: actor and critic)"""
    n_steps: int = 128
    """PPO: rollout length per sub-environment"""
    ppo_batch_size: int = 256
    """PPO: minibatch size"""
    n_epochs: int = 10
    """PPO: epochs per rollout"""
    clip_range: float = 0.2
    """PPO: clip ratio"""
    gae_lambda: float = 0.95
    """PPO: GAE lambda"""
    ent_coef: float = 0.0
    """PPO: entropy bonus coefficient"""
    buffer_size: int = 1_000_000
    """TD3: replay capacity"""
    batch_size: int = 128
    """TD3: mini-batch size"""
    update_every: int = 4
    """TD3: one gradient step per this many transitions"""
    learning_starts: int = 5_000
    """TD3: transitions collected before the first update"""
    polyak: float = 5e-3
    """TD3: target Polyak coefficient tau"""
    action_noise: float = 0.1
    """TD3: std of the Gaussian exploration noise on the [-1, 1] outputs"""
    failure_penalty: float = 5.0
    """training-only extra penalty when an episode ends in LoS/NMAC (as Diffusion-AC)"""
    max_episode_steps: int = 200
    """training-only episode cut (bootstrapped); 0 = scenario horizon"""
    window: int = 100
    """DPSC promotion window (episodes)"""
    promote_at: float = 0.9
    """DPSC promotion threshold on the rolling success rate"""
    log_every: int = 10_000
    """transitions between log lines"""
    checkpoint_every: int = 50_000
    """transitions between checkpoints"""
    eval_episodes: int = 100
    """episodes per density for the final quick evaluation (0 = skip)"""
    resume: bool = False
    """continue from run_dir/state.zip (TD3: with an empty replay buffer)"""
    threads: int = 1
    """torch intra-op threads"""
    progress: bool = True
    """show a tqdm progress bar"""


def _algorithm_class(algorithm: str) -> Any:
    if algorithm == "ppo":
        from stable_baselines3 import PPO

        return PPO
    if algorithm == "maskable-ppo":
        from sb3_contrib import MaskablePPO

        return MaskablePPO
    if algorithm == "td3":
        from stable_baselines3 import TD3

        return TD3
    raise ValueError(f"algorithm must be one of {ALGORITHMS}, got {algorithm!r}")


def _new_model(algorithm: str, args: Args, venv: Any) -> Any:
    cls = _algorithm_class(algorithm)
    common = dict(gamma=args.gamma, learning_rate=args.lr, seed=args.seed, device="cpu", verbose=0)
    if algorithm in ("ppo", "maskable-ppo"):
        arch = [args.width] * 3
        return cls(
            "MlpPolicy",
            venv,
            n_steps=args.n_steps,
            batch_size=args.ppo_batch_size,
            n_epochs=args.n_epochs,
            clip_range=args.clip_range,
            gae_lambda=args.gae_lambda,
            ent_coef=args.ent_coef,
            policy_kwargs=dict(net_arch=dict(pi=arch, vf=arch)),
            **common,
        )
    from stable_baselines3.common.noise import NormalActionNoise, VectorizedActionNoise

    noise = VectorizedActionNoise(
        NormalActionNoise(np.zeros(3), np.full(3, args.action_noise)), args.n_envs
    )
    return cls(
        "MlpPolicy",
        venv,
        buffer_size=args.buffer_size,
        batch_size=args.batch_size,
        learning_starts=args.learning_starts,
        tau=args.polyak,
        train_freq=1,
        gradient_steps=max(1, round(args.n_envs / args.update_every)),
        action_noise=noise,
        policy_kwargs=dict(net_arch=[args.width] * 3),
        **common,
    )


def train(algorithm: str, args: Args) -> dict:
    import torch
    from stable_baselines3.common.callbacks import BaseCallback

    from cdr_bench.rl.quick_eval import quick_eval
    from cdr_bench.rl.sb3_policies import export_actor
    from cdr_bench.rl.sb3_vecenv import BatchedVecEnv

    cls = _algorithm_class(algorithm)
    os.makedirs(args.run_dir, exist_ok=True)
    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)

    env = SplitTrainEnv(
        args.n_envs,
        seed=args.seed,
        scenario=args.scenario,
        curriculum=Curriculum(args.window, args.promote_at) if args.curriculum else None,
        failure_penalty=args.failure_penalty,
        max_episode_steps=args.max_episode_steps,
    )
    venv = BatchedVecEnv(env, continuous=algorithm == "td3")
    zip_path = os.path.join(args.run_dir, "state.zip")
    side_path = os.path.join(args.run_dir, "state.json")
    wall_before = 0.0
    if args.resume:
        side = json.load(open(side_path))
        if env.curriculum is not None:
            env.curriculum.stage = side["stage"]
            env._build()
        env.rng = np.random.default_rng(side["rng_seed"])
        wall_before = side["wall_s"]
        model = cls.load(zip_path, env=venv, device="cpu")
    else:
        model = _new_model(algorithm, args, venv)
    log = JsonlLog(args.run_dir, args.resume)
    write_args(args.run_dir, args, algorithm=algorithm)
    kind = "td3" if algorithm == "td3" else "ppo"
    t0 = time.time()

    def save() -> None:
        wall = wall_before + time.time() - t0
        model.save(zip_path)
        side = {
            "step": int(model.num_timesteps),
            "wall_s": wall,
            "stage": env.curriculum.stage if env.curriculum else 0,
            "rng_seed": int(env.rng.integers(0, 2**31)),
        }
        with open(side_path, "w") as f:
            json.dump(side, f)
        meta = {"step": int(model.num_timesteps), "wall_s": round(wall, 1), "algorithm": algorithm}
        export_actor(model, kind, os.path.join(args.run_dir, "checkpoint.pt"), meta)

    class Progress(BaseCallback):
        """Progress bar, JSONL log lines, periodic checkpoints and the wall-time limit."""

        def _on_training_start(self) -> None:
            self.pbar = None
            if args.progress:
                from tqdm import tqdm

                self.pbar = tqdm(
                    total=args.total_steps,
                    initial=int(self.model.num_timesteps),
                    unit="step",
                    dynamic_ncols=True,
                )
            self.last_log = self.last_ckpt = int(self.model.num_timesteps)

        def _on_step(self) -> bool:
            step = int(self.model.num_timesteps)
            if self.pbar is not None:
                self.pbar.update(venv.num_envs)
            for stage in venv.promotions:
                log.write(
                    {
                        "step": step,
                        "curriculum/promoted_to": stage,
                        "wall_s": wall_before + time.time() - t0,
                    }
                )
            venv.promotions.clear()
            if step - self.last_log >= args.log_every:
                self.last_log = step
                rec = {
                    "step": step,
                    "wall_s": round(wall_before + time.time() - t0, 1),
                    "curriculum/stage": env.curriculum.stage if env.curriculum else 0,
                    "charts/success_rolling": env.success_rate(),
                    "charts/episodes": env.episodes,
                    **outcome_charts(venv.finished),
                }
                for k, v in self.model.logger.name_to_value.items():
                    if k.startswith("train/") and "loss" in k:
                        rec["losses/" + k.split("/", 1)[1]] = float(v)
                log.write(rec)
                venv.finished.clear()
                if self.pbar is not None:
                    self.pbar.set_postfix(
                        stage=rec["curriculum/stage"], succ=f"{rec['charts/success_rolling']:.2f}"
                    )
            if step - self.last_ckpt >= args.checkpoint_every:
                self.last_ckpt = step
                save()
            return not (args.max_wall_minutes and time.time() - t0 > 60 * args.max_wall_minutes)

        def _on_training_end(self) -> None:
            if self.pbar is not None:
                self.pbar.close()

    remaining = max(0, args.total_steps - int(model.num_timesteps))
    if remaining:
        model.learn(
            remaining, callback=Progress(), log_interval=None, reset_num_timesteps=not args.resume
        )
    save()
    wall = wall_before + time.time() - t0

    summary: dict = {
        "step": int(model.num_timesteps),
        "wall_s": round(wall, 1),
        "stage": env.curriculum.stage if env.curriculum else 0,
    }
    if args.eval_episodes:
        from cdr_bench.rl.baselines import continuous_to_index
        from cdr_bench.rl.sb3_policies import load_actor

        net, _ = load_actor(os.path.join(args.run_dir, "checkpoint.pt"))

        def act_batch(o: np.ndarray, m: np.ndarray) -> np.ndarray:
            with torch.no_grad():
                out = net(torch.from_numpy(o))
            if kind == "td3":
                return continuous_to_index(out.numpy())
            if algorithm == "maskable-ppo":
                out = out.masked_fill(torch.from_numpy(m) == 0, -torch.inf)
            return out.argmax(1).numpy()

        for sc in ("low", "medium", "high"):
            summary[f"eval/{sc}"] = quick_eval(act_batch, sc, args.eval_episodes, seed=10_000)
    log.write({"final": summary})
    try:
        plot_curve(log.path, os.path.join(args.run_dir, "curve.png"), TITLES[algorithm])
    except Exception as e:  # plotting must never lose a finished run
        print(f"curve not written: {e}")
    return summary


def add_arguments(p: argparse.ArgumentParser, algorithm: str) -> None:
    add_dataclass_arguments(p, Args, run_dir=f"runs/{algorithm}")


def run(algorithm: str, ns: argparse.Namespace) -> dict:
    return train(algorithm, from_namespace(Args, ns))


def main(algorithm: str, doc: str | None, argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        description=doc, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    add_arguments(p, algorithm)
    print(json.dumps(run(algorithm, p.parse_args(argv)), indent=1))
    return 0
