"""Training throughput of the off-policy trainers against a reference commit measured in the
same run: end-to-end transitions/s of the real training loop, and what the time goes to.

For each algorithm (``diffusion-ac``, ``rainbow``) the worker runs
:func:`cdr_bench.rl.offpolicy.train` itself -- acting, environment steps, replay inserts,
sampling, updates at the default ratio (one per ``update_every`` = 4 transitions), logging --
at the hyper-parameters of the shipped reference run (``agents/<agent>/train_args.json``: the
defaults, plus the DPSC curriculum and temperatures for Diffusion-AC and ``medium`` without
curriculum for Rainbow-DQN), with ``--transitions`` measured after the ``learning_starts`` =
5,000 transitions of pure collection and ``--warmup`` more. Checkpoints are not written in the
measured window (``checkpoint_every`` beyond the budget; the real run writes one every 50,000 or
100,000 transitions) and there is no final evaluation.

Every round runs each algorithm on the current checkout and on ``--reference`` (default
``70fce2e``, the last commit before the issue-16 speed-up of the trainers) one after the other,
each in a fresh process with ``OMP_NUM_THREADS=1`` and ``--threads`` torch threads (default 1,
the trainers' default), unpinned. The table gives medians over rounds of transitions/s in wall
time and in CPU time of the process (``time.process_time``: less sensitive to other jobs on the
machine, but still slowed by sharing a core's caches) and the median of the per-round ratios
current/reference.

The breakdown: CPU time per transition by part of the loop, from timers wrapped around the
methods the loop calls (the same names in both checkouts):

* ``env``: ``CurriculumEnv.step`` (the numba simulator, rewards, restarts, curriculum);
* ``act``: the learner's ``act`` (exploring action selection: Diffusion-AC's T = 10 reverse
  steps, Rainbow's noise draw and forward pass);
* ``replay add`` / ``replay sample`` / ``priorities``: ``Replay.add`` (n-step returns for
  Rainbow), ``Replay.sample``, ``Replay.update_priorities``;
* ``update: forward``: the learner's ``update`` minus the parts below (forward passes, losses,
  targets, noise draws, statistics);
* ``update: backward``: ``torch.autograd.backward``;
* ``update: optimizer``: ``Optimizer.step`` and ``zero_grad`` (and gradient clipping);
* ``update: target``: the Polyak averaging of the target network;
* ``loop``: the rest (the loop's own Python: batches to tensors, counters, logging).

Run: ``python benchmarks/train_throughput.py [--reference 70fce2e] [--rounds 3]
[--algorithms diffusion-ac rainbow] [--transitions 4000] [--threads 1]``; ``--reference none``
measures the current checkout only. The reference is checked out with ``git worktree`` into
``.bench/<commit>`` (ignored).

``--n-envs 1 8 16 32`` instead compares numbers of parallel episodes (``--n-envs`` of the
trainers: the loop steps N episodes together and acts for all their flying aircraft in one
call; one update per ``update_every`` transitions whatever N) on the current checkout: each
round one worker process trains each algorithm at each N in turn (the same process, so the same
machine state, numba and torch warmed up once), each run measured as above; the table gives
medians over rounds of transitions/s and updates/s in wall time, their ratio to the first N, and
the CPU time per transition of acting and of the updates.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).parent))
from _checkout import checkout as _checkout  # noqa: E402
from _checkout import positive_int  # noqa: E402

ALGORITHMS: dict[str, tuple[str, dict[str, Any]]] = {
    # module, flags of the shipped reference run that are not the defaults
    "diffusion-ac": (
        "cdr_bench.rl.train_diffusion_ac",
        {"curriculum": True, "tau_start": 0.2, "tau_end": 0.05},
    ),
    "rainbow": ("cdr_bench.rl.train_rainbow", {"curriculum": False, "scenario": "medium"}),
}
PARTS = (
    "env",
    "act",
    "replay add",
    "replay sample",
    "priorities",
    "update: forward",
    "update: backward",
    "update: optimizer",
    "update: target",
    "loop",
)


# --------------------------------------------------------------------------------------------
# The worker (a fresh process per measurement)


class _Timers:
    """CPU time (``time.process_time``) inside wrapped callables, by part; nested wrapped calls
    are charged to the innermost part only."""

    def __init__(self) -> None:
        self.cpu: dict[str, float] = defaultdict(float)
        self.calls: dict[str, int] = defaultdict(int)
        self._stack: list[list[float]] = []  # per open call: [start, time of nested calls]
        self.on = False

    def wrap(self, owner: Any, name: str, part: str) -> None:
        fn = getattr(owner, name)
        timers = self

        def timed(*a: Any, **k: Any) -> Any:
            if not timers.on:
                return fn(*a, **k)
            frame = [time.process_time(), 0.0]
            timers._stack.append(frame)
            try:
                return fn(*a, **k)
            finally:
                timers._stack.pop()
                spent = time.process_time() - frame[0]
                timers.cpu[part] += spent - frame[1]
                timers.calls[part] += 1
                if timers._stack:
                    timers._stack[-1][1] += spent

        setattr(owner, name, timed)


def _worker(args: argparse.Namespace) -> None:
    """Measure one algorithm in this process (``--worker``): prints one JSON line per
    ``--n-envs`` value (one line at the shipped run's number of episodes without it)."""
    if args.code:  # the reference checkout: bypass the editable install of the current one
        sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in repr(f).lower()]
        sys.path.insert(0, args.code)
    import importlib

    import torch

    from cdr_bench.rl import curriculum, offpolicy, replay
    from cdr_bench.rl.common import RunLog

    module_name, flags = ALGORITHMS[args.algorithm]
    trainer = importlib.import_module(module_name)
    learner_module = importlib.import_module(
        {"diffusion-ac": "cdr_bench.rl.diffusion_ac", "rainbow": "cdr_bench.rl.rainbow"}[
            args.algorithm
        ]
    )
    learner_cls = {"diffusion-ac": "DiffusionAC", "rainbow": "Rainbow"}[args.algorithm]
    learner_cls = getattr(learner_module, learner_cls)

    timers = _Timers()
    timers.wrap(curriculum.CurriculumEnv, "step", "env")
    timers.wrap(learner_cls, "act", "act")
    timers.wrap(replay.Replay, "add", "replay add")
    timers.wrap(replay.Replay, "sample", "replay sample")
    timers.wrap(replay.Replay, "update_priorities", "priorities")
    timers.wrap(learner_cls, "update", "update: forward")
    timers.wrap(torch.autograd, "backward", "update: backward")
    timers.wrap(torch.optim.Optimizer, "zero_grad", "update: optimizer")
    timers.wrap(torch.optim.Adam, "step", "update: optimizer")
    networks = importlib.import_module("cdr_bench.rl.networks")
    if hasattr(networks, "FusedAdam"):  # its own step (the fused kernel called directly)
        timers.wrap(networks.FusedAdam, "step", "update: optimizer")
    if hasattr(networks, "FlatParameters"):  # gradients gathered, zeroed and clipped
        for name in ("zero_grad", "collect_grad", "clip_grad_norm"):
            timers.wrap(networks.FlatParameters, name, "update: optimizer")
    timers.wrap(torch.nn.utils, "clip_grad_norm_", "update: optimizer")
    timers.wrap(learner_module, "polyak_update", "update: target")

    learning_starts = trainer.Args().learning_starts
    start = learning_starts + args.warmup
    total = start + args.transitions
    marks: list[tuple[float, float, int]] = []
    advance = RunLog.advance

    def advanced(self: Any, step: int, n: int, env: Any) -> None:
        # called once per iteration of the loop, after its collection and updates
        if step >= start and (timers.on or not marks):
            marks.append((time.perf_counter(), time.process_time(), step))
            timers.on = step < total
        advance(self, step, n, env)

    RunLog.advance = advanced  # type: ignore[method-assign]
    for n_envs in args.n_envs or [None]:
        marks.clear()
        timers.cpu.clear()
        timers.calls.clear()
        with tempfile.TemporaryDirectory() as tmp:
            a = trainer.Args(
                run_dir=tmp,
                seed=1,
                total_steps=total,
                threads=args.threads,
                progress=False,
                eval_episodes=0,
                checkpoint_every=10 * total,
                **flags,
                **({"n_envs": n_envs} if n_envs else {}),
            )
            offpolicy.train(trainer.ALGORITHM, a)

        (w0, c0, s0), (w1, c1, s1) = marks[0], marks[-1]
        wall, cpu, n = w1 - w0, c1 - c0, s1 - s0
        parts = {p: timers.cpu.get(p, 0.0) for p in PARTS if p != "loop"}
        parts["loop"] = cpu - sum(parts.values())
        updates = timers.calls.get("update: forward", 0)
        out = {
            "algorithm": args.algorithm,
            "n_envs": a.n_envs,
            "transitions": n,
            "updates": updates,
            "wall_per_s": n / wall,
            "cpu_per_s": n / cpu,
            "updates_wall_per_s": updates / wall,
            "us_per_transition": {p: 1e6 * v / n for p, v in parts.items()},
            "calls": dict(timers.calls),
            "code": os.path.dirname(importlib.import_module("cdr_bench").__file__ or ""),
            "torch": torch.__version__,
            "threads": torch.get_num_threads(),
        }
        print(json.dumps(out), flush=True)


