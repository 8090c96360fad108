"""Throughput of ``cdr-bench evaluate``: episodes/s of the reference agents at high density.

Runs the same code path as the CLI (lock-step batches on the batched simulator, result files
written) in this process, one core. Usage:

    OMP_NUM_THREADS=1 taskset -c 1 python benchmarks/evaluate_throughput.py [--episodes 1000]

Target (issue 3): 1000 high-density episodes with ``direct`` in under 30 s on one core.
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from cdr_bench.evaluate.api import Job, evaluate
from cdr_bench.scenarios import load_scenario

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--episodes", type=int, default=1000)
    p.add_argument("--scenario", default="high")
    p.add_argument("--agents", nargs="+", default=["direct", "mvp"])
    args = p.parse_args()
    cfg = load_scenario(args.scenario)
    print(f"# {platform.machine()}, python {platform.python_version()}, numpy {np.__version__}")
    print("| agent | scenario | episodes | wall s | episodes/s | mean steps/episode |")
    print("|---|---|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.agents:
            out = Path(tmp) / f"{name}.json"
            t0 = time.perf_counter()
            res = evaluate(
                ROOT / "agents" / name / "agent.py",
                [Job(cfg, args.episodes)],
                out,
                progress=False,
            )
            wall = time.perf_counter() - t0
            del res
            eps = [json.loads(x) for x in out.with_suffix(".jsonl").read_text().splitlines()]
            ms = sum(e["steps"] for e in eps) / len(eps)
            print(
                f"| {name} | {args.scenario} | {args.episodes} | {wall:.2f} | "
                f"{args.episodes / wall:,.0f} | {ms:.1f} |"
            )


if __name__ == "__main__":
    main()
