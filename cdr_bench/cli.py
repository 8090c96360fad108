"""``cdr-bench`` command line. The CLI and the Python API call the same functions.

Subcommands are registered by the module that owns them: each module exposes
``register(subparsers)`` adding its parsers with ``set_defaults(func=...)``; ``func(args)``
returns the exit code. User errors raise :class:`UserError` (or ``ScenarioError``) and end with a
one-line message and exit code 2, never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from cdr_bench.errors import UserError

# Modules that add subcommands; a module missing from an install is skipped.
_SUBCOMMAND_MODULES = (
    "cdr_bench.cli",
    "cdr_bench.evaluate.cli",
    "cdr_bench.evaluate.analysis",
    "cdr_bench.rl.cli",
    "cdr_bench.leaderboard.cli",
    "cdr_bench.scale.cli",
)


def register(sub: Any) -> None:
    """The scenario and render subcommands."""
    sc = sub.add_parser("scenarios", help="list, show and validate scenarios")
    sc_sub = sc.add_subparsers(dest="scenarios_cmd", required=True)
    p = sc_sub.add_parser("list", help="list the shipped scenarios")
    p.set_defaults(func=_scenarios_list)
    p = sc_sub.add_parser("show", help="print the fully resolved config of a scenario as YAML")
    p.add_argument("name", help="registry name or YAML path")
    p.set_defaults(func=_scenarios_show)
    p = sc_sub.add_parser("validate", help="validate scenario YAML files")
    p.add_argument("files", nargs="+", help="YAML files (or registry names)")
    p.set_defaults(func=_scenarios_validate)
    p = sc_sub.add_parser("fields", help="print the scenario format: every field, type and range")
    p.set_defaults(func=_scenarios_fields)

    r = sub.add_parser("render", help="record an episode of a scenario as an animated GIF")
    r.add_argument("scenario", help="registry name or YAML path")
    r.add_argument("--out", required=True, help="output .gif path")
    r.add_argument(
        "--agent",
        default=None,
        help="agent file (default: every aircraft holds course, speed and level)",
    )
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--max-frames", type=int, default=400)
    r.add_argument("--fps", type=int, default=8)
    r.add_argument(
        "--zoom-km",
        type=float,
        default=None,
        help="show this many km around the ownship (default: the encounter in tactical "
        "scenarios, the whole sector otherwise; inf: the whole sector)",
    )
    from cdr_bench.evaluate.cli import add_agent_args

    add_agent_args(r)
    r.set_defaults(func=_render)


def _scenarios_list(args: argparse.Namespace) -> int:
    from cdr_bench.scenarios import list_scenarios, load_scenario

    for name in list_scenarios():
        cfg = load_scenario(name)
        print(f"{name:24s} {cfg.description}")
    return 0


def _scenarios_show(args: argparse.Namespace) -> int:
    import yaml

    from cdr_bench.scenarios import load_scenario

    cfg = load_scenario(args.name)
    print(f"# {cfg.id}  sha256 {cfg.config_hash()[:16]}")
    print(yaml.safe_dump(cfg.to_dict(), sort_keys=False, default_flow_style=None), end="")
    return 0


def _scenarios_validate(args: argparse.Namespace) -> int:
    from cdr_bench.scenarios import ScenarioError, load_scenario

    bad = 0
    for f in args.files:
        try:
            cfg = load_scenario(f)
            print(
                f"ok    {f}  ({cfg.id}, {cfg.n_route_intruders} airway intruders, "
                f"{len(cfg.aircraft)} placed, {cfg.n_learning_intruders} learning)"
            )
        except ScenarioError as e:
            bad += 1
            print(f"error {e}", file=sys.stderr)
    return 2 if bad else 0


def _scenarios_fields(args: argparse.Namespace) -> int:
    from cdr_bench.scenarios import field_docs

    for path, tp, doc in field_docs():
        print(f"{path:34s} {tp:28s} {doc}")
    return 0


def _render(args: argparse.Namespace) -> int:
    from cdr_bench.actions import HOLD
    from cdr_bench.env import CDREnv
    from cdr_bench.render import save_gif

    out = Path(args.out)
    if out.suffix.lower() != ".gif":
        raise UserError(f"--out {args.out}: expected a .gif path")
    env = CDREnv(args.scenario, render_mode="rgb_array")
    if args.zoom_km is not None:
        if not args.zoom_km > 0:
            raise UserError(f"--zoom-km: expected a number of km > 0 (or inf), got {args.zoom_km}")
        env.render_zoom_km = args.zoom_km
    policy: Any = None
    if args.agent is not None:
        from cdr_bench.evaluate.cli import agent_options
        from cdr_bench.evaluate.remote import AgentFault
        from cdr_bench.evaluate.runner import fault_message, load_for

        agent = load_for(args.agent, env.config, agent_options(args, args.agent))

        def act(o: dict[str, Any]) -> int:
            try:
                return int(agent.act_batch(o["observation"][None], o["action_mask"][None])[0])
            except AgentFault as f:
                raise UserError(fault_message(f, agent, f"{args.scenario!r}")) from None

        policy = act

    obs, _ = env.reset(seed=args.seed)
    frames: list[Any] = [env.render()]
    while env.agents and len(frames) < args.max_frames:
        actions = {a: (policy(obs[a]) if policy else HOLD) for a in env.agents}
        obs, _, _, _, infos = env.step(actions)
        frames.append(env.render())
    outcome = infos.get("ownship_0", {}).get("outcome", "running") if len(frames) > 1 else "-"
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.tmp")
    save_gif(frames, str(tmp), fps=args.fps)
    tmp.replace(out)
    print(f"wrote {out} ({len(frames)} frames, ownship outcome: {outcome})")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="cdr-bench",
        description="Benchmark suite for learned air-traffic conflict detection and resolution.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    for name in _SUBCOMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as e:
            if e.name and name.startswith(e.name):
                continue
            raise
        module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except UserError as e:
        print(f"cdr-bench: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("cdr-bench: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # run the imported module so its exception classes are the ones caught
    from cdr_bench.cli import main as _main

    sys.exit(_main())
