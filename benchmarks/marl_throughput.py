"""Multi-agent environment throughput on one core, against the single-agent case in the same
process and, optionally, a reference commit measured in the same run.

Per measurement process (pinned to one CPU, ``OMP_NUM_THREADS=1``), resets included:

* *PettingZoo steps/s*: ``cdr_bench.parallel_env(scenario)`` stepped with the README's own loop
  (``{a: env.action_space(a).sample(obs[a]["action_mask"]) for a in env.agents}``: observation,
  reward, termination and info dicts built every step), ``--steps`` steps, for the
  single-agent ``high`` and for ``--marl`` (default ``marl/high-all``: 48 airway aircraft and
  the ownship, all controlled).
* *batched*: ``VectorEnv(scenario, num_envs=--batch, autoreset=True)`` stepped with
  ``random_feasible_actions``. Three rates: episode-steps/s (one episode advanced one step),
  aircraft-steps/s (controlled aircraft flying at the start of the step, summed over
  episodes: the ones the step moves, judges and rewards) and slot-steps/s (episodes x every
  controlled slot, ``M``, flying or not: the issue's "N episodes x controlled aircraft").

Every rate is measured in wall time and in CPU time (``time.process_time``: on a shared
machine the process is descheduled, which wall time counts and CPU time does not). The ratio
``marl / single`` is taken within one process, so it does not depend on the machine's speed at
that minute. With ``--reference <commit>`` every round also runs that commit (checked out with
``git worktree`` into ``.bench/<commit>``) in a fresh process right after the current checkout.

Run: ``python benchmarks/marl_throughput.py [--reference 74187f2] [--rounds 3]``
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

SINGLE = "high"


def _worker(args: argparse.Namespace) -> None:
    """Measure in this process (``--worker``): prints one JSON line."""
    if args.cpu >= 0 and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {args.cpu})
    if args.code:  # the reference checkout: bypass the editable install of the current one
        sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in repr(f).lower()]
        sys.path.insert(0, args.code)
    import numpy as np

    import cdr_bench
    from cdr_bench.vector_env import VectorEnv, random_feasible_actions

    def pettingzoo(scenario: str, steps: int) -> dict[str, float]:
        env = cdr_bench.parallel_env(scenario)
        obs, _ = env.reset(seed=0)
        t0, c0 = time.perf_counter(), time.process_time()
        for _ in range(steps):
            actions = {a: env.action_space(a).sample(obs[a]["action_mask"]) for a in env.agents}
            obs, *_ = env.step(actions)
            if not env.agents:
                obs, _ = env.reset()
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        return {"steps_wall": steps / wall, "steps_cpu": steps / cpu}

    def batched(scenario: str, steps: int, n: int) -> dict[str, float]:
        rng = np.random.default_rng(0)
        env = VectorEnv(scenario, num_envs=n, autoreset=True, seed=0)
        _, masks = env.reset()
        flying = 0
        active = env.sim.active[:, env.sim.B :]  # a live view (not timed: one sum per step)
        wall = cpu = 0.0
        for _ in range(steps):
            flying += int(active.sum())
            t0, c0 = time.perf_counter(), time.process_time()
            masks = env.step(random_feasible_actions(masks, rng)).action_mask
            wall += time.perf_counter() - t0
            cpu += time.process_time() - c0
        out: dict[str, float] = {}
        for clock, t in (("wall", wall), ("cpu", cpu)):
            out[f"episode_steps_{clock}"] = steps * n / t
            out[f"aircraft_steps_{clock}"] = flying / t
            out[f"slot_steps_{clock}"] = steps * n * env.n_agents / t
        out["mean_flying"] = flying / (steps * n)
        out["agents"] = env.n_agents
        return out

    # Warm-up: compiled code loaded (auto-reset included), caches filled.
    for scenario in (SINGLE, args.marl):
        pettingzoo(scenario, 300)
        batched(scenario, 60, args.batch)
    out = {
        "pz_single": pettingzoo(SINGLE, args.steps),
        "pz_marl": pettingzoo(args.marl, args.marl_steps),
        "vec_single": batched(SINGLE, args.batched_steps, args.batch),
        "vec_marl": batched(args.marl, args.marl_batched_steps, args.batch),
        "code": os.path.dirname(cdr_bench.__file__),
    }
    print(json.dumps(out))


def _measure(args: argparse.Namespace, code: str | None) -> dict[str, Any]:
    cmd = [sys.executable, __file__, "--worker", "--marl", args.marl]
    for flag in ("steps", "marl_steps", "batched_steps", "marl_batched_steps", "batch", "cpu"):
        cmd += [f"--{flag.replace('_', '-')}", str(getattr(args, flag))]
    if code:
        cmd += ["--code", code]
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONHASHSEED="0")
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    if out.returncode != 0:
        raise SystemExit(f"worker failed:\n{out.stderr[-3000:]}")
    result: dict[str, Any] = json.loads(out.stdout.strip().splitlines()[-1])
    return result


ROWS = (
    ("pz_single", "steps", "PettingZoo steps/s, {single}"),
    ("pz_marl", "steps", "PettingZoo steps/s, {marl}"),
    ("vec_single", "episode_steps", "batched episode-steps/s, {single}"),
    ("vec_marl", "episode_steps", "batched episode-steps/s, {marl}"),
    ("vec_marl", "aircraft_steps", "batched aircraft-steps/s (flying), {marl}"),
    ("vec_marl", "slot_steps", "batched slot-steps/s (episodes x M), {marl}"),
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reference", default="none", help="commit to compare with, or 'none'")
    ap.add_argument("--rounds", type=positive_int, default=3)
    ap.add_argument("--marl", default="marl/high-all", help="the multi-agent scenario")
    ap.add_argument("--steps", type=positive_int, default=5000, help="PettingZoo steps, high")
    ap.add_argument(
        "--marl-steps", type=positive_int, default=1000, help="PettingZoo steps, --marl"
    )
    ap.add_argument("--batched-steps", type=positive_int, default=200, help="batched steps, high")
    ap.add_argument(
        "--marl-batched-steps", type=positive_int, default=150, help="batched steps, --marl"
    )
    ap.add_argument("--batch", type=positive_int, default=256, help="episodes of the batched env")
    ap.add_argument("--cpu", type=int, default=0, help="CPU to pin to (-1: not pinned)")
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
    cur0 = rows["current"][0]
    print(
        f"# {platform.machine()}, python {platform.python_version()}, batch {args.batch}, "
        f"{args.rounds} rounds, {args.marl}: {cur0['vec_marl']['agents']:.0f} controlled slots, "
        f"{cur0['vec_marl']['mean_flying']:.1f} flying on average; load average at the end "
        f"{os.getloadavg()[0]:.1f}"
    )
    for clock in ("wall", "cpu"):
        print(f"\n{clock} time, medians over rounds:\n")
        head_ref = f" | reference ({args.reference}) | current / reference" if ref else ""
        print(f"| measure | current ({head}){head_ref} |")
        print("|---|---:|" + ("---:|---:|" if ref else ""))
        for part, key, label in ROWS:
            k = f"{key}_{clock}"
            cur = [r[part][k] for r in rows["current"]]
            name = label.format(single=SINGLE, marl=args.marl)
            line = f"| {name} | {statistics.median(cur):,.0f} |"
            if ref:
                old = [r[part][k] for r in rows["reference"]]
                ratios = [c / o for c, o in zip(cur, old, strict=True)]
                line += f" {statistics.median(old):,.0f} | {statistics.median(ratios):.2f} |"
            print(line)
        # within-process ratios: the multi-agent case against the single-agent one
        for name, (a, ka), (b, kb) in (
            ("PettingZoo steps/s, marl / single", ("pz_marl", "steps"), ("pz_single", "steps")),
            (
                "batched aircraft-steps/s (flying) marl / episode-steps/s single",
                ("vec_marl", "aircraft_steps"),
                ("vec_single", "episode_steps"),
            ),
        ):
            line = f"| {name} (same process) |"
            for which in ("current", "reference") if ref else ("current",):
                rs = [r[a][f"{ka}_{clock}"] / r[b][f"{kb}_{clock}"] for r in rows[which]]
                line += f" {statistics.median(rs):.3f} |"
            print(line + (" |" if ref else ""))


if __name__ == "__main__":
    main()
