"""Safe-DQN-X (:mod:`cdr_bench.rl.safe_dqn`): safety and goal Q networks, CleanRL reading order.

    cdr-bench train safe-dqn-x --run-dir runs/safe-dqn-x --total-steps 200000

Exploration is epsilon-greedy over the feasible actions (a random feasible action with
probability epsilon, annealed linearly), otherwise the combination rule (``--combine``).

Same environment, observation and reward as Diffusion-AC (:class:`~cdr_bench.rl.vecenv.TrainEnv`
with the DPSC curriculum, failure penalty 5 and a 200-step training cut by default), gamma 0.99,
width 128. Outputs in ``run_dir``: ``log.jsonl``, ``state.pt`` (for ``--resume``; the replay
buffer is not saved), ``checkpoint.pt`` (small, loaded by agents/safe_dqn_x/agent.py with
``weights_only=True``), ``curve.png``, ``args.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from dataclasses import dataclass

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

# torch is imported inside train(): building the cdr-bench parser must not import it.


@dataclass
class Args:
    run_dir: str = "runs/safe-dqn-x"
    """directory for logs, checkpoints and the curve"""
    seed: int = 1
    """seed of torch, numpy and the episode-seed stream"""
    total_steps: int = 200_000
    """budget in environment transitions (one flying aircraft, one step)"""
    max_wall_minutes: float = 0.0
    """stop (and finish normally) after this wall time; 0 = no limit"""
    n_envs: int = 32
    """parallel episodes in the batched simulator"""
    curriculum: bool = True
    """DPSC on (stages 1..12) or off (train on ``scenario``)"""
    scenario: str = "medium"
    """training scenario without the curriculum"""
    width: int = 128
    """hidden width of each Q network (three hidden layers)"""
    combine: str = "sum"
    """combination rule of the two Q networks: "sum" or "lexicographic" (see safe_dqn.py)"""
    slack: float = 0.1
    """lexicographic rule: actions within this of the best safety Q count as safe"""
    eps_start: float = 1.0
    """epsilon of epsilon-greedy at the start"""
    eps_end: float = 0.05
    """epsilon after the annealing"""
    eps_fraction: float = 0.25
    """fraction of total_steps over which epsilon anneals linearly"""
    buffer_size: int = 1_000_000
    """replay capacity"""
    batch_size: int = 128
    """mini-batch size"""
    update_every: int = 4
    """one update per this many environment transitions"""
    learning_starts: int = 5_000
    """transitions collected before the first update"""
    gamma: float = 0.99
    """discount"""
    lr: float = 1e-4
    """Adam step size"""
    polyak: float = 5e-3
    """target-network Polyak coefficient"""
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
    """continue from run_dir/state.pt"""
    threads: int = 1
    """torch intra-op threads"""
    progress: bool = True
    """show a tqdm progress bar"""


def train(args: Args) -> dict:
    import torch

    from cdr_bench.rl.quick_eval import quick_eval
    from cdr_bench.rl.replay import SplitRewardReplayBuffer
    from cdr_bench.rl.safe_dqn import RULES, SafeDQN, SafeDQNConfig

    if args.combine not in RULES:
        raise ValueError(f"--combine must be one of {RULES}, got {args.combine!r}")
    os.makedirs(args.run_dir, exist_ok=True)
    torch.set_num_threads(args.threads)

    # Seeding.
    torch.manual_seed(args.seed)
    rng = np.random.default_rng(args.seed)

    # Environment, learner, storage.
    env = SplitTrainEnv(
        args.n_envs,
        seed=args.seed,
        scenario=args.scenario,
        curriculum=Curriculum(args.window, args.promote_at) if args.curriculum else None,
        failure_penalty=args.failure_penalty,
        max_episode_steps=args.max_episode_steps,
    )
    obs_dim = env.observe()[0].shape[1]
    learner = SafeDQN(SafeDQNConfig(obs_dim, args.width, args.combine, args.slack), lr=args.lr)
    buffer = SplitRewardReplayBuffer(args.buffer_size, obs_dim)
    step, n_updates, wall_before = 0, 0, 0.0
    state_path = os.path.join(args.run_dir, "state.pt")
    if args.resume:
        st = torch.load(state_path, map_location="cpu", weights_only=False)
        learner.load_state_dict(st["learner"])
        step, n_updates, wall_before = st["step"], st["updates"], st["wall_s"]
        if env.curriculum is not None:
            env.curriculum.stage = st["stage"]
            env._build()
        rng = np.random.default_rng(st["rng_seed"])
        env.rng = np.random.default_rng(st["rng_seed"] + 1)
    log = JsonlLog(args.run_dir, args.resume)
    write_args(args.run_dir, args, algorithm="safe-dqn-x")

    # The loop.
    t0 = time.time()
    credit, last_log, last_ckpt = 0.0, step, step
    losses: dict[str, list[float]] = {}
    outcomes: list[int] = []
    pbar = None
    if args.progress:
        from tqdm import tqdm

        pbar = tqdm(total=args.total_steps, initial=step, unit="step", dynamic_ncols=True)
    learn_from = step + args.learning_starts
    while step < args.total_steps:
        if args.max_wall_minutes and time.time() - t0 > 60 * args.max_wall_minutes:
            break
        obs, mask, _ = env.observe()
        frac = min(1.0, step / max(1.0, args.eps_fraction * args.total_steps))
        eps = args.eps_start + frac * (args.eps_end - args.eps_start)
        actions = learner.net.act(torch.from_numpy(obs), torch.from_numpy(mask)).numpy()
        explore = rng.random(len(actions)) < eps
        if explore.any():
            # A uniformly random feasible action: argmax of uniform noise over the feasible set.
            noise = np.where(mask[explore] > 0, rng.random((int(explore.sum()), mask.shape[1])), -1)
            actions[explore] = noise.argmax(axis=1)
        tr = env.step(actions)
        buffer.add_split(
            tr["obs"],
            tr["mask"],
            tr["action"],
            tr["goal_reward"],
            tr["safety_reward"],
            tr["next_obs"],
            tr["next_mask"],
            tr["done"],
        )
        n = len(tr["action"])
        step += n
        outcomes += tr["finished"]
        if tr["promoted"]:
            assert env.curriculum is not None
            log.write(
                {
                    "step": step,
                    "curriculum/promoted_to": env.curriculum.stage,
                    "wall_s": wall_before + time.time() - t0,
                }
            )
        if step >= learn_from:
            credit += n / args.update_every
            while credit >= 1.0:
                credit -= 1.0
                b = buffer.sample(args.batch_size, rng)
                tb = {k: torch.from_numpy(v) for k, v in b.items()}
                for k, v in learner.update(tb, args.gamma, args.polyak).items():
                    losses.setdefault(k, []).append(v)
                n_updates += 1
        if pbar is not None:
            pbar.update(n)
        if step - last_log >= args.log_every:
            last_log = step
            rec = {
                "step": step,
                "updates": n_updates,
                "wall_s": round(wall_before + time.time() - t0, 1),
                "curriculum/stage": env.curriculum.stage if env.curriculum else 0,
                "charts/success_rolling": env.success_rate(),
                "charts/episodes": env.episodes,
                **outcome_charts(outcomes),
                "charts/epsilon": eps,
            }
            rec.update({f"losses/{k}": float(np.mean(v)) for k, v in losses.items()})
            log.write(rec)
            if pbar is not None:
                pbar.set_postfix(
                    stage=rec["curriculum/stage"],
                    succ=f"{rec['charts/success_rolling']:.2f}",
                    eps=f"{eps:.2f}",
                )
            losses, outcomes = {}, []
        if step - last_ckpt >= args.checkpoint_every:
            last_ckpt = step
            _save(args, learner, env, step, n_updates, wall_before + time.time() - t0, rng)
    if pbar is not None:
        pbar.close()
    wall = wall_before + time.time() - t0
    _save(args, learner, env, step, n_updates, wall, rng)

    summary: dict = {
        "step": step,
        "updates": n_updates,
        "wall_s": round(wall, 1),
        "stage": env.curriculum.stage if env.curriculum else 0,
    }
    if args.eval_episodes:
        net = learner.net.eval()

        def act_batch(o: np.ndarray, m: np.ndarray) -> np.ndarray:
            return net.act(torch.from_numpy(o), torch.from_numpy(m)).numpy()

        for sc in ("low", "medium", "high"):
            summary[f"eval/{sc}"] = quick_eval(act_batch, sc, args.eval_episodes, seed=10_000)
    log.write({"final": summary})
    try:
        plot_curve(log.path, os.path.join(args.run_dir, "curve.png"), "Safe-DQN-X")
    except Exception as e:  # plotting must never lose a finished run
        print(f"curve not written: {e}")
    return summary


def _save(args, learner, env, step, n_updates, wall, rng) -> None:
    import torch

    from cdr_bench.rl.safe_dqn import save_net

    st = {
        "learner": learner.state_dict(),
        "step": step,
        "updates": n_updates,
        "wall_s": wall,
        "stage": env.curriculum.stage if env.curriculum else 0,
        "rng_seed": int(rng.integers(0, 2**31)),
    }
    torch.save(st, os.path.join(args.run_dir, "state.pt.tmp"))
    os.replace(os.path.join(args.run_dir, "state.pt.tmp"), os.path.join(args.run_dir, "state.pt"))
    meta = {"step": step, "updates": n_updates, "wall_s": round(wall, 1), "algorithm": "safe-dqn-x"}
    save_net(os.path.join(args.run_dir, "checkpoint.pt"), learner.net, meta)


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_dataclass_arguments(p, Args)


def run(ns: argparse.Namespace) -> dict:
    """Entry point of ``cdr-bench train safe-dqn-x``."""
    return train(from_namespace(Args, ns))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    add_arguments(p)
    print(json.dumps(run(p.parse_args(argv)), indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
