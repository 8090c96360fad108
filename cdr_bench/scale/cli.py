"""``cdr-bench sweep`` and ``cdr-bench sweep-plot`` (registered by cdr_bench.cli)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import cdr_bench.scale.ray_eval  # noqa: F401  (registers the evaluator's "ray" backend)
from cdr_bench.checks import ranged
from cdr_bench.evaluate.cli import add_command, add_episodes_arg

MAX_TOTAL_STEPS = 10**10
"""Largest ``--total-steps`` of a sweep (the longest shipped recipe trains 3e6 steps)."""


def register(sub: Any) -> None:
    p = add_command(
        sub, "sweep", _sweep, "train and evaluate a grid of settings x seeds on Ray (sweeps/*.yaml)"
    )
    p.add_argument("sweep", help="sweep YAML file")
    p.add_argument("--out", default=None, help="output folder (runs/sweeps/<name>)")
    p.add_argument("--address", default=None, help="Ray cluster address (default: local Ray)")
    p.add_argument("--resume", action="store_true", help="skip the trials already finished")
    p.add_argument(
        "--num-cpus",
        type=ranged(int, 1, 4096),
        default=None,
        help="CPUs of the local Ray (all of this machine)",
    )
    p.add_argument(
        "--total-steps",
        type=ranged(int, 1, MAX_TOTAL_STEPS),
        default=None,
        help="replace budget.total_steps (reduced run)",
    )
    add_episodes_arg(p, None, "replace evaluation.episodes (reduced run)")
    p.add_argument("--seeds", default=None, help="replace seeds: comma-separated, e.g. 1,2")
    p.add_argument(
        "--scenario",
        action="append",
        default=None,
        metavar="NAME",
        help="replace evaluation.scenarios (repeatable)",
    )
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FLAG=VALUE",
        help="override a trainer flag of `fixed` (repeatable), e.g. --set learning-starts=500",
    )
    p.add_argument(
        "--where",
        action="append",
        default=[],
        metavar="FLAG=VALUE",
        help="run only the trials whose training flag has this value (repeatable; the trial "
        "keys stay those of the whole sweep), e.g. --where ablation=no-dpsc",
    )
    p.add_argument("--dry-run", action="store_true", help="list the trials, run nothing")
    p.add_argument("--quiet", action="store_true", help="no per-trial lines")

    q = add_command(
        sub,
        "sweep-plot",
        _plot,
        "sensitivity panels (success, NMAC rate, latency, reward) of a finished sweep",
    )
    q.add_argument("sweep_dir", help="output folder of `cdr-bench sweep`")
    q.add_argument("--out", default=None, help="PNG path (<sweep_dir>/sensitivity.png)")
    q.add_argument("--json", default=None, help="also write the plotted numbers here")


def _sweep(args: argparse.Namespace) -> int:
    """Run a sweep file: each trial trains with `cdr-bench train` and is scored with `cdr-bench
    evaluate`; one folder per trial (named by a hash of its settings) holding the run, trial.json
    and result.json/.jsonl.xz. Runs on a local Ray started on demand, or on a cluster with
    --address."""
    import yaml

    from cdr_bench.errors import UserError
    from cdr_bench.scale.config import load_sweep

    def pairs(option: str, items: list[str]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for item in items:
            key, sep, value = item.partition("=")
            if not sep or not key:
                raise UserError(f"{option} {item!r}: expected FLAG=VALUE")
            try:
                out[key] = yaml.safe_load(value)
            except yaml.YAMLError:
                raise UserError(f"{option} {item!r}: {value!r} is not a value") from None
        return out

    overrides = pairs("--set", args.set)
    where = pairs("--where", args.where)
    seeds = None
    if args.seeds is not None:
        try:
            seeds = [int(x) for x in args.seeds.split(",")]
        except ValueError:
            raise UserError(f"--seeds {args.seeds!r}: expected integers like 1,2,3") from None
    sweep = load_sweep(
        args.sweep,
        total_steps=args.total_steps,
        episodes=args.episodes,
        overrides=overrides,
        seeds=seeds,
        scenarios=args.scenario,
        where=where,
    )
    if args.num_cpus is not None and args.address is None:
        if args.num_cpus < 1:
            raise UserError(f"--num-cpus {args.num_cpus}: expected a whole number >= 1")
        if args.num_cpus < sweep.num_cpus_per_trial:  # Ray would wait for ever
            raise UserError(
                f"--num-cpus {args.num_cpus}: fewer than the {sweep.num_cpus_per_trial:g} CPUs "
                f"each trial of {args.sweep} asks for (num_cpus_per_trial)"
            )
    out = Path(args.out) if args.out else Path("runs") / "sweeps" / sweep.name
    if out.exists() and not out.is_dir():
        raise UserError(f"--out {out}: exists and is not a folder (a sweep writes a folder)")
    if args.dry_run:
        for t in sweep.trials:
            print(f"{t.key}  {t.factor:14s} {t.label:16s} seed {t.seed}")
        print(f"{len(sweep.trials)} trials -> {out}")
        return 0
    from cdr_bench.scale.sweep import run_sweep

    summary = run_sweep(
        sweep,
        out,
        address=args.address,
        resume=args.resume,
        num_cpus=args.num_cpus,
        progress=not args.quiet,
    )
    print(f"sweep {sweep.name}: {sum(t['done'] for t in summary['trials'])} trials in {out}")
    return 0


def _plot(args: argparse.Namespace) -> int:
    from cdr_bench.evaluate.results import check_output_path
    from cdr_bench.scale.plot import plot_sweep

    out = Path(args.out) if args.out else Path(args.sweep_dir) / "sensitivity.png"
    check_output_path(out)
    if args.json:
        check_output_path(args.json, "--json")
    plot_sweep(Path(args.sweep_dir), out, json_out=Path(args.json) if args.json else None)
    print(f"wrote {out}")
    return 0
