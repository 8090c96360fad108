"""Environment throughput on one core, against a reference commit measured in the same run.

Two numbers, both with random feasible actions and resets included:

* PettingZoo ``ParallelEnv`` steps/s (one env, ``cdr_bench.parallel_env``);
* batched environment episode-steps/s (``VectorEnv`` with ``--batch`` episodes and auto-reset;
  one episode-step advances one episode by one step). A reference commit that predates
  ``VectorEnv`` runs its own batched loop (``Simulator`` + ``observe`` + resets of finished
  episodes), the loop its evaluator and trainers ran.

Run: ``python benchmarks/env_throughput.py [--reference 9145d86] [--rounds 5] [--scenario high]``

This machine's speed varies by tens of percent from minute to minute, so every round runs the
current checkout and the reference one after the other, each in a fresh process pinned to the
same CPU, and the table gives medians and the median of the per-round ratios. The reference is
checked out with ``git worktree`` into ``.bench/<commit>`` (ignored by git).
``--reference none`` measures the current checkout only (CI's smoke run).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).parent))
from _checkout import checkout as _checkout  # noqa: E402
from _checkout import positive_int  # noqa: E402


def _worker(args: argparse.Namespace) -> None:
    """Measure in this process (``--worker``): prints one JSON line."""
    if args.cpu is not None and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {args.cpu})
    if args.code:  # the reference checkout: bypass the editable install of the current one
        sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in repr(f).lower()]
        sys.path.insert(0, args.code)
    import numpy as np

    import cdr_bench

    rng = np.random.default_rng(0)

    def pettingzoo(steps: int) -> float:
        env = cdr_bench.parallel_env(args.scenario)
        obs, _ = env.reset(seed=0)
        t0 = time.perf_counter()
        for _ in range(steps):
            actions = {}
            for a in env.agents:
                feasible = np.flatnonzero(obs[a]["action_mask"])
                actions[a] = int(feasible[rng.integers(len(feasible))])
            obs, *_ = env.step(actions)
            if not env.agents:
                obs, _ = env.reset()
        return steps / (time.perf_counter() - t0)

    def batched(steps: int, n: int) -> float:
        try:
            from cdr_bench.vector_env import VectorEnv
        except ImportError:
            return _batched_before_vector_env(args.scenario, steps, n, rng)
        from cdr_bench.vector_env import random_feasible_actions

        env = VectorEnv(args.scenario, num_envs=n, autoreset=True, seed=0)
        _, masks = env.reset()
        t0 = time.perf_counter()
        for _ in range(steps):
            masks = env.step(random_feasible_actions(masks, rng)).action_mask
        return steps * n / (time.perf_counter() - t0)

    pettingzoo(200)  # warm-up: compiled code loaded, caches filled
    batched(60, args.batch)  # 60 steps: episodes end, so the restart path is loaded too
    out = {
        "pettingzoo_steps_per_s": pettingzoo(args.steps),
        "batched_episode_steps_per_s": batched(args.batched_steps, args.batch),
        "code": os.path.dirname(cdr_bench.__file__),
    }
    print(json.dumps(out))


def _batched_before_vector_env(scenario: str, steps: int, n: int, rng: Any) -> float:
    """The batched loop of a checkout without ``VectorEnv``."""
    import numpy as np

    from cdr_bench.scenarios import load_scenario
    from cdr_bench.sim import Simulator, observe

    sim = Simulator(load_scenario(scenario), n_episodes=n)
    sim.reset(np.arange(n))
    t0 = time.perf_counter()
    for _ in range(steps):
        masks = sim.action_masks()
        sim.step((rng.random(masks.shape) * masks).argmax(-1))
        observe(sim)
        done = np.flatnonzero(~sim.ac_active.any(axis=1))
        if done.size:
            sim.reset(rng.integers(0, 2**62, done.size), episodes=done)
    return steps * n / (time.perf_counter() - t0)


def _measure(args: argparse.Namespace, code: str | None) -> dict[str, Any]:
    cmd = [sys.executable, __file__, "--worker", "--scenario", args.scenario]
    cmd += ["--steps", str(args.steps), "--batched-steps", str(args.batched_steps)]
    cmd += ["--batch", str(args.batch), "--cpu", str(args.cpu)]
    if code:
        cmd += ["--code", code]
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONHASHSEED="0")
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    if out.returncode != 0:
        raise SystemExit(f"worker failed:\n{out.stderr[-3000:]}")
    result: dict[str, Any] = json.loads(out.stdout.strip().splitlines()[-1])
    return result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reference", default="9145d86", help="commit to compare with, or 'none'")
    ap.add_argument("--rounds", type=positive_int, default=5)
    ap.add_argument("--scenario", default="high")
    ap.add_argument(
        "--steps", type=positive_int, default=5000, help="PettingZoo steps per measurement"
    )
    ap.add_argument(
        "--batched-steps", type=positive_int, default=100, help="batched steps per measurement"
    )
    ap.add_argument("--batch", type=positive_int, default=256, help="episodes of the batched env")
    ap.add_argument("--cpu", type=int, default=0, help="CPU every measurement is pinned to")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--code", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        _worker(args)
        return
    ref = None if args.reference == "none" else _checkout(args.reference)
    rows: dict[str, list[dict[str, Any]]] = {"current": [], "reference": []}
    for _ in range(args.rounds):
        rows["current"].append(_measure(args, None))
        if ref:
            rows["reference"].append(_measure(args, ref))
    head = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    print(
        f"# {platform.machine()}, python {platform.python_version()}, scenario {args.scenario}, "
        f"{args.rounds} rounds, load average at the end {os.getloadavg()[0]:.1f}"
    )
    print(
        "| measure | current (" + head + ") median | reference median | ratio (median of rounds) |"
    )
    print("|---|---:|---:|---:|")
    for key, label in (
        ("pettingzoo_steps_per_s", "PettingZoo steps/s"),
        ("batched_episode_steps_per_s", f"batched episode-steps/s (batch {args.batch})"),
    ):
        cur = [r[key] for r in rows["current"]]
        line = f"| {label} | {statistics.median(cur):,.0f} |"
        if ref:
            old = [r[key] for r in rows["reference"]]
            ratios = [c / o for c, o in zip(cur, old, strict=True)]
            line += f" {statistics.median(old):,.0f} | {statistics.median(ratios):.2f} |"
        else:
            line += " - | - |"
        print(line)


if __name__ == "__main__":
    main()
