"""PettingZoo steps/s at low / medium / high density with random masked actions, and the raw
simulator's aircraft-steps/s (single core).

Run: python benchmarks/env_throughput.py [--steps 20000] [--repeats 5] [--batch 256]

PettingZoo steps/s is measured ``--repeats`` times per density (``--steps`` steps each, one env
stepped on, auto-reset); the median and the best run are printed. On a shared virtual machine
single runs scatter by tens of percent, so report the median and say so.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from typing import Any

import numpy as np

import cdr_bench
from cdr_bench.scenarios import load_scenario
from cdr_bench.sim import Simulator, observe


def pettingzoo_steps_per_s(
    scenario: str, steps: int, repeats: int, seed: int = 0
) -> tuple[float, float]:
    """(median, best) PettingZoo steps/s over ``repeats`` runs of ``steps`` steps."""
    env = cdr_bench.parallel_env(scenario)
    rng = np.random.default_rng(seed)
    obs, _ = env.reset(seed=seed)
    rates = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        obs = random_steps(env, obs, rng, steps)
        rates.append(steps / (time.perf_counter() - t0))
    return float(np.median(rates)), max(rates)


def random_steps(env: Any, obs: dict[str, Any], rng: np.random.Generator, steps: int) -> Any:
    """Step ``env`` with random feasible actions, resetting when no agent is left; returns the
    last observations."""
    for _ in range(steps):
        actions = {}
        for a in env.agents:
            feasible = np.flatnonzero(obs[a]["action_mask"])
            actions[a] = int(feasible[rng.integers(len(feasible))])
        obs, *_ = env.step(actions)
        if not env.agents:
            obs, _ = env.reset()
    return obs


def sim_throughput(scenario: str, steps: int, batch: int, seed: int = 0) -> tuple[float, float]:
    """Batched simulator with observations and masks, random masked actions, auto-reset.

    Returns (episode-steps/s, aircraft-steps/s): one episode-step advances one episode by one
    step; aircraft-steps count every aircraft in the sky (intruders + controlled) per step.
    """
    cfg = load_scenario(scenario)
    sim = Simulator(cfg, n_episodes=batch)
    sim.reset(np.arange(batch) + seed)
    rng = np.random.default_rng(seed)
    aircraft = 0
    t0 = time.perf_counter()
    for _ in range(steps):
        masks = sim.action_masks()
        u = rng.random(masks.shape) * masks
        sim.step(u.argmax(-1))
        observe(sim)
        aircraft += int(sim.bg_active.sum() + sim.ac_active.sum())
        done = np.flatnonzero(~sim.ac_active.any(axis=1))
        if done.size:
            sim.reset(rng.integers(0, 2**62, done.size), episodes=done)
    elapsed = time.perf_counter() - t0
    return steps * batch / elapsed, aircraft / elapsed


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--steps", type=int, default=20000, help="PettingZoo steps per run")
    ap.add_argument("--repeats", type=int, default=5, help="PettingZoo runs per density")
    ap.add_argument("--batch", type=int, default=256, help="episodes in the batched simulator")
    ap.add_argument("--sim-steps", type=int, default=200, help="batched simulator steps")
    ap.add_argument(
        "--scenarios", nargs="+", default=["low", "medium", "high"], help="scenarios to measure"
    )
    ap.add_argument("--no-sim", action="store_true", help="skip the batched simulator columns")
    args = ap.parse_args()
    print(
        f"# {platform.processor() or platform.machine()}, python {platform.python_version()}, "
        f"numpy {np.__version__}, OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')}, "
        f"cdr_bench from {os.path.dirname(cdr_bench.__file__)}"
    )
    print(
        f"| scenario | PettingZoo steps/s, median of {args.repeats} | best run "
        f"| batched sim episode-steps/s (batch {args.batch}) | batched sim aircraft-steps/s |"
    )
    print("|---|---:|---:|---:|---:|")
    for sc in args.scenarios:
        median, best = pettingzoo_steps_per_s(sc, args.steps, args.repeats)
        ep, ac = (np.nan, np.nan) if args.no_sim else sim_throughput(sc, args.sim_steps, args.batch)
        print(f"| {sc} | {median:,.0f} | {best:,.0f} | {ep:,.0f} | {ac:,.0f} |")


if __name__ == "__main__":
    main()
