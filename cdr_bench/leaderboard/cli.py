"""``cdr-bench leaderboard build`` and ``render-docs`` (registered by :mod:`cdr_bench.cli`)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from cdr_bench.checks import MAX_SEED, ranged
from cdr_bench.evaluate.cli import add_command, add_episodes_arg, add_workers_arg
from cdr_bench.evaluate.sandbox import Limits

MAX_CPU_S = 30 * 86400
"""Largest ``--cpu-limit`` (CPU seconds per process): 30 days."""
MAX_MEMORY_MB = 4 << 20
"""Largest ``--memory-limit`` (MiB of address space per process): 4 TiB."""
MAX_WALL_S = 7 * 86400.0
"""Largest ``--timeout`` (wall-clock seconds per submission run): 7 days."""


def register(sub: Any) -> None:
    lb = sub.add_parser("leaderboard", help="build or check the leaderboard (leaderboard/)")
    lb_sub = lb.add_subparsers(dest="leaderboard_cmd", required=True)
    defaults = Limits()
    b = add_command(
        lb_sub,
        "build",
        _build,
        "render the leaderboard from result files; --evaluate re-runs submissions first",
    )
    _add_dir(b)
    b.add_argument(
        "--evaluate",
        nargs="*",
        metavar="NAME",
        default=None,
        help="re-evaluate these submissions (all when no name is given) before rendering",
    )
    b.add_argument(
        "--check",
        action="store_true",
        help="replay every committed episode, re-run each agent on a random sample, re-render "
        "and compare with the committed leaderboard; writes nothing",
    )
    add_episodes_arg(
        b,
        None,
        "episodes per scenario (--evaluate: 1000 = the paper's; named submissions: the committed "
        "count; --check: the committed count, or a smaller multiple of 200 to check the first "
        "episodes only)",
    )
    b.add_argument(
        "--all-seeds",
        action="store_true",
        help="--check: ask the agent of every training seed of every entry again (default: one "
        "run per entry, drawn at random among its seeds; every seed is always replayed)",
    )
    b.add_argument(
        "--sample-seed",
        type=ranged(int, 0, MAX_SEED),
        default=None,
        help="--check: seed of the agent re-run sample (default: drawn at random and printed, "
        "so a check can be repeated exactly)",
    )
    b.add_argument(
        "--rerun-batches",
        type=ranged(int, 1, 30),
        default=1,
        help="--check: batches of 200 committed episodes per run on which the agent is asked "
        "again, the first drawn among the headline scenario's (1)",
    )
    b.add_argument(
        "--fresh-episodes",
        type=int,
        default=200,
        help="--check: episodes of the headline scenario, from seeds drawn at check time, on "
        "which each entry's agent flies and must match its committed score (Fisher's exact "
        "test, p < 1e-4 fails; 0: no such test) (200)",
    )
    add_workers_arg(b, 2, "evaluation processes (2)")
    b.add_argument(
        "--cpu-limit",
        type=ranged(int, 1, MAX_CPU_S),
        default=defaults.cpu_s,
        help=f"CPU seconds per process ({defaults.cpu_s}; at most this host's hard limit)",
    )
    b.add_argument(
        "--memory-limit",
        type=ranged(int, 64, MAX_MEMORY_MB),
        default=defaults.memory_mb,
        help=f"address space per process, MiB ({defaults.memory_mb}; at least 64, at most this "
        "host's hard limit)",
    )
    b.add_argument(
        "--timeout",
        type=ranged(float, 0, MAX_WALL_S, low_in=False),
        default=defaults.wall_s,
        help=f"wall-clock seconds per submission run ({defaults.wall_s:g}; finite, at most "
        f"{MAX_WALL_S:g})",
    )
    b.add_argument(
        "--reference",
        default=None,
        help="entry the others are compared with on paired episodes (diffusion-ac)",
    )

    d = add_command(
        lb_sub,
        "render-docs",
        _render_docs,
        "rewrite the results tables in the docs' marked blocks from leaderboard/results",
    )
    _add_dir(d)
    d.add_argument(
        "--check",
        action="store_true",
        help="write nothing; exit code 1 and a diff if a block differs from what the files give",
    )
    _add_headroom(lb_sub)


HEADROOM_HELP = "plan the ranking's episodes with a planner that knows the traffic (unranked row)"


def _add_headroom(lb_sub: Any) -> None:
    h = add_command(lb_sub, "headroom", _headroom, HEADROOM_HELP)
    _add_dir(h)
    h.add_argument(
        "--reference",
        default=None,
        help="the entry whose committed episodes are planned (default: mvp; every entry is "
        "scored on the same episodes)",
    )


def _headroom(args: argparse.Namespace) -> int:
    """Fly every episode of the ranking's headline scenario (the committed entries' episodes: their
    base seed and count) with the clairvoyant planner of cdr_bench/evaluate/headroom.py and write
    leaderboard/headroom/<scenario>.json and its log: the unranked headroom row of the leaderboard
    (re-render with `build`). The planner knows the traffic's future, so it is not an agent and is
    never ranked; `build --check` replays its recorded decisions."""
    import sys

    from cdr_bench.errors import UserError
    from cdr_bench.evaluate.headroom import headroom_result
    from cdr_bench.evaluate.results import read_result
    from cdr_bench.leaderboard.data import DEFAULT_REFERENCE, HEADLINE_SCENARIO, headroom_path
    from cdr_bench.leaderboard.tables import result_path
    from cdr_bench.scenarios import load_scenario

    d = _leaderboard_dir(args)
    ref = result_path(d / "results", args.reference or DEFAULT_REFERENCE)
    if not ref.is_file():
        raise UserError(f"headroom: {ref}: no result of the reference entry (--reference)")
    try:
        result = read_result(ref, metrics=False)
    except ValueError as e:
        raise UserError(f"headroom: the reference entry's result is needed ({e})") from None
    sc = next((s for s in result["scenarios"] if s["id"] == HEADLINE_SCENARIO), None)
    if sc is None:
        raise UserError(f"{ref}: no {HEADLINE_SCENARIO} episodes to plan")
    config = load_scenario(HEADLINE_SCENARIO)
    if config.config_hash() != sc["config_hash"]:
        raise UserError(f"{ref}: scored on another configuration of {HEADLINE_SCENARIO}")
    out = headroom_path(d)
    got = headroom_result(
        config,
        int(result["base_seed"]),
        int(sc["episodes"]),
        out,
        batch_size=int(result["batch_size"]),
        progress=True,
    )
    m = got["scenarios"][0]["metrics"]["ownship"]["clean_success_rate"]
    print(
        f"cdr-bench leaderboard: wrote {out}: clean success {100 * m['value']:.1f} % "
        f"({m['count']}/{m['n']})",
        file=sys.stderr,
    )
    return 0


def _add_dir(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--dir", default="leaderboard", help="the leaderboard folder (default: leaderboard)"
    )


def _leaderboard_dir(args: argparse.Namespace) -> Path:
    """``--dir``, which must be a folder."""
    from cdr_bench.errors import UserError

    d = Path(args.dir)
    if not d.is_dir():
        raise UserError(f"--dir {d}: no such folder")
    return d


def _build(args: argparse.Namespace) -> int:
    """Render leaderboard/README.md, index.html, leaderboard.json and plots/ from the submissions
    and the result files in leaderboard/results, then the results tables in the marked blocks of
    the repository's docs (as render-docs). With --evaluate, first score every submission (or the
    named ones) in its own sandboxed process. With --check, replay every committed episode from
    its recorded decisions, ask each entry's agent again on a random sample of them, and fail
    (exit code 1, with a diff) if a record, the agreement, the committed leaderboard or a docs
    block differs."""
    from cdr_bench.errors import UserError
    from cdr_bench.leaderboard.build import Options, run
    from cdr_bench.leaderboard.data import DEFAULT_REFERENCE

    if not 0 <= args.fresh_episodes <= 10_000 or args.fresh_episodes % 200:
        raise UserError(
            f"--fresh-episodes: expected a multiple of 200 in 0..10000, got {args.fresh_episodes}"
        )
    check_host_limits(args.cpu_limit, args.memory_limit)
    d = _leaderboard_dir(args)
    opts = Options(
        leaderboard_dir=d,
        evaluate=args.evaluate,
        check=args.check,
        episodes=args.episodes,
        workers=args.workers,
        limits=Limits(cpu_s=args.cpu_limit, memory_mb=args.memory_limit, wall_s=args.timeout),
        reference=args.reference or DEFAULT_REFERENCE,
        all_seeds=args.all_seeds,
        sample_seed=args.sample_seed,
        rerun_batches=args.rerun_batches,
        fresh_episodes=args.fresh_episodes,
    )
    rc = run(opts)
    if rc == 0 or args.check:
        rc = max(rc, _docs(d, args.check))
    return rc


def check_host_limits(cpu_s: int, memory_mb: int) -> None:
    """A one-line :class:`UserError` when a limit is above this host's hard limit (``ulimit
    -Ht`` / ``-Hv``): the process that sets it could not, and would fail when started. The
    CPU limit is set with a hard limit 5 s above it (:func:`~cdr_bench.evaluate.sandbox
    .set_limits`)."""
    import resource

    from cdr_bench.errors import UserError

    for flag, value, rlimit, margin, shift, unit in (
        ("--cpu-limit", cpu_s, resource.RLIMIT_CPU, 5, 0, "CPU seconds (ulimit -Ht)"),
        ("--memory-limit", memory_mb, resource.RLIMIT_AS, 0, 20, "MiB (ulimit -Hv)"),
    ):
        hard = resource.getrlimit(rlimit)[1]
        if hard != resource.RLIM_INFINITY and (value << shift) + margin > hard:
            most = (hard - margin) >> shift
            raise UserError(f"{flag} {value}: this host's hard limit allows at most {most} {unit}")


def _docs(lb_dir: Path, check: bool) -> int:
    import sys

    from cdr_bench.leaderboard.tables import render_docs

    diffs = render_docs(lb_dir, check=check)
    if check and diffs:
        print(
            "docs check FAILED: these marked blocks differ from what the result files give "
            "(regenerate with `cdr-bench leaderboard render-docs`):\n",
            file=sys.stderr,
        )
        print("\n\n".join(diffs), file=sys.stderr)
        return 1
    if check:
        msg = "docs blocks match the result files"
    elif diffs:
        msg = f"rewrote the results blocks of {len(diffs)} doc file(s)"
    else:
        msg = "docs blocks already current"
    print(f"cdr-bench leaderboard: {msg}", file=sys.stderr)
    return 0


def _render_docs(args: argparse.Namespace) -> int:
    """Rewrite every marked block (<!-- name:start --> ... <!-- name:end -->) of README.md,
    agents/BASELINES.md and agents/diffusion_ac/README.md from the committed files:
    leaderboard/results, leaderboard/published and the agents' training and latency logs (what each
    block shows: cdr_bench/leaderboard/tables.py; rendered by cdr_bench/evaluate/report.py). Reads
    result files only; `build` does this too."""
    return _docs(_leaderboard_dir(args), args.check)
