"""``cdr-bench`` command line. The CLI and the Python API call the same functions.

Subcommands are registered by the module that owns them: each module exposes
``register(subparsers)`` adding its parsers with ``set_defaults(func=...)``; ``func(args)``
returns the exit code. User errors raise :class:`UserError` (or ``ScenarioError``) and end with a
one-line message and exit code 2, never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import io
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from cdr_bench.checks import MAX_SEED, ranged
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
    from cdr_bench.evaluate.cli import (
        add_agent_args,
        add_base_seed_arg,
        add_count_arg,
        add_episodes_arg,
    )

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
    p = sc_sub.add_parser(
        "certify",
        help="certify a tactical or multi-aircraft family: holding fails, several manoeuvre "
        "families (joint patterns) succeed per episode, the MVP resolver (for every aircraft) "
        "solves 30-90 %% (docs/model.md §8.3, §8.4.1)",
    )
    p.add_argument("name", help="registry name or YAML path")
    add_episodes_arg(p, 1000, "episodes for holding and the agent (1000)")
    add_episodes_arg(
        p,
        200,
        "episodes searched for manoeuvre families (200; the first of the same episodes)",
        flag="--search-episodes",
        least=0,
    )
    p.add_argument(
        "--agent",
        default="agents/mvp",
        help="the reference resolver, run in this process (trusted code only; 'none' skips it)",
    )
    add_base_seed_arg(p)
    p.add_argument(
        "--enough",
        type=ranged(int, 1, 5),
        default=None,
        help="stop an episode's search once this many families are found (faster; default: "
        "search every family)",
    )
    p.add_argument("--out", default=None, help="write the full report (JSON) here")
    p.set_defaults(func=_scenarios_certify)

    r = sub.add_parser("render", help="record an episode of a scenario as an animated GIF")
    r.add_argument("scenario", help="registry name or YAML path")
    r.add_argument("--out", required=True, help="output .gif path")
    r.add_argument(
        "--agent",
        default=None,
        help="agent file (default: every aircraft holds course, speed and level)",
    )
    r.add_argument("--seed", type=ranged(int, 0, MAX_SEED), default=0, help="episode seed (0)")
    add_count_arg(r, "--max-frames", 1, 400, "stop after this many frames (400)")
    r.add_argument(
        "--fps", type=ranged(int, 1, 100), default=8, help="frames per second, 1 to 100 (8)"
    )
    r.add_argument(
        "--zoom-km",
        type=ranged(float, 0, float("inf"), low_in=False, inf_ok=True),
        default=None,
        help="show this many km around the ownship (default: the encounter in tactical "
        "scenarios, the whole sector otherwise; inf: the whole sector)",
    )
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


def _scenarios_certify(args: argparse.Namespace) -> int:
    import json

    from cdr_bench.evaluate.results import atomic_write_text, check_output_path
    from cdr_bench.evaluate.search import certify
    from cdr_bench.scenarios import load_scenario

    if args.out:
        check_output_path(args.out)
    agent = None if args.agent.lower() == "none" else args.agent
    if agent is not None and not Path(agent).exists():
        raise UserError(f"--agent {agent}: no such file or folder (give a path, or 'none')")
    cfg = load_scenario(args.name)
    r = certify(
        cfg,
        episodes=args.episodes,
        search_episodes=args.search_episodes,
        agent=agent,
        base_seed=args.seed,
        enough=args.enough,
    )

    def mark(ok: bool) -> str:
        return "ok  " if ok else "FAIL"

    def pct(x: float) -> str:
        return f"{100 * x:.1f} %"

    h, f = r["hold"], r["families"]
    print(f"{cfg.id} (version {cfg.version}, config {r['config_hash'][:16]}, seed {args.seed})")
    print(
        f"{mark(h['ok'])} (a) holding fails in {h['failures']} / {h['episodes']} episodes "
        f"({pct(h['failure_rate'])}, 95 % CI {pct(h['ci95'][0])}-{pct(h['ci95'][1])}; "
        f"required {h['required']})  [{h['seconds']} s]"
    )
    if f["episodes"]:
        dist = ", ".join(f"{n}: {c}" for n, c in f["distribution"].items() if c)
        found = ", ".join(f"{k} {v}" for k, v in f["found"].items())
        simple = ", ".join(f"{k} {v}" for k, v in f["simple_manoeuvre_succeeds"].items())
        enough = f", search stopped at {f['enough']} families" if f["enough"] else ""
        print(
            f"{mark(f['ok'])} (b) {f['kind']} per episode over {f['episodes']} "
            f"episodes{enough}: {dist} (mean {f['mean']:.2f}); >= 2 in "
            f"{pct(f['share_at_least'])}; required {f['required']}  [{f['seconds']} s]"
        )
        print(f"       episodes with a success, per pattern: {found}")
        if simple:
            print(f"       ... by the plain manoeuvre of the family: {simple}")
        for ep in f["per_episode"]:
            if len(ep["families"]) < 2:
                print(f"       episode {ep['episode']} (seed {ep['seed']}): {ep['families']}")
    if "agent" in r:
        a = r["agent"]
        print(
            f"{mark(a['ok'])} (c) {a['path']} flying {a['flies']} succeeds in "
            f"{a['successes']} / {a['episodes']} "
            f"episodes ({pct(a['success_rate'])}, 95 % CI {pct(a['ci95'][0])}-"
            f"{pct(a['ci95'][1])}; required {a['required']})  [{a['seconds']} s]"
        )
    names = ", ".join(f["names"]) if f["episodes"] else ""
    print(
        f"{'certified' if r['ok'] else 'NOT certified'}"
        + (f" ({f['kind']}: {names})" if names else "")
    )
    if args.out:
        atomic_write_text(Path(args.out), json.dumps(r, indent=1) + "\n")
    return 0 if r["ok"] else 1


def _render(args: argparse.Namespace) -> int:
    from cdr_bench.actions import HOLD
    from cdr_bench.env import CDREnv
    from cdr_bench.evaluate.results import atomic_write_text, check_output_path
    from cdr_bench.render import save_gif

    out = Path(args.out)
    if out.suffix.lower() != ".gif":
        raise UserError(f"--out {args.out}: expected a .gif path")
    check_output_path(out)  # before the episode is run
    env = CDREnv(args.scenario, render_mode="rgb_array")
    if args.zoom_km is not None:
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
    gif = io.BytesIO()
    save_gif(frames, gif, fps=args.fps)
    atomic_write_text(out, gif.getvalue())  # never replaces anything but a regular file
    print(f"wrote {out} ({len(frames)} frames, ownship outcome: {outcome})")
    return 0


def build_parser(trainers: bool = True) -> argparse.ArgumentParser:
    """The ``cdr-bench`` parser; ``trainers=False``: ``train`` without its algorithms' flags
    (what every other command needs: building them imports each trainer module, a fifth of a
    second at every start)."""
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
        if trainers or name != "cdr_bench.rl.cli":
            module.register(sub)
        else:
            module.register_command(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(trainers="train" in argv)
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except UserError as e:
        print(f"cdr-bench: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:  # a file the command needed could not be read or written
        where = f"{e.filename}: " if e.filename else ""
        print(f"cdr-bench: error: {where}{e.strerror or e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("cdr-bench: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # run the imported module so its exception classes are the ones caught
    from cdr_bench.cli import main as _main

    sys.exit(_main())
