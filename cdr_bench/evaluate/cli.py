"""``cdr-bench evaluate``, ``cdr-bench compare`` and ``cdr-bench report``."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from cdr_bench.checks import MAX_BATCH_SIZE, MAX_EPISODES, MAX_SEED, MAX_STEPS, MAX_WORKERS, ranged
from cdr_bench.errors import UserError
from cdr_bench.evaluate.seeds import SPLITS, VALIDATION


def register(sub: Any) -> None:
    p = add_command(
        sub,
        "evaluate",
        _evaluate,
        "score an agent on identical episodes (default: the paper suite)",
    )
    p.add_argument(
        "agent",
        help="agent .py file, a folder holding agent.py, or a built-in reference agent: "
        "direct, mvp, random (used when no such file or folder is here)",
    )
    _add_scenarios_arg(p, "registry name or YAML path (repeatable); replaces the default suite")
    p.add_argument("--suite", default=None, help="named suite: paper (the default)")
    add_episodes_arg(p, None, f"episodes per scenario (1000; at most {MAX_EPISODES})")
    p.add_argument(
        "--split",
        choices=tuple(SPLITS),
        default=None,
        help="the episodes: validation (base seed 1, the default: tune and compare here), "
        "validation-0 (base seed 0, the test set before 2026-11-27) or test (the "
        "leaderboard's: score a finished agent once, never choose on it)",
    )
    p.add_argument(
        "--seed",
        type=ranged(int, 0, MAX_SEED),
        default=None,
        help="base seed of the episode seeds, instead of --split",
    )
    p.add_argument("--out", default=None, help="result JSON (results/<agent>/<suite>.json)")
    add_workers_arg(p, 1, "processes running batches (1)")
    p.add_argument(
        "--backend",
        choices=("local", "ray"),
        default="local",
        help="run batches in local processes or as Ray tasks (the ray extra); same results",
    )
    p.add_argument(
        "--address",
        default=None,
        help="with --backend ray: the cluster address (default: a local Ray of --workers CPUs)",
    )
    p.add_argument("--resume", action="store_true", help="finish an interrupted run")
    p.add_argument("--force", action="store_true", help="overwrite an existing result file")
    p.add_argument(
        "--wide", action="store_true", help="print every metric (default: a compact summary)"
    )
    p.add_argument(
        "--batch-size",
        type=ranged(int, 1, MAX_BATCH_SIZE),
        default=None,
        help=f"episodes stepped in lock-step per batch (200, at most {MAX_BATCH_SIZE}); part of "
        "the result key",
    )
    add_agent_args(p)
    p.add_argument("--no-progress", action="store_true", help="no progress bar")

    c = add_command(
        sub, "compare", _compare, "paired comparison of two results on the same episodes"
    )
    c.add_argument("result_a")
    c.add_argument("result_b")
    _add_scenarios_arg(
        c, "compare on these scenarios only (repeatable; default: every scenario both hold)"
    )
    c.add_argument("--json", default=None, help="also write the comparison as JSON here")

    r = add_command(
        sub,
        "report",
        _report,
        "Markdown table of result files (every metric and role, 95 %% intervals)",
    )
    r.add_argument("results", nargs="+", help="result JSON files")
    r.add_argument("--out", default=None, help="write here instead of printing")


def add_command(
    sub: Any, name: str, func: Callable[[argparse.Namespace], int], help: str
) -> argparse.ArgumentParser:
    """The subcommand ``name`` of the subparsers ``sub``, run as ``func(args)`` (its exit code):
    ``help`` is its line in the parent's list, ``func``'s docstring (if any) the description its
    ``--help`` shows (re-wrapped by argparse)."""
    p = sub.add_parser(name, help=help, description=func.__doc__)
    p.set_defaults(func=func)
    return p


def _add_scenarios_arg(p: argparse.ArgumentParser, help: str) -> None:
    """``--scenario NAME``, repeatable: the scenarios the command runs or reads (none given: an
    empty list, the command's default set)."""
    p.add_argument("--scenario", action="append", default=[], metavar="NAME", help=help)


_TIME_LIMITS = {
    "--decision-timeout": "one decision call, enforced from outside the agent's process (10 s)",
    "--load-timeout": "importing and constructing the agent (300 s)",
}
"""The time limits of the agent's process, by flag: what each bounds (the flag's help, after
``time limit of``); both are seconds in (0, MAX_TIMEOUT_S]."""


def add_agent_args(p: argparse.ArgumentParser) -> None:
    """The options of the agent's process (shared by every command that runs an agent)."""
    from cdr_bench.evaluate.remote import MAX_TIMEOUT_S

    for flag, what in _TIME_LIMITS.items():
        p.add_argument(
            flag,
            type=ranged(float, 0, MAX_TIMEOUT_S, low_in=False),
            default=None,
            metavar="SECONDS",
            help=f"time limit of {what}",
        )
    p.add_argument(
        "--sandbox",
        action="store_true",
        help="confine the agent's process with bubblewrap: read-only view of the current "
        "folder, private scratch, no network, CPU and memory limits (for agents you do not "
        "trust; the agent always runs in its own process)",
    )


def add_episodes_arg(
    p: argparse.ArgumentParser,
    default: int | None,
    help: str,
    *,
    flag: str = "--episodes",
    least: int = 1,
) -> None:
    """An episode count (``--episodes`` unless ``flag`` says otherwise), ``least`` to
    :data:`~cdr_bench.checks.MAX_EPISODES`: every command that runs or checks episodes; ``help``
    says what they are and the default."""
    p.add_argument(flag, type=ranged(int, least, MAX_EPISODES), default=default, help=help)


def add_count_arg(
    p: argparse.ArgumentParser, flag: str, least: int, default: int, help: str
) -> None:
    """A count of steps, frames or agent calls, ``least`` to :data:`~cdr_bench.checks.MAX_STEPS`
    (the flags that bound or time a run)."""
    p.add_argument(flag, type=ranged(int, least, MAX_STEPS), default=default, help=help)


def add_workers_arg(p: argparse.ArgumentParser, default: int, help: str) -> None:
    """``--workers``: the processes that run episodes, 1 to
    :data:`~cdr_bench.checks.MAX_WORKERS`."""
    p.add_argument("--workers", type=ranged(int, 1, MAX_WORKERS), default=default, help=help)


def add_base_seed_arg(p: argparse.ArgumentParser) -> None:
    """``--seed``: the base seed of the episodes a scenario check or an analysis runs (0, the
    seeds of the split validation-0, unless given)."""
    p.add_argument(
        "--seed",
        type=ranged(int, 0, MAX_SEED),
        default=0,
        help="base seed of the episodes (0: validation-0; 1: validation; 20261127: test)",
    )


def agent_options(args: argparse.Namespace, agent: str) -> Any:
    """The :class:`~cdr_bench.evaluate.remote.AgentOptions` of :func:`add_agent_args`."""
    from cdr_bench.evaluate.loader import resolve_agent_path
    from cdr_bench.evaluate.remote import (
        DEFAULT_DECISION_TIMEOUT_S,
        DEFAULT_LOAD_TIMEOUT_S,
        AgentOptions,
        check_timeout,
    )
    from cdr_bench.evaluate.sandbox import Confinement, Limits, isolation

    decision = (
        DEFAULT_DECISION_TIMEOUT_S if args.decision_timeout is None else args.decision_timeout
    )
    load = DEFAULT_LOAD_TIMEOUT_S if args.load_timeout is None else args.load_timeout
    check_timeout("--decision-timeout", decision)
    check_timeout("--load-timeout", load)
    confinement = limits = None
    if args.sandbox:
        view = Path.cwd().resolve()
        f = resolve_agent_path(agent)
        if not f.is_relative_to(view):
            raise UserError(
                f"--sandbox: the agent {agent} is outside the current folder {view}, the only "
                "folder the sandbox lets it read; run from a folder that holds it"
            )
        limits = Limits()
        confinement = Confinement(view=str(view), limits=limits)
        _, how = isolation()
        print(f"cdr-bench: sandbox: {how}", file=sys.stderr)
    return AgentOptions(
        confinement=confinement, limits=limits, load_timeout_s=load, decision_timeout_s=decision
    )


def base_seed_of(args: argparse.Namespace) -> int:
    """The base seed ``--split`` or ``--seed`` names (validation by default)."""
    if args.split is not None and args.seed is not None:
        raise UserError("--split and --seed both name the episodes: give one")
    if args.seed is not None:
        return int(args.seed)
    return SPLITS[args.split or VALIDATION]


def _evaluate(args: argparse.Namespace) -> int:
    """Score an agent file (or folder with agent.py) on the paper's metrics. Default: the paper
    suite (low, medium, high and the tactical scenarios, 1000 episodes each). Writes a result JSON
    and a per-episode JSONL beside it. The reference agents direct, mvp and random are shipped in
    the package and named without a path (`cdr-bench evaluate mvp --scenario high`): the
    repository's agents/<name>/agent.py, with the same identity hash."""
    from cdr_bench.evaluate.api import default_out, evaluate, resolve_jobs
    from cdr_bench.evaluate.report import summary_text
    from cdr_bench.evaluate.results import check_output_path, episodes_path
    from cdr_bench.evaluate.runner import DEFAULT_BATCH_SIZE

    suite = args.suite if (args.suite or args.scenario) else "paper"
    jobs, notes = resolve_jobs(args.scenario, suite, args.episodes)
    for n in notes:
        print(f"cdr-bench: note: {n}", file=sys.stderr)
    options = agent_options(args, args.agent)
    out = check_output_path(args.out or default_out(args.agent, jobs, suite))
    check_output_path(episodes_path(out), "--out: the per-episode log")
    if out.exists() and not (args.force or args.resume):
        raise UserError(
            f"{out} exists (an earlier result); --force overwrites it, --out writes elsewhere"
        )
    result = evaluate(
        args.agent,
        jobs,
        out,
        base_seed=base_seed_of(args),
        suite=suite,
        workers=args.workers,
        resume=args.resume,
        batch_size=DEFAULT_BATCH_SIZE if args.batch_size is None else args.batch_size,
        agent_options=options,
        progress=not args.no_progress,
        backend=args.backend,
        address=args.address,
    )
    print(summary_text(result, wide=args.wide))
    print(f"wrote {out} and {episodes_path(out)}")
    return 0


def _compare(args: argparse.Namespace) -> int:
    from cdr_bench.evaluate.compare import compare, comparison_table
    from cdr_bench.evaluate.results import atomic_write_text, check_output_path

    if args.json:
        check_output_path(args.json, "--json")
    cmp = compare(args.result_a, args.result_b, scenarios=args.scenario or None)
    for note in cmp.get("notes", []):
        print(f"cdr-bench: note: {note}", file=sys.stderr)
    print(comparison_table(cmp))
    if args.json:
        atomic_write_text(Path(args.json), json.dumps(cmp, indent=1) + "\n")
    return 0


def _report(args: argparse.Namespace) -> int:
    """One Markdown table over result JSON files (one row per agent, scenario and aircraft role,
    every metric with its 95 % interval), rendered by cdr_bench.evaluate.report with the column list
    and number formats of every results table. The tables in the repository's docs are rendered by
    `cdr-bench leaderboard build` / `render-docs`."""
    from cdr_bench.evaluate.report import report_markdown
    from cdr_bench.evaluate.results import atomic_write_text, check_output_path, read_result

    if args.out:
        check_output_path(args.out)
    loaded = []
    for p in args.results:
        try:
            loaded.append((p, read_result(p)))
        except ValueError as e:
            raise UserError(str(e)) from None
    text = report_markdown(loaded)
    if args.out:
        atomic_write_text(Path(args.out), text)
        print(f"wrote {args.out}")
    else:
        print(text, end="")
    return 0