# --------------------------------------------------------------------------------------------
# The driver


def _measure(args: argparse.Namespace, algorithm: str, code: str | None) -> Any:
    """One worker's measurement (a list of them, one per N, with ``--n-envs``)."""
    cmd = [sys.executable, __file__, "--worker", "--algorithm", algorithm]
    cmd += ["--transitions", str(args.transitions), "--warmup", str(args.warmup)]
    cmd += ["--threads", str(args.threads)]
    if args.n_envs:
        cmd += ["--n-envs", *map(str, args.n_envs)]
    if code:
        cmd += ["--code", code]
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", PYTHONHASHSEED="0")
    env.pop("PYTHONPATH", None)
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    if out.returncode != 0:
        raise SystemExit(f"worker failed ({algorithm}, {code or 'current'}):\n{out.stderr[-3000:]}")
    lines = [x for x in out.stdout.strip().splitlines() if x.startswith("{")]
    if args.n_envs:
        return [json.loads(x) for x in lines]
    result: dict[str, Any] = json.loads(lines[-1])
    if code and not result["code"].startswith(code):
        raise SystemExit(f"the reference run imported {result['code']}, not {code}")
    return result


def _n_envs_sweep(args: argparse.Namespace) -> None:
    """``--n-envs``: each algorithm at each N, the current checkout; a table of medians."""
    runs: dict[str, list[list[dict[str, Any]]]] = {a: [] for a in args.algorithms}
    t0 = time.time()
    for i in range(args.rounds):
        for algorithm in args.algorithms:
            runs[algorithm].append(_measure(args, algorithm, None))
            print(f"round {i + 1}/{args.rounds} {algorithm} done", file=sys.stderr, flush=True)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    torch_version = runs[args.algorithms[0]][0][0]["torch"]
    print(
        f"`{platform.machine()}, python {platform.python_version()}, torch {torch_version}, "
        f"{args.threads} torch thread(s), OMP_NUM_THREADS=1, {args.rounds} round(s) of "
        f"{args.transitions} transitions after {args.warmup} of warm-up per N, "
        f"{time.time() - t0:.0f} s, load average at the end {load:.1f}, {_git_head()}`"
    )
    print()
    print(
        "| algorithm | N (--n-envs) | transitions/s | updates/s | transitions/s vs "
        f"N={args.n_envs[0]} | act µs/transition | update µs/transition |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|")
    update_parts = [p for p in PARTS if p.startswith("update") or p == "replay sample"]
    for algorithm, rounds in runs.items():
        for j, n in enumerate(args.n_envs):
            rows = [r[j] for r in rounds]
            tps = _median(rows, lambda x: x["wall_per_s"])
            ups = _median(rows, lambda x: x["updates_wall_per_s"])
            ratio = statistics.median(r[j]["wall_per_s"] / r[0]["wall_per_s"] for r in rounds)
            act = _median(rows, lambda x: x["us_per_transition"]["act"])
            upd = _median(rows, lambda x: sum(x["us_per_transition"][p] for p in update_parts))
            print(
                f"| {algorithm} | {n} | {tps:,.0f} | {ups:,.0f} | {ratio:.2f}x | {act:,.0f} "
                f"| {upd:,.0f} |"
            )
    if args.json:
        Path(args.json).write_text(json.dumps(runs, indent=1))


