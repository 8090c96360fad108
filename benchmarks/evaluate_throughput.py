"""Throughput of ``cdr-bench evaluate`` against a reference commit measured in the same run.

Measures what the process boundary costs (the agent in its own process since 0.3: every
decision is a round trip over a pipe): ``cdr-bench evaluate AGENT --suite paper`` with the first
``--episodes`` of every scenario, for the current checkout and for ``--reference`` (default
``06fc59b``, the last commit that ran the agent inside the evaluator), one after the other in
every round, each command in a fresh process pinned to the same CPU (so the evaluator and the
agent process share one core, and the table counts every cycle the boundary adds).

Two times per run: ``loop`` is the evaluation itself (``timing.wall_s`` of the result: episodes,
decisions, result files), ``total`` the whole command (interpreter start, loading the agent).
The table gives medians over rounds and the median of the per-round ratios current/reference.

Run: ``python benchmarks/evaluate_throughput.py [--reference 06fc59b] [--agents mvp diffusion_ac]
[--episodes 200] [--rounds 3] [--cpu 1]``; ``--reference none`` measures the current checkout
only. The reference is checked out with ``git worktree`` into ``.bench/<commit>`` (ignored).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).parent))
from _checkout import checkout as _checkout  # noqa: E402
from _checkout import positive_int  # noqa: E402

# Runs the CLI of the checkout at argv[1] (bypassing the editable install of the current one).
_LAUNCH = (
    "import sys; code = sys.argv.pop(1)\n"
    "if code:\n"
    "    sys.meta_path[:] = [f for f in sys.meta_path if 'editable' not in repr(f).lower()]\n"
    "    sys.path.insert(0, code)\n"
    "from cdr_bench.cli import main\n"
    "raise SystemExit(main(sys.argv[1:]))\n"
)


def _run(agent: str, code: str, args: argparse.Namespace, tmp: str) -> dict[str, float]:
    out = Path(tmp) / f"{agent}-{'ref' if code else 'cur'}.json"
    for p in (out, out.with_suffix(".jsonl")):
        p.unlink(missing_ok=True)
    cmd = [sys.executable, "-c", _LAUNCH, code, "evaluate", str(ROOT / "agents" / agent)]
    cmd += ["--suite", "paper", "--episodes", str(args.episodes), "--out", str(out)]
    cmd += ["--no-progress"]
    if args.cpu is not None:
        cmd = ["taskset", "-c", str(args.cpu), *cmd]
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONHASHSEED="0")
    env.pop("PYTHONPATH", None)
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=code or ROOT)
    total = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"evaluate failed ({agent}, {code or 'current'}):\n{r.stderr[-3000:]}")
    loop = json.loads(out.read_text())["timing"]["wall_s"]
    return {"loop": float(loop), "total": total}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--reference", default="06fc59b")
    p.add_argument("--agents", nargs="+", default=["mvp", "diffusion_ac"])
    p.add_argument("--episodes", type=positive_int, default=200)
    p.add_argument("--rounds", type=positive_int, default=3)
    p.add_argument("--cpu", type=int, default=1, help="CPU to pin to (-1: no pinning)")
    args = p.parse_args()
    if args.cpu is not None and args.cpu < 0:
        args.cpu = None
    ref = None if args.reference == "none" else _checkout(args.reference)
    rows: dict[str, dict[str, list[Any]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.rounds):
            for agent in args.agents:
                r = rows.setdefault(agent, {"cur": [], "ref": []})
                r["cur"].append(_run(agent, "", args, tmp))
                if ref:
                    r["ref"].append(_run(agent, ref, args, tmp))
    print(
        f"`evaluate --suite paper --episodes {args.episodes}` (6 scenarios), {args.rounds} "
        f"round(s), pinned to CPU {args.cpu}; medians, ratio = median of per-round ratios"
    )
    print()
    print("| agent | time | current s | reference s | current / reference |")
    print("|---|---|---:|---:|---:|")
    for agent, r in rows.items():
        for k in ("loop", "total"):
            cur = statistics.median(x[k] for x in r["cur"])
            if r["ref"]:
                refv = statistics.median(x[k] for x in r["ref"])
                ratio = statistics.median(
                    c[k] / f[k] for c, f in zip(r["cur"], r["ref"], strict=True)
                )
                print(f"| {agent} | {k} | {cur:.2f} | {refv:.2f} | {ratio:.3f} |")
            else:
                print(f"| {agent} | {k} | {cur:.2f} | - | - |")


if __name__ == "__main__":
    main()
