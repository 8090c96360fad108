"""``cdr-bench leaderboard build`` (registered by :mod:`cdr_bench.cli`)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from cdr_bench.leaderboard.sandbox import Limits


def register(sub: Any) -> None:
    lb = sub.add_parser("leaderboard", help="build or check the leaderboard (leaderboard/)")
    lb_sub = lb.add_subparsers(dest="leaderboard_cmd", required=True)
    defaults = Limits()
    b = lb_sub.add_parser(
        "build",
        help="render the leaderboard from result files; --evaluate re-runs submissions first",
        description="Render leaderboard/README.md, index.html, leaderboard.json and plots/ from "
        "the submissions and the result files in leaderboard/results. With --evaluate, first "
        "score every submission (or the named ones) in its own sandboxed process. With --check, "
        "re-evaluate and fail (exit code 1, with a diff) if the committed leaderboard differs.",
    )
    b.add_argument(
        "--dir", default="leaderboard", help="the leaderboard folder (default: leaderboard)"
    )
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
        help="re-evaluate and compare with the committed leaderboard; writes nothing",
    )
    b.add_argument(
        "--episodes",
        type=int,
        default=None,
        help="episodes per scenario (--evaluate: 1000 = the paper's; named submissions: the "
        "committed count; --check: the committed count, or a smaller multiple of 200 to check "
        "the first episodes only)",
    )
    b.add_argument("--workers", type=int, default=2, help="evaluation processes (2)")
    b.add_argument("--cpu-limit", type=int, default=defaults.cpu_s, help="CPU seconds per process")
    b.add_argument(
        "--memory-limit",
        type=int,
        default=defaults.memory_mb,
        help="address space per process, MiB",
    )
    b.add_argument(
        "--timeout",
        type=float,
        default=defaults.wall_s,
        help="wall-clock seconds per submission run",
    )
    b.add_argument(
        "--reference",
        default=None,
        help="entry the others are compared with on paired episodes (diffusion-ac)",
    )
    b.set_defaults(func=_build)


def _build(args: argparse.Namespace) -> int:
    from cdr_bench.errors import UserError
    from cdr_bench.leaderboard.build import Options, run
    from cdr_bench.leaderboard.data import DEFAULT_REFERENCE

    if args.workers < 1:
        raise UserError(f"--workers must be >= 1, got {args.workers}")
    if args.cpu_limit < 1 or args.memory_limit < 64 or args.timeout <= 0:
        raise UserError("--cpu-limit, --memory-limit (>= 64 MiB) and --timeout must be positive")
    d = Path(args.dir)
    if not d.is_dir():
        raise UserError(f"--dir {d}: no such folder")
    opts = Options(
        leaderboard_dir=d,
        evaluate=args.evaluate,
        check=args.check,
        episodes=args.episodes,
        workers=args.workers,
        limits=Limits(cpu_s=args.cpu_limit, memory_mb=args.memory_limit, wall_s=args.timeout),
        reference=args.reference or DEFAULT_REFERENCE,
    )
    return run(opts)
