"""The off-policy training loop of Diffusion-AC, Rainbow-DQN and Safe-DQN-X, read top to bottom
like CleanRL.

    cdr-bench train diffusion-ac --run-dir runs/dac --total-steps 200000
    cdr-bench train rainbow --run-dir runs/rainbow --total-steps 200000
    cdr-bench train safe-dqn-x --run-dir runs/safe-dqn-x --total-steps 200000

An algorithm is an :class:`OffPolicyAlgorithm`: its flags (an Args dataclass extending
:class:`OffPolicyArgs`), how it stores transitions (:class:`~cdr_bench.rl.replay.ReplayConfig`)
and a :class:`Learner` (what acts and learns). The loop owns everything else: the environment
(:class:`~cdr_bench.rl.curriculum.CurriculumEnv`: DPSC curriculum, failure penalty, training
cut), the replay, the update ratio, the schedules, logging, checkpoints and ``--resume``.

Outputs in ``run_dir``: ``log.jsonl`` (keys under fixed prefixes, see :mod:`cdr_bench.rl.common`),
``state.pt`` (everything needed to continue exactly with ``--resume``: learner, replay,
environment, random streams and counters; never shipped), ``checkpoint.pt`` (small inference
checkpoint ``{"config", "state_dict", "meta"}`` loaded by agents/<name>/agent.py with
``weights_only=True``), ``curve.png`` and ``args.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol, cast

import numpy as np
from numpy.typing import NDArray

from cdr_bench.rl.common import (
    RunLog,
    TrainArgs,
    add_arguments,
    from_namespace,
    quick_evaluation,
    training_env,
)
from cdr_bench.rl.curriculum import CurriculumEnv, TrainStep
from cdr_bench.rl.replay import Replay, ReplayConfig

if TYPE_CHECKING:
    import torch

# torch is imported inside train(): building the cdr-bench parser must not import it.


@dataclass
class OffPolicyArgs(TrainArgs):
    buffer_size: int = 1_000_000
    """replay capacity"""
    batch_size: int = 128
    """mini-batch size"""
    update_every: int = 4
    """one update per this many environment transitions"""
    learning_starts: int = 5_000
    """transitions collected before the first update"""
    polyak: float = 5e-3
    """target-network Polyak coefficient"""
    stop_at: int = 0
    """pause once this many transitions are trained (state saved, as an interruption would
    leave it; schedules still span total_steps), then continue with --resume; 0 = no pause"""


class Learner(Protocol):
    """What the loop needs of an algorithm."""

    @property
    def config(self) -> dict[str, Any]:
        """JSON-able configuration of :attr:`actor` (``checkpoint.pt``'s ``config``)."""
        ...

    @property
    def actor(self) -> torch.nn.Module:
        """The inference network (``checkpoint.pt``'s ``state_dict``)."""
        ...

    @property
    def checkpoint_extra(self) -> dict[str, Any]:
        """Further entries of ``checkpoint.pt`` the agent needs beside ``config`` and
        ``state_dict`` (tensors, lists, dicts and numbers only: ``torch.load(weights_only=True)``
        reads it); usually none."""
        ...

    def schedule(self, step: int, stage: int | None) -> dict[str, float]:
        """Set the scheduled hyper-parameters for this point of training (transitions so far,
        DPSC stage or None) and return them (logged as ``charts/<name>``)."""
        ...

    def act(self, obs: NDArray[np.float32], mask: NDArray[np.int8], explore: bool) -> NDArray:
        """(N,) actions for (N, F) observations and (N, 27) masks: exploring while training,
        else the inference rule."""
        ...

    def update(self, batch: dict[str, torch.Tensor]) -> dict[str, float]:
        """One gradient step on a replay batch; returns its losses (logged as ``losses/``)."""
        ...

    def state_dict(self) -> dict[str, Any]: ...

    def load_state_dict(self, state: dict[str, Any]) -> None: ...


class Prioritised(Protocol):
    """A learner trained from prioritised replay also gives new priorities."""

    priorities: NDArray[np.floating]
    """per-sample priorities of the last update's batch"""


@dataclass(frozen=True)
class OffPolicyAlgorithm:
    """One algorithm of the loop; its ``add_arguments`` / ``run`` are those of its trainer
    module (:data:`cdr_bench.rl.cli.TRAINERS`)."""

    name: str
    """``cdr-bench train NAME``"""
    title: str
    """title of the learning curve"""
    args: type[OffPolicyArgs]
    """its flags"""
    build: Callable[..., Learner]
    """(args, observation size, the loop's numpy generator, device=torch.device) -> the
    learner, its networks on that device"""
    replay: Callable[[Any], ReplayConfig] = lambda args: ReplayConfig()
    """how its transitions are stored and drawn"""

    def add_arguments(self, p: argparse.ArgumentParser, name: str | None = None) -> None:
        add_arguments(p, self.args)

    def run(self, ns: argparse.Namespace) -> dict:
        return train(self, from_namespace(self.args, ns))

    def main(self, argv: list[str] | None = None) -> int:
        p = argparse.ArgumentParser(description=__doc__)
        self.add_arguments(p)
        print(json.dumps(self.run(p.parse_args(argv)), indent=1))
        return 0


@dataclass
class Counters:
    """The loop's own state (saved with the rest for ``--resume``)."""

    losses: dict[str, list[float]] = field(default_factory=dict)
    step: int = 0
    updates: int = 0
    credit: float = 0.0
    learn_from: int = 0
    beta: float = 0.0


def collect(
    env: CurriculumEnv,
    learner: Learner,
    replay: Replay,
    obs: NDArray[np.float32],
    mask: NDArray[np.int8],
) -> tuple[TrainStep, int]:
    """One step of every episode: act for every flying aircraft (exploring), step, store the
    step's transitions (rows in slot order; truncation, by the horizon or the training cut,
    bootstraps, only termination is terminal). Returns the step and its number of transitions."""
    acting = env.flying
    actions = np.full(acting.shape, 13, dtype=np.int64)
    if acting.any():
        actions[acting] = learner.act(obs[acting], mask[acting], explore=True)
    st = env.step(actions)
    transitions = {
        "obs": obs[acting],
        "mask": mask[acting],
        "action": actions[acting],
        "reward": st.reward[acting].astype(np.float32),
        "goal_reward": st.goal_reward[acting].astype(np.float32),
        "safety_reward": st.safety_reward[acting].astype(np.float32),
        "next_obs": st.final_obs[acting],
        "next_mask": st.final_action_mask[acting],
        "done": st.terminated[acting].astype(np.float32),
    }
    replay.add(np.flatnonzero(acting), transitions, st.flight_ended[acting])
    return st, int(acting.sum())


def on_cpu(state: dict[str, Any]) -> dict[str, Any]:
    """A state dict whose tensors are all on the CPU (what a checkpoint holds, whatever device
    trained it): ``state`` itself when they already are."""
    if all(v.device.type == "cpu" for v in state.values()):
        return state
    return {k: v.cpu() for k, v in state.items()}


def train(algorithm: OffPolicyAlgorithm, args: OffPolicyArgs) -> dict:
    """Train, write ``args.run_dir``, return the summary (also its ``final`` log line)."""
    import torch

    from cdr_bench.rl.device import resolve_device

    if args.stop_at < 0:
        raise ValueError(f"--stop-at must be 0 (no pause) or a transition count: {args.stop_at}")
    device = resolve_device(args.device)
    cuda = device.type == "cuda"
    torch.set_num_threads(args.threads)

    # Seeding.
    torch.manual_seed(args.seed)
    rng = np.random.default_rng(args.seed)

    # Environment, learner, replay.
    env = training_env(args)
    learner = algorithm.build(args, env.observation_size, rng, device=device)
    n_slots = env.num_envs * env.n_agents
    replay = Replay(
        algorithm.replay(args), args.buffer_size, env.observation_size, n_slots, args.gamma
    )
    loop = Counters(learn_from=args.learning_starts, beta=replay.cfg.beta_start)
    state_path = os.path.join(args.run_dir, "state.pt")
    saved: dict[str, Any] = {"log": None}
    if args.resume:
        saved = torch.load(state_path, map_location="cpu", weights_only=False)
        if saved["algorithm"] != algorithm.name:
            raise ValueError(f"{state_path} is a {saved['algorithm']} run, not {algorithm.name}")
        learner.load_state_dict(saved["learner"])
        replay.load_state_dict(saved["replay"])
        env.load_state_dict(saved["env"])
        loop = Counters(**saved["loop"])
        rng.bit_generator.state = saved["rng"]  # in place: the learner may hold this generator
        torch.set_rng_state(saved["torch_rng"])
        if cuda and "cuda_rng" in saved:
            torch.cuda.set_rng_state(saved["cuda_rng"], device)
    log = RunLog(args, algorithm.name, saved["log"])

    def save() -> None:
        state = {
            "algorithm": algorithm.name,
            "learner": learner.state_dict(),
            "replay": replay.state_dict(),
            "env": env.state_dict(),
            "loop": dataclasses.asdict(loop),
            "log": log.state_dict(loop.step),
            "rng": rng.bit_generator.state,
            "torch_rng": torch.get_rng_state(),
            **({"cuda_rng": torch.cuda.get_rng_state(device)} if cuda else {}),
        }
        torch.save(state, state_path + ".tmp")
        os.replace(state_path + ".tmp", state_path)
        meta = {
            "step": loop.step,
            "updates": loop.updates,
            "wall_s": round(log.wall(), 1),
            "algorithm": algorithm.name,
            "args": dataclasses.asdict(args),
        }
        checkpoint = {
            **learner.checkpoint_extra,
            "config": learner.config,
            "state_dict": on_cpu(learner.actor.state_dict()),
        }
        torch.save({**checkpoint, "meta": meta}, os.path.join(args.run_dir, "checkpoint.pt"))

    # The loop, batched over the n_envs episodes.
    obs, mask = env.observe()
    while loop.step < args.total_steps:
        if log.out_of_time() or 0 < args.stop_at <= loop.step:
            break
        # Act for every flying aircraft, step, store the transitions.
        hyper = learner.schedule(loop.step, env.stage)
        st, n = collect(env, learner, replay, obs, mask)
        obs, mask = st.obs, st.action_mask
        loop.step += n
        if st.promoted:  # a new stage can change the schedule for the updates below
            hyper = learner.schedule(loop.step, env.stage)

        # One update per update_every transitions once learning has started.
        if loop.step >= loop.learn_from and len(replay) >= args.batch_size:
            loop.credit += n / args.update_every
            loop.beta = replay.beta(loop.step, args.total_steps)
            while loop.credit >= 1.0:
                loop.credit -= 1.0
                batch = replay.sample(args.batch_size, rng, loop.beta)
                on_device = {k: torch.from_numpy(v).to(device) for k, v in batch.items()}
                losses = learner.update(on_device)
                for k, v in losses.items():
                    loop.losses.setdefault(k, []).append(v)
                if replay.prioritized:
                    replay.update_priorities(batch, cast(Prioritised, learner).priorities)
                loop.updates += 1

        # Logging and checkpoints.
        log.advance(loop.step, n, env)
        if log.log_due(loop.step):
            charts = {f"charts/{k}": v for k, v in hyper.items()}
            if replay.prioritized:
                charts["charts/beta"] = loop.beta
            charts.update({f"losses/{k}": float(np.mean(v)) for k, v in loop.losses.items()})
            log.interval(loop.step, env, env.take_outcomes(), updates=loop.updates, **charts)
            loop.losses = {}
        if log.curve_due(loop.step):
            log.curve_point(loop.step, lambda o, m: learner.act(o, m, explore=False), learner)
        if log.checkpoint_due(loop.step):
            save()
    save()

    # Final quick evaluation (the inference rule) and the learning curve.
    summary: dict[str, Any] = {
        "step": loop.step,
        "updates": loop.updates,
        "wall_s": round(log.wall(), 1),
        "stage": env.stage or 0,
    }
    summary.update(
        quick_evaluation(lambda o, m: learner.act(o, m, explore=False), args.eval_episodes)
    )
    return log.finish(summary, algorithm.title)
