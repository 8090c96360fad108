"""PPO, MaskablePPO and TD3 with Stable-Baselines3 / sb3-contrib (paper §5.2).

    cdr-bench train ppo --run-dir runs/ppo --total-steps 200000
    cdr-bench train maskable-ppo --run-dir runs/maskable-ppo --total-steps 200000
    cdr-bench train td3 --run-dir runs/td3 --total-steps 200000
    python -m cdr_bench.rl.train_sb3 ppo --run-dir runs/ppo --total-steps 200000

Same environment, observation and reward as Diffusion-AC: the SB3 ``VecEnv`` of
:func:`cdr_bench.wrappers.vector_env_to_sb3` over the training environment
(:class:`~cdr_bench.rl.curriculum.CurriculumEnv`: DPSC curriculum, failure penalty 5 and the
200-step training cut; each controlled aircraft one slot). Networks: three hidden layers of 128
(PPO: separate actor and critic, Tanh, clip 0.2, GAE 0.95; TD3: ReLU, continuous
(a_psi, a_v, a_h) rounded to the discrete triple), gamma 0.99. PPO and TD3 are unmasked as in
the paper (a masked level change is not executed by the env and counts as invalid); MaskablePPO
masks in acting and in its loss.

Outputs in ``run_dir``: ``log.jsonl``, ``state.zip`` (the SB3 model) + ``state.pt`` (environment,
random streams and counters; TD3 also ``replay.pkl``) for an exact ``--resume`` (never shipped:
they unpickle on load), ``checkpoint.pt`` (the actor's weights, loaded by agents/<name>/agent.py
with ``weights_only=True``), ``curve.png``, ``args.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np

from cdr_bench.errors import UserError
from cdr_bench.rl import common
from cdr_bench.rl.common import (
    PPOArgs,
    RunLog,
    from_namespace,
    quick_evaluation,
    same_named,
    training_env,
)
from cdr_bench.rl.offpolicy import OffPolicyArgs
from cdr_bench.rl.quick_eval import ActBatch

ALGORITHMS = ("ppo", "maskable-ppo", "td3")
TITLES = {"ppo": "PPO", "maskable-ppo": "MaskablePPO", "td3": "TD3"}

# SB3 and torch are imported inside train(): building the cdr-bench parser must not import them.


@dataclass
class Args(PPOArgs, OffPolicyArgs):
    """The replay flags (``buffer_size`` .. ``polyak``) are TD3's; PPO and MaskablePPO ignore
    them, and TD3 those of :class:`~cdr_bench.rl.common.PPOArgs`."""

    run_dir: str = "runs/sb3"
    n_envs: int = 16
    width: int = 128
    """hidden width (three hidden layers)"""
    lr: float = 3e-4
    """Adam step size (TD3: actor and critic)"""
    action_noise: float = 0.1
    """TD3: std of the Gaussian exploration noise on the [-1, 1] outputs"""
    ppo_batch_size: int = 256
    """PPO: minibatch size"""
    teacher: str = ""
    """PPO, MaskablePPO: an agent (folder or file of the agent protocol, e.g. agents/mvp) whose
    demonstrations the policy and value head are fitted to before RL starts (imitation, then
    RL; cdr_bench/rl/imitation.py); empty = none"""
    teacher_transitions: int = 100_000
    """PPO, MaskablePPO: demonstration transitions collected from ``teacher`` (not counted in
    ``total_steps``)"""
    teacher_epochs: int = 5
    """PPO, MaskablePPO: passes over the demonstrations"""
    mvp_input: bool = False
    """append the one-hot of ``mvp``'s action (cdr_bench/resolvers.py) to the observation: a
    learned residual on top of ``mvp`` (with ``--teacher agents/mvp`` it starts as a copy of
    it); the checkpoint records it and agents/mvp_residual plays it"""


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


def _new_model(algorithm: str, args: Args, venv: Any, device: Any = "cpu") -> Any:
    cls = _algorithm_class(algorithm)
    common = dict(gamma=args.gamma, learning_rate=args.lr, seed=args.seed, device=device, verbose=0)
    if algorithm in ("ppo", "maskable-ppo"):
        arch = dict(pi=[args.width] * 3, vf=[args.width] * 3)
        ppo = same_named(args, PPOArgs)
        kwargs = dict(batch_size=args.ppo_batch_size, policy_kwargs=dict(net_arch=arch), **ppo)
        return cls("MlpPolicy", venv, **kwargs, **common)
    from stable_baselines3.common.noise import NormalActionNoise, VectorizedActionNoise

    n = venv.num_envs
    noise = NormalActionNoise(np.zeros(3), np.full(3, args.action_noise))
    td3 = same_named(args, ("buffer_size", "batch_size", "learning_starts"), tau=args.polyak)
    td3.update(train_freq=1, gradient_steps=max(1, round(n / args.update_every)))
    td3.update(action_noise=VectorizedActionNoise(noise, n))
    return cls("MlpPolicy", venv, policy_kwargs=dict(net_arch=[args.width] * 3), **td3, **common)


def train(algorithm: str, args: Args) -> dict:
    import torch
    from stable_baselines3.common.callbacks import BaseCallback

    from cdr_bench.resolvers import mvp_onehot, with_mvp_input
    from cdr_bench.rl.baselines import continuous_to_index
    from cdr_bench.rl.device import resolve_device
    from cdr_bench.rl.sb3_policies import actor_of, export_actor
    from cdr_bench.wrappers import vector_env_to_sb3

    cls = _algorithm_class(algorithm)
    device = resolve_device(args.device)
    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)

    td3 = algorithm == "td3"
    env = training_env(args)
    venv = vector_env_to_sb3(
        env,
        include_mask=False,
        continuous_actions=continuous_to_index if td3 else None,
        extra_features=mvp_onehot if args.mvp_input else None,
    )
    zip_path = os.path.join(args.run_dir, "state.zip")
    state_path = os.path.join(args.run_dir, "state.pt")
    replay_path = os.path.join(args.run_dir, "replay.pkl")
    saved: dict[str, Any] = {"log": None}
    if args.resume:
        saved = torch.load(state_path, map_location="cpu", weights_only=False)
        env.load_state_dict(saved["env"])
        # load() re-seeds every generator (restored below) and must not restart the episodes.
        model = cls.load(zip_path, env=venv, device=device, force_reset=False)
        venv.load_state_dict(saved["venv"])
        venv.seed(None)
        if td3:
            model.load_replay_buffer(replay_path)
        np.random.set_state(saved["numpy_rng"])  # noqa: NPY002 - SB3 draws from the global one
        torch.set_rng_state(saved["torch_rng"])
        model.action_space.np_random.bit_generator.state = saved["action_space_rng"]
    else:
        model = _new_model(algorithm, args, venv, device)
    # an in-memory logger (read by read_losses): SB3's default leaves an empty /tmp/SB3-<time>
    # folder behind every run
    from stable_baselines3.common.logger import Logger

    model.set_logger(Logger(None, []))
    log = RunLog(args, algorithm, saved["log"])
    if args.teacher and not args.resume:
        if td3:
            raise UserError("--teacher: PPO and MaskablePPO only (TD3 has no categorical policy)")
        log.write({"step": 0, **_imitate(model, args, masked=algorithm == "maskable-ppo")})
    kind = "td3" if td3 else "ppo"

    losses: dict[str, float] = saved.get("losses", {})  # of the last update, as SB3 logs them

    def greedy() -> ActBatch:
        """The deterministic policy of the actor as it is now (what the checkpoint would act)."""
        net = actor_of(model, kind)

        def act_batch(o: np.ndarray, m: np.ndarray) -> np.ndarray:
            x = with_mvp_input(o, m) if args.mvp_input else o
            with torch.no_grad():
                out = net(torch.from_numpy(x))
            if td3:
                return continuous_to_index(out.numpy())
            if algorithm == "maskable-ppo":
                out = out.masked_fill(torch.from_numpy(m) == 0, -torch.inf)
            return out.argmax(1).numpy()

        return act_batch

    def read_losses() -> None:
        for k, v in model.logger.name_to_value.items():
            if k.startswith("train/") and "loss" in k:
                losses["losses/" + k.split("/", 1)[1]] = float(v)

    def save() -> None:
        read_losses()
        model.save(zip_path)
        if td3:
            model.save_replay_buffer(replay_path)
        state = {
            "env": env.state_dict(),
            "venv": venv.state_dict(),
            "log": log.state_dict(int(model.num_timesteps)),
            "numpy_rng": np.random.get_state(),  # noqa: NPY002
            "torch_rng": torch.get_rng_state(),
            "action_space_rng": model.action_space.np_random.bit_generator.state,
            "losses": losses,
        }
        torch.save(state, state_path + ".tmp")
        os.replace(state_path + ".tmp", state_path)
        meta = {
            "step": int(model.num_timesteps),
            "wall_s": round(log.wall(), 1),
            "algorithm": algorithm,
        }
        inputs = {"mvp_input": True} if args.mvp_input else {}
        export_actor(model, kind, os.path.join(args.run_dir, "checkpoint.pt"), meta, **inputs)

    class Progress(BaseCallback):
        """Log lines, checkpoints and the wall-time limit, after every vector step."""

        def _on_step(self) -> bool:
            step = int(self.model.num_timesteps)
            log.advance(step, venv.num_envs, env)
            if log.log_due(step):
                read_losses()
                log.interval(step, env, env.take_outcomes(), **losses)
            if log.curve_due(step):
                log.curve_point(step, greedy(), model.action_space)
            if log.checkpoint_due(step):
                save()
            return not log.out_of_time()

    remaining = max(0, args.total_steps - int(model.num_timesteps))
    if remaining:
        model.learn(
            remaining, callback=Progress(), log_interval=None, reset_num_timesteps=not args.resume
        )
    save()

    summary: dict = {
        "step": int(model.num_timesteps),
        "wall_s": round(log.wall(), 1),
        "stage": env.stage or 0,
    }
    summary.update(quick_evaluation(greedy(), args.eval_episodes))
    return log.finish(summary, TITLES[algorithm])


def _imitate(model: Any, args: Args, masked: bool) -> dict[str, float]:
    """Fit ``model``'s policy and value head to ``args.teacher``'s demonstrations."""
    import gymnasium as gym

    from cdr_bench.actions import N_ACTIONS
    from cdr_bench.evaluate.loader import load_agent
    from cdr_bench.rl.imitation import demonstrations, fit_policy
    from cdr_bench.vector_env import observation_space

    env = training_env(args)  # the spaces the agent protocol gives (those of the first stage)
    teacher = load_agent(
        args.teacher, observation_space(env.config), gym.spaces.Discrete(N_ACTIONS)
    )
    teacher.reset(args.seed)
    data = demonstrations(teacher.act_batch, args, args.teacher_transitions)
    if args.mvp_input:
        from cdr_bench.resolvers import with_mvp_input

        data["obs"] = with_mvp_input(data["obs"], data["mask"])
    return fit_policy(
        model.policy, data, args.teacher_epochs, args.ppo_batch_size, args.seed, masked
    )


def add_arguments(p: argparse.ArgumentParser, name: str | None = None) -> None:
    """The flags of ``cdr-bench train NAME`` for NAME in :data:`ALGORITHMS`."""
    common.add_arguments(p, Args, run_dir=f"runs/{name or 'sb3'}")
    if name is not None:
        p.set_defaults(algorithm=name)


def run(ns: argparse.Namespace) -> dict:
    """Entry point of ``cdr-bench train ppo|maskable-ppo|td3`` (``ns.algorithm``)."""
    return train(ns.algorithm, from_namespace(Args, ns))


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] not in ALGORITHMS:
        print(f"usage: python -m cdr_bench.rl.train_sb3 {{{','.join(ALGORITHMS)}}} [flags]")
        return 2
    p = argparse.ArgumentParser(description=__doc__, prog=f"train_sb3 {argv[0]}")
    add_arguments(p, argv[0])
    print(json.dumps(run(p.parse_args(argv[1:])), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
