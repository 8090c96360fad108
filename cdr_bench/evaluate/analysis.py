"""Analysis that works on any agent: the distribution of its first actions on a scenario
(multimodality, the paper's Fig. 9, and the manoeuvre families its successful samples reach per
episode, docs/model.md §10.4) and its decision latency. Subcommands ``multimodal`` and
``latency`` (registered by cdr_bench.cli)."""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from cdr_bench.actions import HOLD, decode
from cdr_bench.checks import MAX_BATCH_SIZE, int_list, ranged
from cdr_bench.errors import UserError
from cdr_bench.evaluate.cli import (
    add_agent_args,
    add_base_seed_arg,
    add_count_arg,
    add_episodes_arg,
    agent_options,
)
from cdr_bench.evaluate.remote import AgentFault, AgentOptions, RemoteAgent
from cdr_bench.evaluate.results import atomic_write_text, check_output_path
from cdr_bench.evaluate.rollout import Decisions, fly
from cdr_bench.evaluate.runner import batch_seed, close_all, fault_message, load_for
from cdr_bench.evaluate.search import FAMILIES, FAMILY_ACTIONS, search_families
from cdr_bench.evaluate.seeds import episode_seeds
from cdr_bench.render import figure_png
from cdr_bench.scenarios import ScenarioConfig, load_scenario
from cdr_bench.sim.core import SUCCESS
from cdr_bench.vector_env import VectorEnv


def register(sub: Any) -> None:
    mm = sub.add_parser(
        "multimodal",
        help="distribution of successful first actions and manoeuvre families per episode (§5.4)",
    )
    mm.add_argument("agent", help="agent directory or agent.py")
    mm.add_argument("--scenario", default="tactical/head-on")
    add_episodes_arg(
        mm,
        DEFAULT_EPISODES,
        f"episodes of the scenario (the evaluation's first ones; {DEFAULT_EPISODES})",
    )
    mm.add_argument(
        "--samples",
        type=ranged(int, 1, MAX_BATCH_SIZE),
        default=DEFAULT_SAMPLES,
        help=f"samples per episode ({DEFAULT_SAMPLES})",
    )
    add_base_seed_arg(mm)
    mm.add_argument(
        "--search",
        action="store_true",
        help="also search each episode's feasible manoeuvre families (docs/model.md §8.3)",
    )
    add_count_arg(
        mm,
        "--max-steps",
        0,
        0,
        "cut follow-on rollouts after this many steps (a failure); 0 = horizon",
    )
    mm.add_argument(
        "--threshold",
        type=ranged(float, 0, 1),
        default=0.05,
        help="mass threshold of a mode, 0 to 1 (0.05)",
    )
    mm.add_argument("--out", default=None, help="JSON results file (and a .png heat map beside it)")
    add_agent_args(mm)
    mm.set_defaults(func=cmd_multimodal)

    la = sub.add_parser("latency", help="decision latency (median / p99 ms) per batch size")
    la.add_argument("agent", help="agent directory or agent.py")
    la.add_argument(
        "--batch-sizes",
        type=int_list(1, MAX_BATCH_SIZE),
        default=[1, 8, 64, 256],
        help=f"comma-separated batch sizes, each 1 to {MAX_BATCH_SIZE} (1,8,64,256)",
    )
    add_count_arg(
        la,
        "--decisions",
        1,
        1000,
        "decisions timed per batch size (calls = max(--min-calls, decisions / batch))",
    )
    add_count_arg(la, "--min-calls", 1, 20, "timed calls per batch size (>=)")
    add_count_arg(la, "--warmup", 0, 20, "untimed calls before timing")
    la.add_argument("--scenario", default="medium")
    la.add_argument(
        "--threads",
        type=ranged(int, 1, 1024),
        default=1,
        help="threads of the agent's numerical libraries (1)",
    )
    la.add_argument("--out", default=None)
    add_agent_args(la)
    la.set_defaults(func=cmd_latency)


def _load(agent: str, scenario: str, options: AgentOptions) -> RemoteAgent:
    """The agent at ``agent`` in its own process, constructed with the observation and action
    spaces of ``scenario`` as the evaluator does. Every failure is a one-line UserError."""
    try:
        config = load_scenario(scenario)
    except UserError:
        raise
    except Exception as e:
        raise UserError(f"scenario {scenario!r}: {e}") from None
    return load_for(agent, config, options)


def _check_scenario(name: str) -> None:
    try:
        load_scenario(name)
    except Exception as e:
        raise UserError(f"scenario {name!r}: {e}") from None