def _median(rows: list[dict[str, Any]], key: Callable[[dict[str, Any]], float]) -> float:
    return statistics.median(key(r) for r in rows)


def _git_head() -> str:
    r = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    )
    return r.stdout.strip() or "?"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--reference", default="70fce2e")
    p.add_argument("--algorithms", nargs="+", default=list(ALGORITHMS), choices=list(ALGORITHMS))
    p.add_argument("--rounds", type=positive_int, default=3)
    p.add_argument(
        "--transitions", type=positive_int, default=4000, help="measured transitions per run"
    )
    p.add_argument(
        "--warmup", type=int, default=1000, help="transitions after learning_starts not measured"
    )
    p.add_argument(
        "--threads", type=positive_int, default=1, help="torch threads (the trainers' flag)"
    )
    p.add_argument(
        "--n-envs",
        type=positive_int,
        nargs="+",
        help="compare these numbers of parallel episodes (current checkout only)",
    )
    p.add_argument("--json", help="also write every measurement here")
    p.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--algorithm", help=argparse.SUPPRESS)
    p.add_argument("--code", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.worker:
        _worker(args)
        return
    if args.n_envs:
        _n_envs_sweep(args)
        return

    ref = None if args.reference == "none" else _checkout(args.reference)
    runs: dict[str, dict[str, list[dict[str, Any]]]] = {
        a: {"cur": [], "ref": []} for a in args.algorithms
    }
    t0 = time.time()
    for i in range(args.rounds):
        for algorithm in args.algorithms:
            runs[algorithm]["cur"].append(_measure(args, algorithm, None))
            if ref:
                runs[algorithm]["ref"].append(_measure(args, algorithm, ref))
            print(f"round {i + 1}/{args.rounds} {algorithm} done", file=sys.stderr, flush=True)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    torch_version = runs[args.algorithms[0]]["cur"][0]["torch"]
    print(
        f"`{platform.machine()}, python {platform.python_version()}, torch {torch_version}, "
        f"{args.threads} torch thread(s), OMP_NUM_THREADS=1, {args.rounds} round(s) of "
        f"{args.transitions} transitions after {args.warmup} of warm-up, "
        f"{time.time() - t0:.0f} s, load average at the end {load:.1f}`"
    )
    print()
    head = _git_head()
    print(
        f"| algorithm | time | current ({head}) transitions/s | reference ({args.reference}) "
        "transitions/s | current / reference |"
    )
    print("|---|---|---:|---:|---:|")
    for algorithm, r in runs.items():
        for key, label in (("wall_per_s", "wall"), ("cpu_per_s", "CPU")):
            cur = _median(r["cur"], lambda x: x[key])  # noqa: B023
            if r["ref"]:
                refv = _median(r["ref"], lambda x: x[key])  # noqa: B023
                ratio = statistics.median(
                    c[key] / f[key] for c, f in zip(r["cur"], r["ref"], strict=True)
                )
                print(f"| {algorithm} | {label} | {cur:,.0f} | {refv:,.0f} | **{ratio:.2f}x** |")
            else:
                print(f"| {algorithm} | {label} | {cur:,.0f} | - | - |")
    print()
    print("CPU time per transition (µs, medians over rounds; share of the total):")
    print()
    cols = [(a, w) for a in args.algorithms for w in (("cur", "ref") if ref else ("cur",))]
    print(
        "| part | "
        + " | ".join(f"{a} {'current' if w == 'cur' else 'reference'}" for a, w in cols)
        + " |"
    )
    print("|---|" + "---:|" * len(cols))
    for part in (*PARTS, "total"):
        cells = []
        for a, w in cols:
            rows = runs[a][w]
            total = _median(rows, lambda x: sum(x["us_per_transition"].values()))
            if part == "total":
                cells.append(f"**{total:,.0f}**")
                continue
            v = _median(rows, lambda x: x["us_per_transition"][part])  # noqa: B023
            cells.append(f"{v:,.0f} ({100 * v / total:.0f} %)")
        print(f"| {part} | " + " | ".join(cells) + " |")
    if args.json:
        Path(args.json).write_text(json.dumps(runs, indent=1))


if __name__ == "__main__":
    main()
