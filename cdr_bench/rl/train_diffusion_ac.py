"""Diffusion-AC with DPSC: Algorithm 2 (training loop), readable top to bottom like CleanRL.

    python -m cdr_bench.rl.train_diffusion_ac --run-dir runs/dac --total-steps 200000
    cdr-bench train diffusion-ac --run-dir runs/dac --total-steps 200000

Outputs in ``run_dir``: ``log.jsonl`` (one JSON object per log interval, keys prefixed
``charts/``, ``losses/``, ``curriculum/``, ``eval/``), ``state.pt`` (full training state for
``--resume``), ``checkpoint.pt`` (small inference checkpoint, loaded by
agents/diffusion_ac/agent.py), ``curve.png`` and ``args.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from cdr_bench.rl.vecenv import N_STAGES, Curriculum, TrainEnv

if TYPE_CHECKING:
    from cdr_bench.rl.diffusion_ac import DiffusionAC

# torch is imported inside the functions that train, so that building the ``cdr-bench`` parser
# (which lists this trainer's flags) never imports it: ``cdr-bench evaluate`` stays torch-free.
SCHEDULES = ("linear", "cosine")
"""Noise schedules (the names of :data:`cdr_bench.rl.diffusion.SCHEDULES`; a test checks)."""

ABLATIONS = ("none", "no-diffusion", "no-double-q", "no-dpsc", "no-value-guidance")


@dataclass
class Args:
    run_dir: str = "runs/diffusion-ac"
    """directory for logs, checkpoints and the curve"""
    seed: int = 1
    """seed of torch, numpy and the episode-seed stream"""
    total_steps: int = 1_000_000
    """budget in environment transitions (one flying aircraft, one step)"""
    max_wall_minutes: float = 0.0
    """stop (and finish normally) after this wall time; 0 = no limit"""
    n_envs: int = 32
    """parallel episodes in the batched simulator"""
    curriculum: bool = True
    """DPSC on (stages 1..12) or off (train on ``scenario``)"""
    scenario: str = "medium"
    """training scenario without the curriculum"""
    ablation: str = "none"
    """one of: none, no-diffusion, no-double-q, no-dpsc, no-value-guidance (Table 3)"""
    schedule: str = "cosine"
    """noise schedule: "linear" (paper literal, alpha_bar_T ~ 0.90) or "cosine" (alpha_bar_T ~ 0)"""
    T: int = 10
    """diffusion steps"""
    width: int = 128
    """denoiser width (divisible by the 8 attention heads)"""
    n_blocks: int = 2
    """residual blocks in the denoiser"""
    critic_width: int = 128
    """critic hidden width (three layers)"""
    buffer_size: int = 1_000_000
    """replay capacity"""
    batch_size: int = 128
    """mini-batch size"""
    update_every: int = 4
    """one Algorithm-1 update per this many environment transitions"""
    learning_starts: int = 5_000
    """transitions collected before the first update"""
    gamma: float = 0.99
    """discount"""
    polyak: float = 5e-3
    """target-network Polyak coefficient rho"""
    lr_actor: float = 3e-4
    """Adam step size of the denoiser"""
    lr_critic: float = 1e-3
    """Adam step size of the critics"""
    tau_relative: bool = True
    """tau in units of the per-state std of Q over feasible actions (False = Eq. 37 literal)"""
    tau_start: float = 0.5
    """teacher temperature at stage 1"""
    tau_end: float = 0.2
    """teacher temperature at stage 12 (geometric in between); also the fixed tau without DPSC"""
    ce_weight: float = 0.1
    """lambda_CE of Eq. 39"""
    ce_input: str = "y0"
    """terminal-CE input: y0 (Eq. 39 literal), noise (y_T ~ N(0, I) at t = T) or none"""
    diffusion_target: str = "teacher"
    """denoiser target: teacher (Eq. 38 literal, log p*) or sample (log one-hot of a ~ p*)"""
    eps_smooth: float = 0.01
    """label smoothing epsilon of Eq. 38"""
    failure_penalty: float = 5.0
    """training-only extra penalty when an episode ends in LoS/NMAC (0 = literal reward)"""
    max_episode_steps: int = 200
    """training-only episode cut (bootstrapped, counted as a failure); 0 = scenario horizon"""
    explore: str = "sample"
    """action selection while training: "sample" from the masked softmax or "argmax" (paper)"""
    window: int = 100
    """DPSC promotion window (episodes)"""
    promote_at: float = 0.9
    """DPSC promotion threshold on the rolling success rate"""
    log_every: int = 10_000
    """transitions between log lines"""
    checkpoint_every: int = 100_000
    """transitions between checkpoints"""
    eval_episodes: int = 100
    """episodes per density for the final quick evaluation (0 = skip)"""
    resume: bool = False
    """continue from run_dir/state.pt"""
    threads: int = 1
    """torch intra-op threads"""
    progress: bool = True
    """show a tqdm progress bar"""
    extra: dict = field(default_factory=dict)
    """free-form notes stored in args.json"""


def teacher_tau(args: Args, stage: int | None) -> float:
    """Temperature schedule: geometric from tau_start (stage 1) to tau_end (stage 12);
    tau_end without the curriculum; infinity without value guidance."""
    if args.ablation == "no-value-guidance":
        return math.inf
    if stage is None:
        return args.tau_end
    frac = (stage - 1) / (N_STAGES - 1)
    return args.tau_start * (args.tau_end / args.tau_start) ** frac


def build_agent(args: Args, obs_dim: int) -> DiffusionAC:
    from cdr_bench.rl.diffusion_ac import DiffusionAC, PolicyConfig, UpdateConfig

    pcfg = PolicyConfig(
        obs_dim=obs_dim,
        width=args.width,
        n_blocks=args.n_blocks,
        T=args.T,
        schedule=args.schedule,
        critic_width=args.critic_width,
        actor="categorical" if args.ablation == "no-diffusion" else "diffusion",
        twin=args.ablation != "no-double-q",
    )
    ucfg = UpdateConfig(
        gamma=args.gamma,
        polyak=args.polyak,
        lr_actor=args.lr_actor,
        lr_critic=args.lr_critic,
        eps_smooth=args.eps_smooth,
        tau_relative=args.tau_relative,
        ce_weight=args.ce_weight,
        ce_input=args.ce_input,
        diffusion_target=args.diffusion_target,
    )
    return DiffusionAC(pcfg, ucfg)


def train(args: Args) -> dict:
    """Algorithm 2: train, write ``args.run_dir``, return the summary (also its last log line)."""
    import torch

    from cdr_bench.rl.quick_eval import quick_eval
    from cdr_bench.rl.replay import ReplayBuffer

    if args.ablation not in ABLATIONS:
        raise ValueError(f"ablation must be one of {ABLATIONS}, got {args.ablation!r}")
    if args.schedule not in SCHEDULES:
        raise ValueError(f"schedule must be one of {SCHEDULES}, got {args.schedule!r}")
    if args.ce_input not in ("y0", "noise", "none"):
        raise ValueError(f"ce_input must be one of y0, noise, none, got {args.ce_input!r}")
    if args.diffusion_target not in ("teacher", "sample"):
        raise ValueError(
            f"diffusion_target must be one of teacher, sample, got {args.diffusion_target!r}"
        )
    use_curriculum = args.curriculum and args.ablation != "no-dpsc"
    os.makedirs(args.run_dir, exist_ok=True)
    torch.set_num_threads(args.threads)

    # Seeding.
    torch.manual_seed(args.seed)
    rng = np.random.default_rng(args.seed)
    gen = torch.Generator().manual_seed(args.seed)

    # Environment, agent, storage.
    env = TrainEnv(
        args.n_envs,
        seed=args.seed,
        scenario=args.scenario,
        curriculum=Curriculum(args.window, args.promote_at) if use_curriculum else None,
        failure_penalty=args.failure_penalty,
        max_episode_steps=args.max_episode_steps,
    )
    obs_dim = env.observe()[0].shape[1]
    agent = build_agent(args, obs_dim)
    buffer = ReplayBuffer(args.buffer_size, obs_dim)
    step, n_updates, wall_before = 0, 0, 0.0
    state_path = os.path.join(args.run_dir, "state.pt")
    log_path = os.path.join(args.run_dir, "log.jsonl")
    if args.resume:
        st = torch.load(state_path, map_location="cpu", weights_only=False)
        agent.load_state_dict(st["agent"])
        step, n_updates, wall_before = st["step"], st["updates"], st["wall_s"]
        if env.curriculum is not None:
            env.curriculum.stage = st["stage"]
            env._build()
        rng = np.random.default_rng(st["rng_seed"])
        env.rng = np.random.default_rng(st["rng_seed"] + 1)
        # The replay buffer is not saved (hundreds of MB); it refills after learning_starts.
    else:
        with open(log_path, "w"):
            pass
    with open(os.path.join(args.run_dir, "args.json"), "w") as f:
        json.dump(dataclasses.asdict(args), f, indent=2)

    # The loop (Algorithm 2, batched over n_envs episodes).
    t0 = time.time()
    credit, last_log, last_ckpt = 0.0, step, step
    losses: dict[str, list[float]] = {}
    outcomes: list[int] = []
    pbar = None
    if args.progress:
        from tqdm import tqdm

        pbar = tqdm(total=args.total_steps, initial=step, unit="step", dynamic_ncols=True)
    tau = teacher_tau(args, env.curriculum.stage if env.curriculum else None)
    learn_from = step + args.learning_starts
    while step < args.total_steps:
        if args.max_wall_minutes and time.time() - t0 > 60 * args.max_wall_minutes:
            break
        obs, mask, flying = env.observe()
        actions = np.full(len(flying), 13, dtype=np.int64)
        if flying.any():
            a = agent.policy.act(
                torch.from_numpy(obs[flying]),
                torch.from_numpy(mask[flying]),
                gen,
                sample=args.explore == "sample",
            )
            actions[flying] = a.numpy()
        tr = env.step(actions)
        n = len(tr["action"])
        buffer.add(
            *(tr[k] for k in ("obs", "mask", "action", "reward", "next_obs", "next_mask", "done"))
        )
        step += n
        outcomes += tr["finished"]
        if tr["promoted"]:
            assert env.curriculum is not None
            tau = teacher_tau(args, env.curriculum.stage)
            with open(log_path, "a") as f:
                f.write(
                    json.dumps(
                        {
                            "step": step,
                            "curriculum/promoted_to": env.curriculum.stage,
                            "wall_s": wall_before + time.time() - t0,
                        }
                    )
                    + "\n"
                )
        if step >= learn_from:
            credit += n / args.update_every
            while credit >= 1.0:
                credit -= 1.0
                b = buffer.sample(args.batch_size, rng)
                tb = {k: torch.from_numpy(v) for k, v in b.items()}
                for k, v in agent.update(tb, tau).items():
                    losses.setdefault(k, []).append(v)
                n_updates += 1
        if pbar is not None:
            pbar.update(n)
        if step - last_log >= args.log_every:
            last_log = step
            oc = np.array(outcomes) if outcomes else np.zeros(0)
            rec = {
                "step": step,
                "updates": n_updates,
                "wall_s": round(wall_before + time.time() - t0, 1),
                "curriculum/stage": env.curriculum.stage if env.curriculum else 0,
                "curriculum/tau": tau,
                "charts/success_rolling": env.success_rate(),
                "charts/episodes": env.episodes,
                "charts/episodes_in_interval": len(oc),
            }
            for code, name in ((1, "success"), (2, "nmac"), (3, "los_end"), (5, "timeout")):
                rec[f"charts/{name}"] = float(np.mean(oc == code)) if len(oc) else float("nan")
            rec.update({f"losses/{k}": float(np.mean(v)) for k, v in losses.items()})
            with open(log_path, "a") as f:
                f.write(json.dumps(rec) + "\n")
            if pbar is not None:
                pbar.set_postfix(
                    stage=rec["curriculum/stage"],
                    succ=f"{rec['charts/success_rolling']:.2f}",
                    lq=f"{rec.get('losses/loss_q', 0):.3f}",
                    lpi=f"{rec.get('losses/loss_diff', rec.get('losses/loss_ce', 0)):.3f}",
                )
            losses, outcomes = {}, []
        if step - last_ckpt >= args.checkpoint_every:
            last_ckpt = step
            _save(args, agent, env, step, n_updates, wall_before + time.time() - t0, rng)
    if pbar is not None:
        pbar.close()
    wall = wall_before + time.time() - t0
    _save(args, agent, env, step, n_updates, wall, rng)

    # Final quick evaluation (argmax, the paper's inference rule) and the learning curve.
    summary: dict = {
        "step": step,
        "updates": n_updates,
        "wall_s": round(wall, 1),
        "stage": env.curriculum.stage if env.curriculum else 0,
    }
    if args.eval_episodes:
        agent.policy.eval()
        egen = torch.Generator().manual_seed(12345)

        def act_batch(o: np.ndarray, m: np.ndarray) -> np.ndarray:
            return agent.policy.act(torch.from_numpy(o), torch.from_numpy(m), egen).numpy()

        for sc in ("low", "medium", "high"):
            summary[f"eval/{sc}"] = quick_eval(act_batch, sc, args.eval_episodes, seed=10_000)
    with open(log_path, "a") as f:
        f.write(json.dumps({"final": summary}) + "\n")
    try:
        plot_curve(log_path, os.path.join(args.run_dir, "curve.png"))
    except Exception as e:  # plotting must never lose a finished run
        print(f"curve not written: {e}")
    return summary


def _save(args, agent, env, step, n_updates, wall, rng) -> None:
    import torch

    from cdr_bench.rl.diffusion_ac import save_policy

    st = {
        "agent": agent.state_dict(),
        "step": step,
        "updates": n_updates,
        "wall_s": wall,
        "stage": env.curriculum.stage if env.curriculum else 0,
        "rng_seed": int(rng.integers(0, 2**31)),
    }
    torch.save(st, os.path.join(args.run_dir, "state.pt.tmp"))
    os.replace(os.path.join(args.run_dir, "state.pt.tmp"), os.path.join(args.run_dir, "state.pt"))
    meta = {
        "step": step,
        "updates": n_updates,
        "wall_s": round(wall, 1),
        "args": dataclasses.asdict(args),
    }
    save_policy(os.path.join(args.run_dir, "checkpoint.pt"), agent.policy, meta)


def plot_curve(log_path: str, out_png: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [json.loads(x) for x in open(log_path) if x.strip()]
    rows = [r for r in rows if "charts/success_rolling" in r]
    if not rows:
        return
    s = [r["step"] for r in rows]
    fig, ax = plt.subplots(1, 3, figsize=(15, 4))
    ax[0].plot(s, [r["charts/success_rolling"] for r in rows], label="rolling success")
    ax[0].plot(s, [r["charts/success"] or 0 for r in rows], alpha=0.5, label="success in interval")
    ax[0].set_ylim(0, 1)
    ax[0].legend()
    ax[1].plot(s, [r["curriculum/stage"] for r in rows])
    ax[1].set_title("DPSC stage")
    for k in ("losses/loss_q", "losses/loss_diff", "losses/loss_ce"):
        if any(k in r for r in rows):
            ax[2].plot(s, [r.get(k, np.nan) for r in rows], label=k.split("/")[1])
    ax[2].set_yscale("log")
    ax[2].legend()
    for a in ax:
        a.set_xlabel("environment steps")
    fig.tight_layout()
    fig.savefig(out_png, dpi=80)
    plt.close(fig)


def field_docs() -> dict[str, str]:
    """The docstring under each Args field, read from this file's source."""
    import ast
    import inspect

    tree = ast.parse(inspect.getsource(Args))
    body = tree.body[0].body  # type: ignore[attr-defined]
    docs = {}
    for a, b in zip(body, body[1:], strict=False):
        if isinstance(a, ast.AnnAssign) and isinstance(b, ast.Expr):
            docs[a.target.id] = str(b.value.value)  # type: ignore[union-attr,attr-defined]
    return docs


def add_arguments(p: argparse.ArgumentParser) -> None:
    """One flag per Args field (``--no-curriculum`` etc. for booleans)."""
    docs = field_docs()
    for f in dataclasses.fields(Args):
        if f.name == "extra":
            continue
        flag = "--" + f.name.replace("_", "-")
        doc = docs.get(f.name, "").replace("%", "%%") + f" (default: {f.default})"
        if f.type in ("bool", bool):
            p.add_argument(flag, action=argparse.BooleanOptionalAction, default=f.default, help=doc)
        else:
            typ = {"int": int, "float": float, "str": str}[str(f.type)]
            p.add_argument(flag, type=typ, default=f.default, help=doc)


def args_from_namespace(ns: argparse.Namespace) -> Args:
    return Args(
        **{f.name: getattr(ns, f.name) for f in dataclasses.fields(Args) if f.name != "extra"}
    )


def run(ns: argparse.Namespace) -> dict:
    """Entry point of ``cdr-bench train diffusion-ac``."""
    return train(args_from_namespace(ns))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    add_arguments(p)
    summary = train(args_from_namespace(p.parse_args(argv)))
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
