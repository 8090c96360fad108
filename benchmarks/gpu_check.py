"""Every ``cdr-bench train`` algorithm on CUDA and on the CPU in one run: speed and losses.

    python benchmarks/gpu_check.py                    # ~2,000 updates each; < 5 min on a GPU host
    python benchmarks/gpu_check.py --updates 500 --algorithms rainbow safe-dqn-x

Each algorithm trains from the same seed with ``--device cpu`` (one torch thread, the trainers'
default) and then ``--device cuda``, for about ``--updates`` gradient updates at its default
hyper-parameters (off-policy: 1,000 transitions of pure collection, then one update per 4
transitions; PPO / MaskablePPO: 10 epochs of 8 minibatches per rollout of 16 x 128 transitions;
TD3: one update per 4 transitions). It reports updates/s and transitions/s of the whole loop
(collection included) between its first and its last log line (eight per run: set-up, CUDA's
first kernels and the first interval are left out) and the mean of each ``losses/*`` key
over the last half of the run's log lines.

The CPU and the CUDA run use the same seed but not the same random streams (CUDA draws from
its own generators, and the tensor operations of the GPU path round differently from the CPU's
compiled kernels), so their data and losses differ after the first actions: they are
*comparable*, not equal. The check: for every loss key, ``|cuda - cpu| <= 0.5 max(|cpu|,
|cuda|)`` (within a factor of 2) or ``|cuda - cpu| <= 0.05`` (keys near zero, e.g. a policy
gradient loss). A failed key is reported and the script exits 1. Only the losses are checked
(keys named ``loss*`` or ``*loss``; statistics such as ``q_mean`` are printed). ``--calibrate``
adds a CPU run with seed 2 and applies the same check to the two CPU seeds: what the tolerance
has to allow.

Without CUDA the CPU part runs, the script says that CUDA is not available and exits 0.
"""

from __future__ import annotations

import argparse
import importlib
import json
import math
import os
import platform
import sys
import tempfile
import time
from typing import Any

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _checkout import positive_int  # noqa: E402

OFF_POLICY = ("diffusion-ac", "rainbow", "safe-dqn-x")
SB3 = ("ppo", "maskable-ppo", "td3")
LEARNING_STARTS = 1_000
REL_TOL, ABS_TOL = 0.5, 0.05


def plan(name: str, updates: int) -> tuple[dict[str, Any], int]:
    """The flags of a run of about ``updates`` updates and its number of updates."""
    from cdr_bench.rl.train_sb3 import Args as SB3Args

    if name in ("ppo", "maskable-ppo"):
        a = SB3Args()
        rollout = a.n_steps * a.n_envs
        per_rollout = a.n_epochs * math.ceil(rollout / a.ppo_batch_size)
        rollouts = max(1, round(updates / per_rollout))
        return {"total_steps": rollouts * rollout}, rollouts * per_rollout
    update_every = 4
    total = LEARNING_STARTS + updates * update_every
    return {"total_steps": total, "learning_starts": LEARNING_STARTS}, updates


