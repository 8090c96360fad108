"""Subcommand ``train`` (registered by cdr_bench.cli).

Standalone: ``python -m cdr_bench.rl.cli train diffusion-ac --total-steps 200``.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys
from typing import Any

from cdr_bench.errors import UserError

TRAINERS: dict[str, str] = {
    "diffusion-ac": "cdr_bench.rl.train_diffusion_ac",
    "ppo": "cdr_bench.rl.train_sb3",
    "maskable-ppo": "cdr_bench.rl.train_sb3",
    "td3": "cdr_bench.rl.train_sb3",
    "rainbow": "cdr_bench.rl.train_rainbow",
    "safe-dqn-x": "cdr_bench.rl.train_safe_dqn",
    "ippo": "cdr_bench.rl.mappo",
    "mappo": "cdr_bench.rl.mappo",
}
"""``cdr-bench train NAME``: trainer modules (one module may train several NAMEs). Each exposes
``add_arguments(parser, name=None)`` (its flags; with ``name``, the parsed namespace's
``algorithm`` is NAME) and ``run(namespace) -> dict`` (train, write the run directory, return a
JSON summary)."""


def args_class(name: str) -> type:
    """The dataclass of the flags of ``cdr-bench train NAME`` (its ``__post_init__`` checks the
    flags that depend on each other)."""
    module = importlib.import_module(TRAINERS[name])
    algorithm = getattr(module, "ALGORITHM", None)
    return algorithm.args if algorithm is not None else module.Args  # type: ignore[no-any-return]


_HELP = "train a learned reference agent"


def register_command(sub: Any) -> None:
    """``train`` listed with its help only (:func:`cdr_bench.cli.build_parser` registers its
    algorithms only when the command line names ``train``)."""
    sub.add_parser("train", help=_HELP)


def register(sub: Any) -> None:
    tr = sub.add_parser("train", help=_HELP)
    algos = tr.add_subparsers(dest="algorithm", required=True, metavar="ALGORITHM")
    for name, module_name in TRAINERS.items():
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as e:  # torch / SB3 missing: say how to get them, at run time
            p = algos.add_parser(name, help=f"(needs the train extra: {e.name} is not installed)")
            p.add_argument("rest", nargs=argparse.REMAINDER)
            p.set_defaults(func=_missing_extra(name, str(e.name)))
            continue
        p = algos.add_parser(
            name,
            help=(module.__doc__ or name).strip().splitlines()[0],
            description=module.__doc__,
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        module.add_arguments(p, name)
        p.set_defaults(func=_train_with(module))


def _missing_extra(name: str, missing: str) -> Any:
    def fail(ns: argparse.Namespace) -> int:
        raise UserError(
            f"training {name} needs {missing!r}: pip install torch==2.13.0 'cdr-bench[train]'"
        )

    return fail


def _train_with(module: Any) -> Any:
    def cmd_train(ns: argparse.Namespace) -> int:
        _check_paths(ns)
        try:
            summary = module.run(ns)
        except ValueError as e:
            raise UserError(str(e)) from None
        except OSError as e:  # e.g. a run folder that cannot be made or written
            where = e.filename or ns.run_dir
            raise UserError(f"{where}: {e.strerror or e}") from None
        print(json.dumps(summary, indent=1))
        return 0

    return cmd_train


def _check_paths(ns: argparse.Namespace) -> None:
    """What the flags name must exist before anything is written: the training scenario (also
    with the curriculum, which does not use it) and, with ``--resume``, the state to resume."""
    from cdr_bench.scenarios import ScenarioError, load_scenario

    try:
        load_scenario(ns.scenario)
    except ScenarioError as e:
        raise UserError(f"--scenario {ns.scenario}: {e}") from None
    if os.path.exists(ns.run_dir) and not os.path.isdir(ns.run_dir):
        raise UserError(f"--run-dir {ns.run_dir}: exists and is not a folder")
    state = os.path.join(ns.run_dir, "state.pt")
    if ns.resume and not os.path.isfile(state):
        raise UserError(
            f"--resume: {state} does not exist: nothing to resume in {ns.run_dir} "
            "(leave out --resume to start a new run)"
        )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m cdr_bench.rl.cli")
    register(p.add_subparsers(dest="command", required=True))
    ns = p.parse_args(argv)
    try:
        return ns.func(ns)
    except UserError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
