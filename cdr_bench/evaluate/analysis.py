"""Analysis that works on any agent: the distribution of its first actions on a scenario
(multimodality, the paper's Fig. 9) and its decision latency. Subcommands ``multimodal`` and
``latency`` (registered by cdr_bench.cli)."""

from __future__ import annotations

import argparse
import json
import math
import os
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from cdr_bench.actions import HOLD, decode
from cdr_bench.errors import UserError
from cdr_bench.evaluate.cli import add_agent_args, agent_options
from cdr_bench.evaluate.remote import AgentFault, AgentOptions, RemoteAgent
from cdr_bench.evaluate.results import atomic_write_text
from cdr_bench.evaluate.runner import close_all, fault_message, load_for
from cdr_bench.scenarios import load_scenario
from cdr_bench.sim.core import SUCCESS
from cdr_bench.vector_env import VectorEnv


def register(sub: Any) -> None:
    mm = sub.add_parser("multimodal", help="distribution of successful first actions (§5.4)")
    mm.add_argument("agent", help="agent directory or agent.py")
    mm.add_argument("--scenario", default="tactical/head-on")
    mm.add_argument("--samples", type=int, default=1000)
    mm.add_argument("--seed", type=int, default=0)
    mm.add_argument(
        "--max-steps",
        type=int,
        default=0,
        help="cut follow-on rollouts after this many steps (a failure); 0 = horizon",
    )
    mm.add_argument("--threshold", type=float, default=0.05, help="mass threshold of a mode")
    mm.add_argument("--out", default=None, help="JSON results file (and a .png heat map beside it)")
    add_agent_args(mm)
    mm.set_defaults(func=cmd_multimodal)

    la = sub.add_parser("latency", help="decision latency (median / p99 ms) per batch size")
    la.add_argument("agent", help="agent directory or agent.py")
    la.add_argument("--batch-sizes", default="1,8,64,256")
    la.add_argument(
        "--decisions",
        type=int,
        default=1000,
        help="decisions timed per batch size (calls = max(--min-calls, decisions / batch))",
    )
    la.add_argument("--min-calls", type=int, default=20, help="timed calls per batch size (>=)")
    la.add_argument("--warmup", type=int, default=20, help="untimed calls before timing")
    la.add_argument("--scenario", default="medium")
    la.add_argument("--threads", type=int, default=1)
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


def first_action_distribution(
    agent: RemoteAgent, scenario: str, samples: int, seed: int = 0, max_steps: int = 0
) -> dict[str, Any]:
    """Sample the first action ``samples`` times from the scenario's start (one batched call, so
    every row draws its own noise), then validate each by a follow-on rollout with the same
    agent. Returns counts per first action of all samples and of successful ones.

    Every sample is an episode of the same seed in one :class:`VectorEnv`; learning intruders,
    if any, hold."""
    env = VectorEnv(scenario, num_envs=samples)
    obs, masks = env.reset(seeds=np.full(samples, seed))
    try:
        agent.reset(seed)
    except AgentFault as f:
        raise UserError(fault_message(f, agent, f"reset(seed) on {scenario!r}")) from None
    first = None
    t = 0
    act = np.full((samples, env.n_agents), HOLD, dtype=np.int64)
    flying = env.flying[:, 0]
    while flying.any() and not (max_steps and t >= max_steps):
        t += 1
        act[:, 0] = HOLD
        try:
            act[flying, 0] = agent.act_batch(obs[flying, 0], masks[flying, 0])
        except AgentFault as f:
            raise UserError(fault_message(f, agent, f"{scenario!r}, step {t}")) from None
        if first is None:
            first = act[:, 0].copy()
        out = env.step(act)
        obs, masks = out.obs, out.action_mask
        flying = env.flying[:, 0]
    ok = env.sim.ac_outcome[:, 0] == SUCCESS
    assert first is not None, "the scenario ended before the first decision"
    return {
        "all": np.bincount(first, minlength=27).tolist(),
        "success": np.bincount(first[ok], minlength=27).tolist(),
        "success_rate": float(ok.mean()),
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
    shows every sampled first action. Written atomically (temporary file in the same folder,
    then ``os.replace``)."""
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
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".tmp.png", dir=out.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            fig.savefig(f, format="png", dpi=80)
            f.flush()
            os.fsync(f.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, out)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    finally:
        plt.close(fig)


def multimodal(
    agent_path: str,
    scenario: str,
    samples: int,
    seed: int,
    options: AgentOptions,
    max_steps: int = 0,
    threshold: float = 0.05,
    out: str | os.PathLike[str] | None = None,
) -> dict[str, Any]:
    """First-action distribution, its modes and (with ``out``) the JSON and heat map files."""
    if samples < 1:
        raise UserError("--samples must be >= 1")
    _check_scenario(scenario)
    try:
        agent = _load(agent_path, scenario, options)
        d = first_action_distribution(agent, scenario, samples, seed, max_steps)
    finally:
        close_all()
    summ = mode_summary(d["success"], threshold)
    res = {
        "agent": str(agent_path),
        "scenario": scenario,
        "samples": samples,
        "seed": seed,
        "threshold": threshold,
        **d,
        **summ,
    }
    if out is not None:
        o = Path(out)
        # PNG first, JSON last: a JSON file means the run finished and its picture is there.
        heatmap(
            d["success"],
            f"{Path(str(agent_path)).name} on {scenario}: {samples} samples, "
            f"follow-on success {100 * d['success_rate']:.1f} %",
            o.with_suffix(".png"),
            all_counts=d["all"],
        )
        atomic_write_text(o, json.dumps(res, indent=1) + "\n")
    return res


def cmd_multimodal(ns: argparse.Namespace) -> int:
    options = agent_options(ns, ns.agent)
    res = multimodal(
        ns.agent, ns.scenario, ns.samples, ns.seed, options, ns.max_steps, ns.threshold, ns.out
    )
    print(
        f"{ns.scenario}: {ns.samples} samples, follow-on success {res['success_rate']:.3f}, "
        f"{res['modes']} mode(s) >= {ns.threshold:.0%}, normalised entropy "
        f"{res['normalised_entropy']:.3f}"
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
    try:
        sizes = [int(x) for x in ns.batch_sizes.split(",")]
    except ValueError:
        msg = f"--batch-sizes: expected integers separated by commas, got {ns.batch_sizes!r}"
        raise err(msg) from None
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
