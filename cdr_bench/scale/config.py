"""Sweep files: schema in code, values in YAML, unknown keys fail with the file and the field.

A sweep file (``sweeps/smoke.yaml`` is the smallest complete example)::

    name: smoke                      # default output folder: runs/sweeps/<name>
    agent: diffusion-ac              # a trainer of ``cdr-bench train``
    agent_file: ../agents/diffusion_ac/agent.py   # relative to this file; copied into each trial
    seeds: [1, 2]                    # every setting is trained once per seed
    budget: {total_steps: 300}       # --total-steps (and optionally max_wall_minutes)
    fixed: {n-envs: 4}               # trainer flags shared by every trial
    grid: {T: [8, 10]}               # one of: grid (cartesian product), settings (a list of
                                     #   flag dicts) or one_at_a_time (vary one factor around
                                     #   ``fixed``; a value may be a dict setting several flags)
    evaluation: {scenarios: [tactical/head-on], episodes: 4}   # names or YAML paths; on the
                                     #   validation episodes (split: validation or
                                     #   validation-0, or a base seed: seed: N; never test)
    max_retries: 3                   # re-runs of a trial whose worker or node died
    num_cpus_per_trial: 1

Hyper-parameter keys are the trainer's own flag names without the dashes (``T``,
``critic-width``, ``polyak``); they are checked against that trainer's parser, so a mistyped
flag or a value of the wrong type is an error before anything runs.
"""

from __future__ import annotations

import argparse
import hashlib
import importlib
import itertools
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from cdr_bench.checks import MAX_CONFIG_BYTES, read_input
from cdr_bench.errors import UserError
from cdr_bench.evaluate.seeds import SPLITS, TEST_SEED, VALIDATION

RESERVED_FLAGS = ("run-dir", "seed", "total-steps", "max-wall-minutes", "resume", "progress")
"""Set by the sweep itself; a sweep file may not set them as hyper-parameters."""

_TOP_KEYS = {
    "name",
    "agent",
    "agent_file",
    "seeds",
    "budget",
    "fixed",
    "grid",
    "settings",
    "one_at_a_time",
    "evaluation",
    "max_retries",
    "num_cpus_per_trial",
    "description",
}
_BUDGET_KEYS = {"total_steps", "max_wall_minutes"}
_EVAL_KEYS = {"scenarios", "episodes", "seed", "split", "batch_size"}


@dataclass(frozen=True)
class Trial:
    """One training run plus its evaluation."""

    key: str
    """First 16 hex digits of the SHA-256 of :meth:`identity`: the trial's folder name."""
    factor: str
    """Which factor this trial varies (``one_at_a_time``), ``"default"`` for the centre point,
    ``"grid"`` / ``"settings"`` otherwise."""
    label: str
    """The varied value as text (for plots)."""
    seed: int
    train_flags: dict[str, Any]
    """Every trainer flag the sweep sets, the reserved ones included, without ``--run-dir``."""
    agent: str
    agent_file: str
    evaluation: dict[str, Any]

    def identity(self) -> dict[str, Any]:
        return {
            "agent": self.agent,
            "agent_file_sha256": _sha256_file(Path(self.agent_file)),
            "train_flags": self.train_flags,
            "evaluation": self.evaluation,
        }

    def train_argv(self, run_dir: str) -> list[str]:
        argv = [self.agent, "--run-dir", run_dir]
        return argv + flags_argv(self.train_flags)


@dataclass(frozen=True)
class Sweep:
    name: str
    source: Path
    agent: str
    agent_file: Path
    trials: list[Trial]
    max_retries: int
    num_cpus_per_trial: float
    evaluation: dict[str, Any] = field(default_factory=dict)


def flags_argv(flags: dict[str, Any]) -> list[str]:
    """``{"T": 8, "curriculum": False}`` -> ``["--T", "8", "--no-curriculum"]``."""
    argv: list[str] = []
    for k, v in flags.items():
        if isinstance(v, bool):
            argv.append(f"--{k}" if v else f"--no-{k}")
        else:
            argv += [f"--{k}", str(v)]
    return argv


