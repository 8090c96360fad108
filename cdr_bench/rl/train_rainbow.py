"""Rainbow-DQN with action masks (:mod:`cdr_bench.rl.rainbow`), read top to bottom like CleanRL.

    cdr-bench train rainbow --run-dir runs/rainbow --total-steps 200000

Same environment, observation and reward as Diffusion-AC (:class:`~cdr_bench.rl.vecenv.TrainEnv`
with the DPSC curriculum, failure penalty 5 and a 200-step training cut by default), gamma 0.99,
width 128. Outputs in ``run_dir``: ``log.jsonl``, ``state.pt`` (for ``--resume``; the replay
buffer is not saved), ``checkpoint.pt`` (small, loaded by agents/rainbow/agent.py with
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
    run_dir: str = "runs/rainbow"
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
    from cdr_bench.rl.rainbow import Rainbow, RainbowConfig
    from cdr_bench.rl.replay import NStepAccumulator, PrioritizedReplayBuffer

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
    cfg = RainbowConfig(obs_dim, args.width, args.n_atoms, args.v_min, args.v_max, args.sigma0)
    learner = Rainbow(cfg, lr=args.lr)
    buffer = PrioritizedReplayBuffer(args.buffer_size, obs_dim, alpha=args.alpha)
    nstep = NStepAccumulator(args.n_envs, args.n_step, args.gamma)
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
    write_args(args.run_dir, args, algorithm="rainbow")

    # The loop.
    t0 = time.time()
    credit, last_log, last_ckpt = 0.0, step, step
    losses: list[float] = []
    outcomes: list[int] = []
    pbar = None
    if args.progress:
        from tqdm import tqdm

        pbar = tqdm(total=args.total_steps, initial=step, unit="step", dynamic_ncols=True)
    learn_from = step + args.learning_starts
    beta = args.beta_start
    while step < args.total_steps:
        if args.max_wall_minutes and time.time() - t0 > 60 * args.max_wall_minutes:
            break
        obs, mask, _ = env.observe()
        learner.net.reset_noise()  # noisy nets explore: a fresh noise sample per acting step
        actions = learner.net.act(torch.from_numpy(obs), torch.from_numpy(mask)).numpy()
        tr = env.step(actions)
        nt = nstep.push(
            tr["obs"],
            tr["mask"],
            tr["action"],
            tr["reward"],
            tr["next_obs"],
            tr["next_mask"],
            tr["done"],
            tr["ended"],
        )
        if len(nt["action"]):
            buffer.add(
                nt["obs"],
                nt["mask"],
                nt["action"],
                nt["reward"],
                nt["next_obs"],
                nt["next_mask"],
                nt["done"],
                nt["discount"],
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
        if step >= learn_from and len(buffer) >= args.batch_size:
            credit += n / args.update_every
            beta = args.beta_start + (1.0 - args.beta_start) * min(1.0, step / args.total_steps)
            while credit >= 1.0:
                credit -= 1.0
                b = buffer.sample(args.batch_size, rng, beta)
                idx = b.pop("index")
                tb = {k: torch.from_numpy(v) for k, v in b.items()}
                losses.append(learner.update(tb, args.polyak)["loss_ce"])
                buffer.update_priorities(idx, learner.priorities)
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
                "charts/beta": beta,
            }
            if losses:
                rec["losses/loss_ce"] = float(np.mean(losses))
            log.write(rec)
            if pbar is not None:
                pbar.set_postfix(
                    stage=rec["curriculum/stage"],
                    succ=f"{rec['charts/success_rolling']:.2f}",
                    loss=f"{rec.get('losses/loss_ce', 0):.3f}",
                )
            losses, outcomes = [], []
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
        plot_curve(log.path, os.path.join(args.run_dir, "curve.png"), "Rainbow-DQN")
    except Exception as e:  # plotting must never lose a finished run
        print(f"curve not written: {e}")
    return summary


def _save(args, learner, env, step, n_updates, wall, rng) -> None:
    import torch

    from cdr_bench.rl.rainbow import save_net

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
    meta = {"step": step, "updates": n_updates, "wall_s": round(wall, 1), "algorithm": "rainbow"}
    save_net(os.path.join(args.run_dir, "checkpoint.pt"), learner.net, meta)


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_dataclass_arguments(p, Args)


def run(ns: argparse.Namespace) -> dict:
    """Entry point of ``cdr-bench train rainbow``."""
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