def run_one(name: str, device: str, updates: int, run_dir: str, seed: int = 1) -> dict[str, Any]:
    """Train ``name`` on ``device``; its speed and the losses of the last half of the log."""
    from cdr_bench.rl.cli import TRAINERS

    module = importlib.import_module(TRAINERS[name])
    flags, n_updates = plan(name, updates)
    common = dict(
        run_dir=run_dir, device=device, seed=seed, progress=False, eval_episodes=0, curve_every=0,
        checkpoint_every=10**9, log_every=max(1, flags["total_steps"] // 8), **flags,
    )  # fmt: skip
    t0 = time.perf_counter()
    if name in SB3:
        summary = module.train(name, module.Args(**common))
    else:
        from cdr_bench.rl.offpolicy import train

        summary = train(module.ALGORITHM, module.Args(**common))
        n_updates = summary["updates"]
    wall = time.perf_counter() - t0
    rows = [json.loads(line) for line in open(os.path.join(run_dir, "log.jsonl"))]
    rows = [r for r in rows if "charts/success_rolling" in r]
    # speed between the first and the last log line (set-up and the first interval left out)
    timed = [r for r in rows if r["step"] >= LEARNING_STARTS]  # updating (TD3 and off-policy)
    first, last = (timed[0], timed[-1]) if len(timed) > 1 else (rows[0], rows[-1])
    span = last["wall_s"] - first["wall_s"]
    steps = last["step"] - first["step"]
    done = (last["updates"] - first["updates"]) if "updates" in last else None
    if done is None:  # SB3: updates in proportion to transitions
        done = steps * n_updates / max(1, summary["step"])
    rows = [r for r in rows if any(k.startswith("losses/") for k in r)]
    rows = rows[len(rows) // 2 :]
    keys = sorted({k for r in rows for k in r if k.startswith("losses/")})
    losses = {}
    for k in keys:
        vals = [r[k] for r in rows if isinstance(r.get(k), (int, float)) and math.isfinite(r[k])]
        if vals:
            losses[k[len("losses/") :]] = sum(vals) / len(vals)
    return {
        "wall_s": wall,
        "updates": n_updates,
        "transitions": summary["step"],
        "updates_per_s": done / span if span > 0 else math.nan,
        "transitions_per_s": steps / span if span > 0 else math.nan,
        "losses": losses,
    }


def is_loss(key: str) -> bool:
    """The keys compared: the losses (``loss_q``, ``value_loss``, ...), not the statistics
    logged beside them (``q_mean``, ``target_max``: printed, not checked)."""
    return key.startswith("loss") or key.endswith("loss")


def comparable(a: float, b: float) -> bool:
    d = abs(a - b)
    return d <= REL_TOL * max(abs(a), abs(b)) or d <= ABS_TOL


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument(
        "--updates", type=positive_int, default=2_000, help="updates per run (default 2000)"
    )
    p.add_argument(
        "--algorithms", nargs="+", default=[*OFF_POLICY, *SB3], choices=[*OFF_POLICY, *SB3]
    )
    p.add_argument(
        "--calibrate",
        action="store_true",
        help="also train each algorithm on the CPU with seed 2 and apply the loss check to the\n"
        "two CPU seeds (what the tolerance must allow: another random stream)",
    )
    p.add_argument("--json", help="also write the results to this file")
    ns = p.parse_args(argv)

    import torch

    cuda = torch.cuda.is_available()
    print(
        f"{platform.machine()}, python {platform.python_version()}, torch {torch.__version__}, "
        f"CUDA {'available: ' + torch.cuda.get_device_name(0) if cuda else 'not available'}, "
        f"{ns.updates} updates per run"
    )
    if cuda:
        torch.zeros(1, device="cuda")  # the CUDA context, before any timing
    devices = ["cpu", "cuda"] if cuda else ["cpu"]
    if ns.calibrate:
        devices.append("cpu-seed-2")
    results: dict[str, dict[str, Any]] = {}
    failed = []
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for name in ns.algorithms:
            results[name] = {}
            for dev in devices:
                seed = 2 if dev == "cpu-seed-2" else 1
                where = dev.split("-")[0]
                r = run_one(name, where, ns.updates, os.path.join(tmp, f"{name}-{dev}"), seed)
                results[name][dev] = r
                print(
                    f"{name:>13} {dev:>4}: {r['updates']:>6} updates in {r['wall_s']:6.1f} s, "
                    f"{r['updates_per_s']:7.1f} updates/s, {r['transitions_per_s']:8.0f} "
                    f"transitions/s; losses "
                    + ", ".join(f"{k}={v:.4g}" for k, v in r["losses"].items()),
                    flush=True,
                )
            c = results[name]["cpu"]
            for other in devices[1:]:
                g = results[name][other]
                keys = sorted(k for k in {*c["losses"], *g["losses"]} if is_loss(k))
                bad = [
                    k
                    for k in keys
                    if k not in c["losses"]
                    or k not in g["losses"]
                    or not comparable(c["losses"][k], g["losses"][k])
                ]
                speed = g["updates_per_s"] / c["updates_per_s"]
                verdict = "comparable" if keys and not bad else f"NOT comparable: {bad or keys}"
                print(f"{name:>13}: {other} / cpu updates/s {speed:.2f}x; losses {verdict}")
                if bad or not keys:
                    failed.append(f"{name} ({other})")
    print(f"total {time.perf_counter() - t_start:.0f} s")
    if ns.json:
        with open(ns.json, "w") as f:
            json.dump(results, f, indent=1)
    if not cuda and not failed:
        print("CUDA is not available here: the CPU part ran, the CUDA part and the comparison")
        print("were skipped (run this script on a machine with a CUDA device and a CUDA torch).")
        return 0
    if failed:
        print(f"losses not comparable (tolerance: within a factor of 2 or {ABS_TOL}): {failed}")
        return 1
    print(f"all losses comparable (within a factor of 2 or {ABS_TOL} absolute)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
