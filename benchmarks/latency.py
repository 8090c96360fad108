"""Decision latency of every single-agent leaderboard entry, in one controlled run.

The latency columns of the leaderboard come from each result file: measured while that entry
was scored, on whatever the machine was doing then. Here every entry is measured in one run,
one after the other, under the same conditions: the agent (its submission's checkpoint) in its
own process as ``cdr-bench evaluate`` runs it (one thread, unconfined, ``--workers 1``), on the
same ``--episodes`` validation episodes of ``high``:

* *batched*: each step's call for every flying aircraft of the episodes; reported as the
  agent's total time over its decisions (ms per decision). (A result file's ``per_decision_ms``
  is the median over calls of a call's time over its decisions: it depends on how many calls
  come late in a batch, with few episodes still flying, so it compares badly across entries.)
* *single*: one decision per call, on the first observation of each episode, the agent loaded
  in this process (its own compute, without the process boundary): the setting of the
  paper's latency figure (Diffusion-AC 8.3 ms per decision on an RTX 4090).

The leaderboard's latency claim (Diffusion-AC slower per decision than the paper's baselines)
reads the single-decision medians of this run's JSON, ``leaderboard/latency.json``.

The batched figure includes the process boundary (a pipe round trip per call, shared by the
call's decisions), as the evaluator sees it.
Printed with the conditions: CPU, Python, threads and the load average before and after. Run
it with nothing else running.

Run: ``python benchmarks/latency.py [--episodes 200] [--json leaderboard/latency.json]``
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path
from typing import Any

from _checkout import positive_int

ROOT = Path(__file__).resolve().parents[1]


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _q(x: list[float], p: float) -> float:
    s = sorted(x)
    return s[min(len(s) - 1, int(round(p / 100 * (len(s) - 1))))]


def measure(episodes: int, names: list[str] | None) -> dict[str, Any]:
    from cdr_bench.evaluate.loader import load_agent
    from cdr_bench.evaluate.runner import close_all, load_for, run_batch, spaces_for
    from cdr_bench.evaluate.seeds import SPLITS, episode_seeds
    from cdr_bench.leaderboard.submission import load_submissions
    from cdr_bench.scenarios import load_scenario
    from cdr_bench.vector_env import VectorEnv

    config = load_scenario("high")
    base = SPLITS["validation"]
    seeds = episode_seeds(base, config.id, config.config_hash(), 0, episodes)
    obs, masks = VectorEnv(config, num_envs=episodes).reset(seeds=seeds)
    subs = [s for s in load_submissions(ROOT / "leaderboard") if s.track == "single-agent"]
    if names:
        subs = [s for s in subs if s.name in names]
    rows = []
    for sub in subs:
        if sub.checkpoint:
            os.environ["CDR_BENCH_CHECKPOINT"] = str(ROOT / sub.checkpoint)
        else:
            os.environ.pop("CDR_BENCH_CHECKPOINT", None)
        try:
            agent = load_for(str(ROOT / sub.agent), config)
            got = run_batch(agent, config, base, 0, episodes, episodes)
            calls = [float(x) for x in got["timing"]["per_call_ms"]]
            per = [float(x) for x in got["timing"]["per_decision_ms"]]
            decisions = sum(c / d for c, d in zip(calls, per, strict=True) if d > 0)
        finally:
            close_all()
        local = load_agent(ROOT / sub.agent, *spaces_for(config))
        single = []
        for i in range(episodes):
            t0 = time.perf_counter()
            local.act_batch(obs[i, :1], masks[i, :1])
            single.append(1e3 * (time.perf_counter() - t0))
        rows.append(
            {
                "entry": sub.name,
                "batched_ms": sum(calls) / max(decisions, 1.0),
                "calls": len(calls),
                "decisions": round(decisions),
                "single_ms": {"median": statistics.median(single), "p99": _q(single, 99)},
            }
        )
        print(
            f"{sub.name}: batched {rows[-1]['batched_ms']:.4f} ms, single "
            f"{rows[-1]['single_ms']['median']:.3f} ms per decision",
            file=sys.stderr,
        )
    return {"rows": rows}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=positive_int, default=200)
    ap.add_argument("--entries", nargs="*", default=None, help="only these entries")
    ap.add_argument("--json", default=None, help="also write the table as JSON here")
    args = ap.parse_args()
    from cdr_bench.errors import UserError
    from cdr_bench.evaluate.results import check_output_path
    from cdr_bench.leaderboard.submission import load_submissions

    known = {s.name for s in load_submissions(ROOT / "leaderboard") if s.track == "single-agent"}
    unknown = sorted(set(args.entries or ()) - known)
    if unknown:
        ap.error(f"--entries: no single-agent entry {', '.join(unknown)}")
    if args.json:
        try:
            check_output_path(args.json, "--json")
        except UserError as e:
            ap.error(str(e))
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    out = measure(args.episodes, args.entries)
    out["conditions"] = {
        "cpu": _cpu(),
        "python": platform.python_version(),
        "threads": os.environ["OMP_NUM_THREADS"],
        "episodes": args.episodes,
        "load_before": round(load0, 2),
        "load_after": round(os.getloadavg()[0], 2),
        "wall_s": round(time.perf_counter() - t0, 1),
    }
    c = out["conditions"]
    print(
        f"# {c['cpu']}, python {c['python']}, {c['threads']} thread, {c['episodes']} validation "
        f"episodes of high, load average {c['load_before']} before, {c['load_after']} after"
    )
    print("| entry | batched: ms per decision | decisions | single decision: ms, median | p99 |")
    print("|---|---:|---:|---:|---:|")
    for r in out["rows"]:
        s = r["single_ms"]
        print(
            f"| {r['entry']} | {r['batched_ms']:.4f} | {r['decisions']:,} | {s['median']:.3f} | "
            f"{s['p99']:.3f} |"
        )
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