DEFAULT_EPISODES = 20
"""Episodes of ``cdr-bench multimodal`` (the evaluation's first ones)."""
DEFAULT_SAMPLES = 50
"""Samples of the first action per episode."""
MAX_ROWS = 1024
"""Most rollouts of one agent call: episodes are sampled in chunks of ``MAX_ROWS // samples``."""


def first_action_distribution(
    agent: RemoteAgent,
    scenario: str | ScenarioConfig,
    samples: int,
    seed: int = 0,
    max_steps: int = 0,
    episodes: int = 1,
) -> dict[str, Any]:
    """Sample the first action ``samples`` times in each of the first ``episodes`` episodes of
    the evaluation (base seed ``seed``: :func:`~cdr_bench.evaluate.seeds.episode_seeds`), then
    validate each by a follow-on rollout with the same agent.

    The copies of an episode differ only by the agent's own randomness: all rows of a chunk of
    episodes go through one batched call per step, so every row draws its own noise; the agent
    is reset before each chunk (``MAX_ROWS // samples`` episodes) with the seed the evaluator
    gives batch ``chunk``. Learning intruders, if any, hold.

    Returns:
        ``all`` and ``success`` (27 counts of first actions over every sample, and over the
        samples whose episode succeeded), ``success_rate``, and ``per_episode``: for each episode
        its seed, ``all``, ``success``, ``success_rate``, ``family_successes`` (per manoeuvre
        family, docs/model.md §8.3, the successful samples whose first manoeuvre, i.e. first
        action other than hold, is of that family) and ``families`` (those with at least one).
    """
    config = load_scenario(scenario) if isinstance(scenario, str) else scenario
    chash = config.config_hash()
    seeds = episode_seeds(seed, config.id, chash, 0, episodes)
    per_chunk = max(1, MAX_ROWS // samples)
    per_episode = []
    for chunk, lo in enumerate(range(0, episodes, per_chunk)):
        chunk_seeds = seeds[lo : lo + per_chunk]
        n = len(chunk_seeds) * samples
        env = VectorEnv(config, num_envs=n)
        obs, masks = env.reset(seeds=np.repeat(np.asarray(chunk_seeds, dtype=np.uint64), samples))
        try:
            agent.reset(batch_seed(seed, config.id, chash, chunk))
        except AgentFault as f:
            raise UserError(fault_message(f, agent, f"reset(seed) on {config.id!r}")) from None
        first = None
        move = np.full(n, HOLD, dtype=np.int64)  # the first action other than hold

        def decide(d: Decisions) -> Any:
            try:
                return agent.act_batch(d.obs, d.masks)
            except AgentFault as fault:
                at = f"{config.id!r}, step {d.t + 1}"
                raise UserError(fault_message(fault, agent, at)) from None

        def on_step(act: np.ndarray, _: Any) -> None:
            nonlocal first, move
            if first is None:
                first = act[:, 0].copy()
            move = np.where(move == HOLD, act[:, 0], move)

        fly(env, obs, masks, decide, drive="ownship", max_steps=max_steps, on_step=on_step)
        assert first is not None, "the scenario ended before the first decision"
        ok = env.outcomes[:, 0] == SUCCESS
        for i, episode_seed in enumerate(chunk_seeds):
            rows = slice(i * samples, (i + 1) * samples)
            sampled, won = first[rows], ok[rows]
            success = np.bincount(sampled[won], minlength=27)
            moves = np.bincount(move[rows][won], minlength=27)
            per_family = {f: int(sum(moves[a] for a in FAMILY_ACTIONS[f])) for f in FAMILIES}
            per_episode.append(
                {
                    "episode": lo + i,
                    "seed": int(episode_seed),
                    "all": np.bincount(sampled, minlength=27).tolist(),
                    "success": success.tolist(),
                    "success_rate": float(won.mean()),
                    "family_successes": per_family,
                    "families": [f for f in FAMILIES if per_family[f]],
                }
            )
    total_all = np.sum([e["all"] for e in per_episode], axis=0, dtype=np.int64)
    total_success = np.sum([e["success"] for e in per_episode], axis=0, dtype=np.int64)
    return {
        "all": total_all.tolist(),
        "success": total_success.tolist(),
        "success_rate": float(total_success.sum() / max(total_all.sum(), 1)),
        "per_episode": per_episode,
    }


def family_summary(per_episode: list[dict[str, Any]]) -> dict[str, Any]:
    """How many distinct manoeuvre families each episode's successful samples reach: the list,
    its distribution (0..5), its mean, and per family the episodes that reach it."""
    counts = [len(e["families"]) for e in per_episode]
    return {
        "families_per_episode": counts,
        "families_distribution": {str(k): counts.count(k) for k in range(len(FAMILIES) + 1)},
        "families_mean": float(np.mean(counts)) if counts else 0.0,
        "family_episodes": {f: sum(f in e["families"] for e in per_episode) for f in FAMILIES},
    }


def mode_summary(counts: list[int], threshold: float = 0.05) -> dict:
    c = np.asarray(counts, float)
    if c.sum() == 0:
        return {"modes": 0, "normalised_entropy": 0.0}
    p = c / c.sum()
    nz = p[p > 0]
    return {
        "modes": int((p >= threshold).sum()),
        "normalised_entropy": max(0.0, float(-(nz * np.log(nz)).sum() / math.log(27))),
    }


def heatmap(
    counts: list[int],
    title: str,
    out_png: str | os.PathLike[str],
    all_counts: list[int] | None = None,
) -> None:
    """Fig. 9 style: three 3x3 panels (climb / level / descend), heading change x speed change,
    of the successful first actions as shares of all samples; with ``all_counts`` a first row
    shows every sampled first action. Written atomically
    (:func:`~cdr_bench.evaluate.results.atomic_write_text`)."""
    try:
        import matplotlib
    except ImportError:
        raise UserError(
            "the heat map of --out needs matplotlib: pip install 'cdr-bench[plot]'"
        ) from None

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [("successful first actions", counts)]
    if all_counts is not None:
        rows.insert(0, ("all sampled first actions", all_counts))
    n = float(max(sum(all_counts if all_counts is not None else counts), 1))
    fig, axes = plt.subplots(
        len(rows), 3, figsize=(11, 3.4 * len(rows)), squeeze=False, layout="constrained"
    )
    for i, (label, cnt) in enumerate(rows):
        c = np.asarray(cnt, float).reshape(3, 3, 3) / n  # (psi, v, h), share of all samples
        vmax = max(float(c.max()), 1e-9)  # per row, so that rare successes stay visible
        for j, (name, h) in enumerate((("climb", 2), ("level", 1), ("descend", 0))):
            ax = axes[i, j]
            m = c[:, :, h].T  # rows: speed, cols: heading
            im = ax.imshow(m, vmin=0, vmax=vmax, cmap="viridis", origin="lower")
            ax.set_xticks(range(3), ["left", "hold", "right"])
            ax.set_yticks(range(3), ["slower", "keep", "faster"])
            ax.set_title(f"{name}: {label}, {100 * m.sum():.1f} %", fontsize=9)
            for (r, k), v in np.ndenumerate(m):
                ax.text(
                    k, r, f"{v:.2f}", ha="center", va="center", color="w" if v < vmax / 2 else "k"
                )
        fig.colorbar(im, ax=axes[i, :].tolist(), shrink=0.8, label="share of all samples")
    fig.suptitle(title)
    out = Path(out_png)
    try:
        png = figure_png(fig, 80)
    except OSError as e:
        raise UserError(f"{out}: cannot write it ({e.strerror or e})") from None
    atomic_write_text(out, png)


def multimodal(
    agent_path: str,
    scenario: str,
    samples: int,
    seed: int,
    options: AgentOptions,
    max_steps: int = 0,
    threshold: float = 0.05,
    out: str | os.PathLike[str] | None = None,
    episodes: int = DEFAULT_EPISODES,
    search: bool = False,
) -> dict[str, Any]:
    """First-action distribution over ``episodes`` episodes (``samples`` each), its modes, the
    manoeuvre families each episode's successful samples reach (with ``search``, beside those
    the search finds, docs/model.md §8.3) and (with ``out``) the JSON and heat map files."""
    if samples < 1 or episodes < 1:
        raise UserError("--samples and --episodes must be >= 1")
    _check_scenario(scenario)
    config = load_scenario(scenario)
    try:
        agent = _load(agent_path, scenario, options)
        d = first_action_distribution(agent, config, samples, seed, max_steps, episodes)
    finally:
        close_all()
    summ = mode_summary(d["success"], threshold)
    fam = family_summary(d["per_episode"])
    res = {
        "agent": str(agent_path),
        "scenario": scenario,
        "samples": samples,
        "episodes": episodes,
        "seed": seed,
        "threshold": threshold,
        **{k: d[k] for k in ("all", "success", "success_rate")},
        **summ,
        **fam,
        "per_episode": d["per_episode"],
    }
    if search:
        found = search_families(config, [e["seed"] for e in d["per_episode"]])
        for e, r in zip(res["per_episode"], found, strict=True):
            e["feasible_families"] = r.families
        res["feasible_families_mean"] = float(np.mean([len(r.families) for r in found]))
    if out is not None:
        o = Path(out)
        # PNG first, JSON last: a JSON file means the run finished and its picture is there.
        heatmap(
            d["success"],
            f"{Path(str(agent_path)).name} on {scenario}: {episodes} episode(s) x {samples} "
            f"samples, follow-on success {100 * d['success_rate']:.1f} %, "
            f"{fam['families_mean']:.2f} families per episode",
            o.with_suffix(".png"),
            all_counts=d["all"],
        )
        atomic_write_text(o, json.dumps(res, indent=1) + "\n")
    return res


def cmd_multimodal(ns: argparse.Namespace) -> int:
    if ns.out:
        check_output_path(ns.out)
        check_output_path(Path(ns.out).with_suffix(".png"), "--out: the heat map")
    options = agent_options(ns, ns.agent)
    res = multimodal(
        ns.agent,
        ns.scenario,
        ns.samples,
        ns.seed,
        options,
        ns.max_steps,
        ns.threshold,
        ns.out,
        episodes=ns.episodes,
        search=ns.search,
    )
    print(
        f"{ns.scenario}: {ns.episodes} episode(s) x {ns.samples} samples, follow-on success "
        f"{res['success_rate']:.3f}, {res['modes']} mode(s) >= {ns.threshold:.0%}, normalised "
        f"entropy {res['normalised_entropy']:.3f}"
    )
    dist = ", ".join(f"{k}: {v}" for k, v in res["families_distribution"].items() if v)
    per_family = ", ".join(f"{f} {n}" for f, n in res["family_episodes"].items())
    print(
        f"manoeuvre families reached per episode: mean {res['families_mean']:.2f} "
        f"(episodes with 0..5: {dist}); episodes reaching each: {per_family}"
    )
    if "feasible_families_mean" in res:
        print(f"  found by the search: mean {res['feasible_families_mean']:.2f} per episode")
    for e in res["per_episode"]:
        feasible = e.get("feasible_families")
        extra = "" if feasible is None else f" (search: {', '.join(feasible) or '-'})"
        print(
            f"  episode {e['episode']:3d}: success {e['success_rate']:.2f}, families "
            f"{', '.join(e['families']) or '-'}{extra}"
        )
    for a in np.flatnonzero(res["all"]):
        print(
            f"  action {a:2d} {decode(int(a))}: sampled {res['all'][a]:5d}, "
            f"successful {res['success'][a]:5d}"
        )
    return 0


def cmd_latency(ns: argparse.Namespace) -> int:
    # Before the agent is loaded (and imports its numerical libraries): their thread pools read
    # these when they start. The evaluator itself imports no torch.
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = str(ns.threads)
    err = UserError
    if ns.out:
        check_output_path(ns.out)
    sizes = list(ns.batch_sizes)
    if min(sizes) < 1 or ns.decisions < 1 or ns.min_calls < 1 or ns.warmup < 0:
        raise err("--batch-sizes, --decisions and --min-calls must be >= 1, --warmup >= 0")
    _check_scenario(ns.scenario)
    agent = _load(ns.agent, ns.scenario, agent_options(ns, ns.agent))
    env = VectorEnv(ns.scenario, num_envs=max(sizes))
    all_obs, all_masks = env.reset(seeds=np.arange(max(sizes)))
    obs, masks = all_obs[:, 0], all_masks[:, 0]
    rows = []
    print("| batch | calls | decisions | median ms/call | p99 ms/call | median ms/decision |")
    print("|---:|---:|---:|---:|---:|---:|")
    for n in sizes:
        o, m = obs[:n], masks[:n]
        calls = max(ns.min_calls, math.ceil(ns.decisions / n))
        ts = np.empty(calls)
        try:
            for _ in range(ns.warmup):
                agent.act_batch(o, m)
            for i in range(calls):
                t0 = time.perf_counter()
                agent.act_batch(o, m)
                ts[i] = (time.perf_counter() - t0) * 1e3
        except AgentFault as f:
            close_all()
            raise UserError(fault_message(f, agent, f"a batch of {n} on {ns.scenario!r}")) from None
        med, p99 = float(np.median(ts)), float(np.percentile(ts, 99))
        rows.append(
            {
                "batch": n,
                "calls": calls,
                "decisions": calls * n,
                "median_ms": med,
                "p99_ms": p99,
                "median_ms_per_decision": med / n,
            }
        )
        print(f"| {n} | {calls} | {calls * n} | {med:.3f} | {p99:.3f} | {med / n:.4f} |")
    close_all()
    if ns.out:
        res = {"agent": str(ns.agent), "scenario": ns.scenario, "threads": ns.threads, "rows": rows}
        atomic_write_text(Path(ns.out), json.dumps(res, indent=1) + "\n")
    return 0