def _sha256_file(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _err(source: Path, where: str, msg: str) -> UserError:
    return UserError(f"{source}: {where or 'top level'}: {msg}")


def _mapping(source: Path, where: str, value: Any, allowed: set[str] | None) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise _err(source, where, f"expected a mapping, got {type(value).__name__}")
    for k in value:
        if not isinstance(k, str):
            raise _err(source, where, f"keys must be strings, got {k!r}")
        if allowed is not None and k not in allowed:
            raise _err(
                source,
                f"{where}.{k}" if where else k,
                f"unknown field (known: {', '.join(sorted(allowed))})",
            )
    return value


def _int(source: Path, where: str, value: Any, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise _err(source, where, f"expected an integer >= {minimum}, got {value!r}")
    return value


class _RaisingParser(argparse.ArgumentParser):
    def error(self, message: str) -> Any:  # type: ignore[override]
        raise ValueError(message)


def trainer_parser(agent: str) -> argparse.ArgumentParser:
    """The argument parser of ``cdr-bench train <agent>`` (raising instead of exiting)."""
    from cdr_bench.rl.cli import TRAINERS

    if agent not in TRAINERS:
        raise KeyError(agent)
    module = importlib.import_module(TRAINERS[agent])
    p = _RaisingParser(prog=f"cdr-bench train {agent}", add_help=False)
    module.add_arguments(p)
    return p


def _flag_dict(source: Path, where: str, value: Any, known: set[str]) -> dict[str, Any]:
    value = _mapping(source, where, value, None)
    for k, v in value.items():
        if k not in known:
            raise _err(
                source,
                f"{where}.{k}",
                f"not a flag of the trainer (known: {', '.join(sorted(known))})",
            )
        if k in RESERVED_FLAGS:
            raise _err(source, f"{where}.{k}", "set by the sweep (seeds / budget), not here")
        if not isinstance(v, (bool, int, float, str)):
            raise _err(source, f"{where}.{k}", f"expected a scalar, got {v!r}")
    return dict(value)


def _values(source: Path, where: str, value: Any) -> list[Any]:
    if not isinstance(value, list) or not value:
        raise _err(source, where, "expected a non-empty list")
    return value


def _eval_seed(source: Path, ev: dict[str, Any]) -> int:
    """The base seed of a sweep's evaluation: ``split`` (validation by default) or ``seed``;
    never the leaderboard's test set (cdr_bench.evaluate.seeds)."""
    if "split" in ev and "seed" in ev:
        raise _err(source, "evaluation", "give split or seed, not both")
    if "seed" in ev:
        seed = _int(source, "evaluation.seed", ev["seed"], 0)
    else:
        split = ev.get("split", VALIDATION)
        if split not in SPLITS:
            raise _err(source, "evaluation.split", f"expected one of {list(SPLITS)}, got {split!r}")
        seed = SPLITS[split]
    if seed == TEST_SEED:
        raise _err(
            source,
            "evaluation",
            "the test episodes score a finished leaderboard entry once and nothing is chosen "
            "on them; a sweep evaluates on validation (split: validation or validation-0)",
        )
    return seed


def load_sweep(
    path: str | Path,
    *,
    total_steps: int | None = None,
    episodes: int | None = None,
    overrides: dict[str, Any] | None = None,
    seeds: list[int] | None = None,
    scenarios: list[str] | None = None,
    where: dict[str, Any] | None = None,
) -> Sweep:
    """Parse and validate a sweep file; the trials in a fixed order (setting-major, then seed).

    ``total_steps`` / ``episodes`` replace ``budget.total_steps`` / ``evaluation.episodes`` and
    ``overrides`` (flag -> value) are merged into ``fixed``; ``seeds`` / ``scenarios`` replace
    ``seeds`` / ``evaluation.scenarios``: a reduced run of a big sweep (the trial keys change
    with them). ``where`` (flag -> value) keeps only the trials whose training flags have every
    one of those values: a part of the sweep, e.g. one setting per core, with the same trial
    keys as the whole."""
    source = Path(path)
    try:
        raw = yaml.safe_load(read_input(source, MAX_CONFIG_BYTES, "sweep file").decode("utf-8"))
    except UnicodeDecodeError as e:
        raise UserError(f"{source}: not UTF-8 text ({e.reason} at byte {e.start})") from None
    except yaml.YAMLError as e:
        raise UserError(f"{source}: not valid YAML: {str(e).splitlines()[0]}") from None
    raw = _mapping(source, "", raw, _TOP_KEYS)
    for req in ("name", "agent", "seeds", "budget", "evaluation"):
        if req not in raw:
            raise _err(source, req, "missing required field")
    name = raw["name"]
    if not isinstance(name, str) or not name or "/" in name:
        raise _err(source, "name", f"expected a non-empty name without '/', got {name!r}")
    agent = raw["agent"]
    try:
        parser = trainer_parser(str(agent))
    except KeyError:
        from cdr_bench.rl.cli import TRAINERS

        raise _err(
            source, "agent", f"unknown trainer {agent!r} (known: {', '.join(TRAINERS)})"
        ) from None
    known = {a.option_strings[0][2:] for a in parser._actions if a.option_strings}
    from cdr_bench.rl.cli import args_class
    from cdr_bench.rl.common import from_namespace

    args_cls = args_class(agent)
    agent_file = source.parent / raw.get(
        "agent_file", f"../agents/{agent.replace('-', '_')}/agent.py"
    )
    if not agent_file.is_file():
        raise _err(source, "agent_file", f"no such file {agent_file}")

    seeds = _values(source, "seeds", raw["seeds"] if seeds is None else seeds)
    for i, s in enumerate(seeds):
        _int(source, f"seeds[{i}]", s, 0)
    if len(set(seeds)) != len(seeds):
        raise _err(source, "seeds", "a seed is given twice")

    budget = _mapping(source, "budget", raw["budget"], _BUDGET_KEYS)
    if "total_steps" not in budget:
        raise _err(source, "budget.total_steps", "missing required field")
    steps = budget["total_steps"] if total_steps is None else total_steps
    base: dict[str, Any] = {"total-steps": _int(source, "budget.total_steps", steps, 1)}
    if "max_wall_minutes" in budget:
        m = budget["max_wall_minutes"]
        if isinstance(m, bool) or not isinstance(m, (int, float)) or m < 0:
            raise _err(source, "budget.max_wall_minutes", f"expected a number >= 0, got {m!r}")
        base["max-wall-minutes"] = float(m)
    fixed_raw = _mapping(source, "fixed", raw.get("fixed") or {}, None)
    fixed = _flag_dict(source, "fixed", {**fixed_raw, **(overrides or {})}, known)

    modes = [k for k in ("grid", "settings", "one_at_a_time") if k in raw]
    if len(modes) > 1:
        raise _err(source, modes[1], f"give only one of grid, settings, one_at_a_time ({modes})")
    points: list[tuple[str, str, dict[str, Any]]] = []  # (factor, label, flags)
    if not modes:
        points.append(("default", "default", {}))
    elif modes[0] == "grid":
        grid = _mapping(source, "grid", raw["grid"], None)
        axes = []
        for k, vals in grid.items():
            for i, v in enumerate(_values(source, f"grid.{k}", vals)):
                _flag_dict(source, f"grid.{k}[{i}]", {k: v}, known)
            axes.append([(k, v) for v in vals])
        for combo in itertools.product(*axes):
            flags = dict(combo)
            points.append(("grid", ",".join(f"{k}={v}" for k, v in combo), flags))
    elif modes[0] == "settings":
        for i, s in enumerate(_values(source, "settings", raw["settings"])):
            flags = _flag_dict(source, f"settings[{i}]", s, known)
            points.append(("settings", ",".join(f"{k}={v}" for k, v in flags.items()), flags))
    else:
        oat = _mapping(source, "one_at_a_time", raw["one_at_a_time"], None)
        points.append(("default", "default", {}))
        for factor, vals in oat.items():
            for i, v in enumerate(_values(source, f"one_at_a_time.{factor}", vals)):
                w = f"one_at_a_time.{factor}[{i}]"
                flags = _flag_dict(source, w, v if isinstance(v, dict) else {factor: v}, known)
                label = str(v) if not isinstance(v, dict) else str(next(iter(v.values())))
                if all(fixed.get(k) == x for k, x in flags.items()):
                    continue  # the centre point: already the "default" trial
                points.append((factor, label, flags))

    ev = _mapping(source, "evaluation", raw["evaluation"], _EVAL_KEYS)
    scen = _values(
        source, "evaluation.scenarios", ev.get("scenarios") if scenarios is None else scenarios
    )
    for i, s in enumerate(scen):
        if not isinstance(s, str):
            raise _err(source, f"evaluation.scenarios[{i}]", f"expected a name, got {s!r}")
    from cdr_bench.scenarios import ScenarioError, load_scenario

    scen = list(scen)
    for i, name_i in enumerate(scen):
        if name_i.endswith((".yaml", ".yml")) and not Path(name_i).is_absolute():
            scen[i] = str((source.parent / name_i).resolve())  # relative to the sweep file
        try:
            load_scenario(scen[i])
        except ScenarioError as e:
            raise _err(source, f"evaluation.scenarios[{i}]", str(e)) from None
    evaluation = {
        "scenarios": list(scen),
        "episodes": _int(
            source,
            "evaluation.episodes",
            ev.get("episodes", 100) if episodes is None else episodes,
            1,
        ),
        "seed": _eval_seed(source, ev),
    }
    if ev.get("batch_size") is not None:
        evaluation["batch_size"] = _int(source, "evaluation.batch_size", ev["batch_size"], 1)

    max_retries = _int(source, "max_retries", raw.get("max_retries", 3), 0)
    cpus = raw.get("num_cpus_per_trial", 1)
    if isinstance(cpus, bool) or not isinstance(cpus, (int, float)) or cpus <= 0:
        raise _err(source, "num_cpus_per_trial", f"expected a number > 0, got {cpus!r}")

    agent_file = agent_file.resolve()
    trials, seen = [], set()
    for factor, label, flags in points:
        merged = {**fixed, **flags}
        for seed in seeds:
            train_flags = {**merged, **base, "seed": seed, "progress": False}
            try:
                ns = parser.parse_args(flags_argv(train_flags) + ["--run-dir", "x"])
                from_namespace(args_cls, ns)  # the checks across flags, e.g. --v-min < --v-max
            except ValueError as e:
                raise _err(source, f"{factor} {label}", str(e)) from None
            t = Trial("", factor, label, seed, train_flags, agent, str(agent_file), evaluation)
            key = hashlib.sha256(json.dumps(t.identity(), sort_keys=True).encode()).hexdigest()[:16]
            if key in seen:
                raise _err(source, f"{factor} {label}", "the same trial is listed twice")
            seen.add(key)
            trials.append(
                Trial(key, factor, label, seed, train_flags, agent, str(agent_file), evaluation)
            )
    if where:
        trials = _select(trials, where)
    return Sweep(name, source, agent, agent_file, trials, max_retries, float(cpus), evaluation)


def _select(trials: list[Trial], where: dict[str, Any]) -> list[Trial]:
    """The trials whose training flags match every ``flag: value`` of ``where``."""
    for flag, value in where.items():
        values = sorted({repr(t.train_flags[flag]) for t in trials if flag in t.train_flags})
        if not values:
            raise UserError(f"--where {flag}={value}: no trial of the sweep sets {flag}")
        if not any(t.train_flags.get(flag) == value for t in trials):
            raise UserError(
                f"--where {flag}={value}: no trial has this value (its values: {', '.join(values)})"
            )
    return [t for t in trials if all(t.train_flags.get(k) == v for k, v in where.items())]
