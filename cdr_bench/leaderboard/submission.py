"""Leaderboard submissions: ``leaderboard/submissions/<name>.yaml``, one file per entry.

The schema lives here (:data:`FIELDS`); the YAML holds values only. Loading is strict: an
unknown key, a missing required key, a wrong type or a path that does not exist is a
:class:`SubmissionError` naming the file, the field and what was expected.

Example (``leaderboard/submissions/mvp.yaml``)::

    display_name: MVP (geometric resolver)
    description: Modified Voltage Potential adapted to the 27 discrete actions
    agent: agents/mvp/agent.py
    checkpoint: null
    authors: [cdr-bench contributors]
    reference: agents/mvp/agent.py
    training: null
    scenarios: paper
    replays: [tactical/head-on, tactical/crossing, tactical/overtaking]

A learned entry also names its training logs (``training_logs``: one JSON-lines log per seed,
plain ``.jsonl`` or xz ``.jsonl.xz``;
the budget and seed columns and the learning curves are read from them) and, when it is an
ablation of another entry, ``group: ablation``; a scripted resolver with a learned part
(MVP with a learned override) is ``group: hybrid``, ranked and summarised apart from the agents
that learn from scratch.

An entry trained with several seeds lists them all (``seeds``), each with its checkpoint and log;
``checkpoint`` names the seed whose episodes the per-episode views show (replays, multimodality,
the paired tests). Every seed is scored on the same episodes (``results/<name>.json`` for that
seed, ``results/<name>.seed-<k>.json`` for the others) and the leaderboard aggregates them::

    checkpoint: agents/ppo/seeds/1/checkpoint.pt
    seeds:
      - seed: 1
        checkpoint: agents/ppo/seeds/1/checkpoint.pt
        training_log: agents/ppo/seeds/1/training_log.jsonl.xz
      - seed: 2
        checkpoint: agents/ppo/seeds/2/checkpoint.pt
        training_log: agents/ppo/seeds/2/training_log.jsonl.xz

Paths (``agent``, ``checkpoint``, a ``reference`` that is not a URL) are relative to the
repository root, i.e. the folder holding ``leaderboard/``, and must stay inside it.

A submission file is read like a scenario file (:mod:`cdr_bench.scenarios.loader`): at most
:data:`MAX_FILE_BYTES`, UTF-8, no YAML anchors, aliases, tags, merge keys or duplicate keys,
nested at most 20 deep. Free text (``display_name``, ``description``, ``authors``,
``reference``, ``training``) is one line, without control or invisible characters, within the
length caps of :mod:`cdr_bench.leaderboard.text`; a display name holds letters, digits, spaces
and a little punctuation, and no two entries' display names look alike
(:func:`~cdr_bench.leaderboard.text.skeleton`). Every such problem of a file is reported at
once; :func:`load_submissions` reports those of every file.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import yaml

from cdr_bench.errors import ScenarioError, UserError, short_repr
from cdr_bench.evaluate.results import LOG_SUFFIX
from cdr_bench.leaderboard import text as tx
from cdr_bench.scenarios.loader import _read_text, _ScenarioYamlLoader, _yaml_problem, parse_yaml

NAME_RE = re.compile(r"^[a-z0-9][a-z0-9-]{0,63}$")
GROUPS = ("scripted", "learned", "hybrid", "ablation")
TRACKS = ("single-agent", "multi-agent")
"""The leaderboard's two tracks. ``single-agent``: the agent flies the ownship of the paper's
scenarios (ranked by the ownship's clean success on ``high``). ``multi-agent``: it flies every
controlled aircraft of the scenarios whose traffic is controlled (ranked by the share of clean
flights on ``marl/high-all``; docs/model.md §10.1.3)."""
TRACK_HEADLINE = {"single-agent": "high", "multi-agent": "marl/high-all"}
"""The scenario that ranks each track (its first re-run batch and fresh episodes in ``--check``
are drawn from it)."""
TRACK_EPISODES = {"single-agent": 1000, "multi-agent": 200}
"""Episodes per scenario of a full evaluation in each track. The multi-agent track's episodes
hold every controlled flight (37-49 at ``medium-all``/``high-all``), and the episode is the unit
of its intervals: 200 episodes are ~9,800 flights at ``high-all``."""
"""Groups of measured entries, in display order (the paper's numbers are a fourth group,
``published``, never measured here)."""
CHECKPOINT_SUFFIXES = (".pt", ".pth", ".safetensors", ".npz")
TRAINING_LOG_SUFFIXES = (".jsonl", LOG_SUFFIX)
"""A training log is JSON lines, plain or xz (:func:`cdr_bench.evaluate.results.compress_log`:
the shipped logs are kept compressed)."""
_LOG_FILE = f"a {' or '.join(TRAINING_LOG_SUFFIXES)} file"
"""Checkpoint formats that load without unpickling arbitrary objects (``torch.load`` with
``weights_only=True``, safetensors, ``numpy.load`` with ``allow_pickle=False``)."""


MAX_FILE_BYTES = 1 << 20
"""Largest submission file read (1 MiB, the scenario files' cap; the shipped ones are below
2 KiB)."""
MAX_LISTED = 20
"""An error with more problems lists this many."""


class SubmissionError(UserError):
    """A submission file is invalid; the message names the file, the field and what was
    expected: one line, or with several problems (``problems``: (field, message) pairs) a first
    line ``SOURCE: N errors:`` and one line per problem."""

    def __init__(
        self,
        source: str | os.PathLike[str],
        field: str,
        message: str,
        *,
        more: Sequence[tuple[str, str]] = (),
    ):
        self.source = str(source)
        self.field = field
        self.problems = [(field, message), *more]
        if not more:
            super().__init__(f"{source}: {field}: {message}" if field else f"{source}: {message}")
            return
        lines = [f"{source}: {len(self.problems)} errors:"]
        lines += [f"  {f}: {m}" if f else f"  {m}" for f, m in self.problems[:MAX_LISTED]]
        if len(self.problems) > MAX_LISTED:
            lines.append(f"  ... and {len(self.problems) - MAX_LISTED} more")
        super().__init__("\n".join(lines))

    @classmethod
    def of(
        cls, source: str | os.PathLike[str], problems: Sequence[tuple[str, str]]
    ) -> SubmissionError:
        """One error carrying every (field, message) problem of ``source``."""
        (field, message), *more = problems
        return cls(source, field, message, more=more)


class _SubmissionYamlLoader(_ScenarioYamlLoader):
    """The scenario files' hardened YAML loader (no aliases, anchors, tags, merge keys or
    duplicate keys; bounded depth and integers), naming submission files in its messages."""

    _kind = "submission files"


def _read_yaml(src: Path) -> Any:
    """The parsed file, read like a scenario file; every failure a :class:`SubmissionError`."""
    try:
        text = _read_text(src)
    except ScenarioError as e:
        raise SubmissionError(src, "", e.message) from None
    try:
        return parse_yaml(text, _SubmissionYamlLoader)
    except yaml.YAMLError as e:
        problem = _yaml_problem(e).removeprefix("invalid YAML")
        raise SubmissionError(src, "", f"not valid YAML{problem}") from None
    except RecursionError:  # pragma: no cover - the loader's depth cap stops nesting first
        raise SubmissionError(src, "", "not valid YAML: nested too deep") from None


@dataclass(frozen=True)
class Seed:
    """One training seed of an entry: its checkpoint and its training log (repository paths)."""

    seed: int
    checkpoint: str
    training_log: str
    parent: str | None = None
    """The run this seed continued from, when it is not trained from scratch (``mvp-improve
    seed 1``): seeds with the same parent are not independent and are counted as one unit in
    the aggregates over seeds."""


@dataclass(frozen=True)
class Submission:
    """One leaderboard entry, as validated from its YAML file."""

    name: str
    """File stem: the entry's id, the stem of its result files."""
    source: Path
    """The YAML file."""
    display_name: str
    description: str
    agent: str
    """Agent file or folder, relative to the repository root."""
    checkpoint: str | None
    """Checkpoint passed to the agent through ``CDR_BENCH_CHECKPOINT`` (relative path)."""
    authors: tuple[str, ...]
    reference: str
    """Paper or code: an http(s) URL or a path in the repository."""
    training: str | None
    """The command that trained the checkpoint; ``None`` for scripted agents."""
    scenarios: tuple[str, ...]
    """Scenario registry names, in run order."""
    suite: str | None
    """The named suite when ``scenarios`` was given as one (``paper``)."""
    published_as: tuple[str, ...]
    """Rows of the paper's Table 2 (agent) or Table 3 (variant) this entry reproduces (one
    entry may stand for two: the reference-budget Diffusion-AC is both Table 2's
    "Diffusion-AC" and Table 3's "Diffusion-AC (Complete)"); empty for none."""
    multimodality: tuple[str, ...]
    """Scenarios for ``cdr-bench multimodal`` (first-action distributions)."""
    group: str = "scripted"
    trained_on: str | None = None
    """Free text: the scenario(s) the checkpoint was trained on (``medium``, ``the DPSC
    curriculum``, ...), shown in the ranking beside the training budget; ``None``: not said
    (a scripted entry trains on nothing)."""
    """One of :data:`GROUPS`: ``scripted`` (no training), ``learned`` (learns from scratch),
    ``hybrid`` (a scripted resolver with a learned part, e.g. MVP with a learned override) or
    ``ablation``."""
    training_logs: tuple[str, ...] = ()
    """JSON-lines training logs (repository paths), one per seed; each ends in a ``final``
    line whose ``step`` is the transitions trained."""
    budget: tuple[int, int] | None = None
    """Declared ``(transitions, seeds)`` of an entry whose logs are not in the repository."""
    replays: tuple[str, ...] = ()
    """Scenarios whose first episodes are recorded as trajectories and replayed on the page."""
    seeds: tuple[Seed, ...] = ()
    """Every training seed (empty: one seed, ``checkpoint``); one has ``checkpoint``."""
    track: str = "single-agent"
    """One of :data:`TRACKS`: ``single-agent`` (the ownship) or ``multi-agent`` (every
    controlled aircraft of scenarios whose traffic is controlled)."""

    @property
    def headline_scenario(self) -> str:
        """The scenario that ranks this entry's track (:data:`TRACK_HEADLINE`)."""
        return TRACK_HEADLINE[self.track]

    @property
    def seed(self) -> int | None:
        """The seed of ``checkpoint`` (``None`` without ``seeds``)."""
        return next((s.seed for s in self.seeds if s.checkpoint == self.checkpoint), None)

    def seed_views(self) -> list[Submission]:
        """The other seeds, each as a submission scored like this one (same agent, scenarios and
        episodes) under the name ``<name>.seed-<k>``, without per-episode extras."""
        return [
            replace(
                self,
                name=seed_result_name(self.name, s.seed),
                checkpoint=s.checkpoint,
                training_logs=(s.training_log,),
                multimodality=(),
                replays=(),
                published_as=(),
                budget=None,
                seeds=(),
            )
            for s in self.seeds
            if s.checkpoint != self.checkpoint
        ]


def seed_result_name(name: str, seed: int) -> str:
    """The result stem of an entry's seed other than its ``checkpoint``."""
    return f"{name}.seed-{seed}"


def _str(src: Path, field: str, v: Any, *, allow_none: bool = False) -> str | None:
    if v is None and allow_none:
        return None
    if not isinstance(v, str) or not v.strip():
        what = "a non-empty string" + (" or null" if allow_none else "")
        raise SubmissionError(src, field, f"expected {what}, got {v!r}")
    return v.strip()


def _str_list(src: Path, field: str, v: Any, *, allow_empty: bool) -> tuple[str, ...]:
    if not isinstance(v, list) or (not v and not allow_empty):
        what = "a list of strings" if allow_empty else "a non-empty list of strings"
        raise SubmissionError(src, field, f"expected {what}, got {v!r}")
    out = []
    for i, x in enumerate(v):
        if not isinstance(x, str) or not x.strip():
            raise SubmissionError(src, f"{field}[{i}]", f"expected a non-empty string, got {x!r}")
        out.append(x.strip())
    return tuple(out)


def _repo_path(src: Path, field: str, value: str, root: Path) -> Path:
    if len(value) > tx.REFERENCE_MAX or not value.isprintable() or "`" in value:
        raise SubmissionError(
            src,
            field,
            f"expected a path of at most {tx.REFERENCE_MAX} printable characters without "
            f"backticks, got {short_repr(value)}",
        )
    p = Path(value)
    if p.is_absolute() or ".." in p.parts:
        raise SubmissionError(
            src, field, f"expected a path relative to the repository root {root}, got {value!r}"
        )
    full = root / p
    if not full.exists():
        raise SubmissionError(src, field, f"{value} does not exist (relative to {root})")
    real = full.resolve()
    if not real.is_relative_to(root.resolve()):
        raise SubmissionError(
            src, field, f"{value} resolves to {real} (a symbolic link?), outside the repository"
        )
    return full


def _scenarios(src: Path, field: str, v: Any) -> tuple[tuple[str, ...], str | None]:
    from cdr_bench.evaluate.api import SUITES
    from cdr_bench.scenarios import list_scenarios

    if isinstance(v, str):
        if v not in SUITES:
            raise SubmissionError(
                src,
                field,
                f"expected a suite ({', '.join(SUITES)}) or a list of scenario names, got {v!r}",
            )
        return SUITES[v], v
    names = _str_list(src, field, v, allow_empty=False)
    known = set(list_scenarios())
    for i, n in enumerate(names):
        if n not in known:
            raise SubmissionError(
                src, f"{field}[{i}]", f"unknown scenario {n!r} (`cdr-bench scenarios list`)"
            )
    if len(set(names)) != len(names):
        raise SubmissionError(src, field, f"a scenario is listed twice: {list(names)}")
    return names, None


FIELDS: dict[str, tuple[bool, str]] = {
    "display_name": (False, "name shown in the tables (default: the file name)"),
    "description": (False, "one line: what the agent is"),
    "trained_on": (False, "one line: the scenario(s) the checkpoint was trained on"),
    "agent": (True, "agent .py file or folder holding agent.py, relative to the repository root"),
    "checkpoint": (
        False,
        "checkpoint file (.pt, .pth, .safetensors, .npz) given to the agent through "
        "CDR_BENCH_CHECKPOINT, or null",
    ),
    "authors": (True, "list of authors"),
    "reference": (True, "paper or code: an http(s) URL or a path in the repository"),
    "training": (True, "the command that trained the checkpoint; null for a scripted agent"),
    "scenarios": (
        True,
        "'paper' (the paper suite), 'marl' (the multi-agent suite) or a list of scenario registry "
        "names",
    ),
    "track": (
        False,
        "single-agent (default: the agent flies the ownship) or multi-agent (it flies every "
        "controlled aircraft; scenarios whose traffic is controlled, e.g. the 'marl' suite)",
    ),
    "published_as": (
        False,
        "row of the paper's Table 2 (agent) or Table 3 (variant) shown beside this entry, or a "
        "list of such rows",
    ),
    "multimodality": (
        False,
        "scenarios on which `cdr-bench multimodal` maps the first-action distribution",
    ),
    "group": (
        False,
        f"one of {', '.join(GROUPS)} (default: scripted without training, learned with it)",
    ),
    "training_logs": (
        False,
        "training logs (.jsonl or .jsonl.xz, one per seed, each ending in a 'final' line): the "
        "budget and seed columns and the learning curves come from them",
    ),
    "budget": (
        False,
        "{transitions: N, seeds: K}: declared budget of an entry whose training logs are not "
        "in the repository (with training_logs: must agree with them)",
    ),
    "replays": (
        False,
        "scenarios whose first episodes are recorded and replayed side by side on index.html",
    ),
    "seeds": (
        False,
        "every training seed: a list of {seed: K, checkpoint: FILE, training_log: "
        "FILE.jsonl[.xz]} with an optional `parent: RUN` (the run a seed continued from; seeds "
        "with the same parent count as one in the aggregates over seeds); `checkpoint` is one "
        "of them (the seed the per-episode views show), `training_logs` is then not given",
    ),
}
"""Every key of a submission file: ``name -> (required, meaning)``."""


def load_submission(
    path: str | os.PathLike[str],
    root: str | os.PathLike[str],
    published_names: Callable[[], set[str]] | None = None,
) -> Submission:
    """Read and validate one submission file. ``root`` is the repository root; paths in the
    file are relative to it. ``published_names`` returns the valid ``published_as`` values."""
    src = Path(path)
    root = Path(root)
    name = src.stem
    if src.suffix != ".yaml":
        raise SubmissionError(src, "", "expected a .yaml file")
    if not NAME_RE.match(name):
        raise SubmissionError(
            src, "", "file name must be lower-case letters, digits and dashes (it is the entry id)"
        )
    data = _read_yaml(src)
    if not isinstance(data, dict):
        raise SubmissionError(src, "", f"expected a mapping of fields, got {type(data).__name__}")
    problems = [
        (_key_label(key), f"unknown field (known: {', '.join(FIELDS)})")
        for key in data
        if key not in FIELDS
    ]
    problems += [
        (key, "missing required field")
        for key, (required, _) in FIELDS.items()
        if required and key not in data
    ]
    problems += _text_problems(data)
    if problems:
        raise SubmissionError.of(src, problems)

    agent = _str(src, "agent", data["agent"])
    assert agent is not None
    agent_full = _repo_path(src, "agent", agent, root)
    if agent_full.is_dir() and not (agent_full / "agent.py").is_file():
        raise SubmissionError(src, "agent", f"folder {agent} has no agent.py")
    if agent_full.is_file() and agent_full.suffix != ".py":
        raise SubmissionError(src, "agent", f"expected a .py file or a folder, got {agent}")

    checkpoint = _str(src, "checkpoint", data.get("checkpoint"), allow_none=True)
    if checkpoint is not None:
        ck = _repo_path(src, "checkpoint", checkpoint, root)
        if not ck.is_file() or ck.suffix not in CHECKPOINT_SUFFIXES:
            raise SubmissionError(
                src,
                "checkpoint",
                f"expected a file ending in {', '.join(CHECKPOINT_SUFFIXES)} (formats that load "
                f"without unpickling), got {checkpoint}",
            )

    reference = _str(src, "reference", data["reference"])
    assert reference is not None
    if reference.startswith(("https://", "http://")):
        _url(src, "reference", reference)
    else:
        _repo_path(src, "reference", reference, root)

    training = _str(src, "training", data["training"], allow_none=True)
    if checkpoint is not None and training is None:
        raise SubmissionError(
            src, "training", "a submission with a checkpoint must give the command that trained it"
        )

    scenarios, suite = _scenarios(src, "scenarios", data["scenarios"])
    multimodality = _str_list(src, "multimodality", data.get("multimodality", []), allow_empty=True)
    for i, s in enumerate(multimodality):
        if s not in scenarios:
            raise SubmissionError(
                src, f"multimodality[{i}]", f"{s!r} is not one of this entry's scenarios"
            )

    raw = data.get("published_as")
    if isinstance(raw, list):
        published_as = _str_list(src, "published_as", raw, allow_empty=False)
        dup = sorted({x for x in published_as if published_as.count(x) > 1})
        if dup:
            raise SubmissionError(src, "published_as", f"row {dup[0]!r} named twice")
        fields = [f"published_as[{i}]" for i in range(len(published_as))]
    else:
        one = _str(src, "published_as", raw, allow_none=True)
        published_as, fields = ((), []) if one is None else ((one,), ["published_as"])
    if published_names is not None and published_as:
        valid = published_names()
        for field, row in zip(fields, published_as, strict=True):
            if row not in valid:
                raise SubmissionError(
                    src,
                    field,
                    f"unknown row {row!r} (Table 2/3 rows: {', '.join(sorted(valid))})",
                )

    group = _str(src, "group", data.get("group", "scripted" if training is None else "learned"))
    if group not in GROUPS:
        raise SubmissionError(src, "group", f"expected one of {', '.join(GROUPS)}, got {group!r}")
    if group == "scripted" and training is not None:
        raise SubmissionError(src, "group", "a scripted entry has no training command")
    if group != "scripted" and training is None:
        raise SubmissionError(src, "training", f"a {group} entry gives its training command")

    logs = _str_list(src, "training_logs", data.get("training_logs", []), allow_empty=True)
    for i, log in enumerate(logs):
        full = _repo_path(src, f"training_logs[{i}]", log, root)
        if not full.is_file() or not full.name.endswith(TRAINING_LOG_SUFFIXES):
            raise SubmissionError(src, f"training_logs[{i}]", f"expected {_LOG_FILE}, got {log}")
    if len(set(logs)) != len(logs):
        raise SubmissionError(src, "training_logs", f"a log is listed twice: {list(logs)}")
    if logs and training is None:
        raise SubmissionError(src, "training_logs", "a scripted entry has no training logs")
    budget = _budget(src, data.get("budget"))
    if budget is not None and training is None:
        raise SubmissionError(src, "budget", "a scripted entry has no training budget")

    replays = _str_list(src, "replays", data.get("replays", []), allow_empty=True)
    for i, sc in enumerate(replays):
        if sc not in scenarios:
            raise SubmissionError(
                src, f"replays[{i}]", f"{sc!r} is not one of this entry's scenarios"
            )
    if len(set(replays)) != len(replays):
        raise SubmissionError(src, "replays", f"a scenario is listed twice: {list(replays)}")

    track = _str(src, "track", data.get("track", "single-agent"))
    if track not in TRACKS:
        raise SubmissionError(src, "track", f"expected one of {', '.join(TRACKS)}, got {track!r}")
    _track_scenarios(src, track, scenarios)

    seeds = _seeds(src, data.get("seeds"), root)
    if seeds:
        if training is None:
            raise SubmissionError(src, "seeds", "a scripted entry has no training seeds")
        if "training_logs" in data:
            raise SubmissionError(
                src, "training_logs", "not given with seeds (each seed names its training_log)"
            )
        if checkpoint not in {s.checkpoint for s in seeds}:
            raise SubmissionError(
                src,
                "checkpoint",
                f"expected one of the seeds' checkpoints "
                f"({', '.join(s.checkpoint for s in seeds)}), got {checkpoint}",
            )
        logs = tuple(s.training_log for s in seeds)
        if budget is not None and budget[1] != len(seeds):
            raise SubmissionError(
                src, "budget", f"declares {budget[1]} seed(s), seeds lists {len(seeds)}"
            )

    return Submission(
        name=name,
        source=src,
        display_name=_str(src, "display_name", data.get("display_name", name)) or name,
        description=_str(src, "description", data.get("description", "-")) or "-",
        trained_on=_str(src, "trained_on", data.get("trained_on"), allow_none=True) or None,
        agent=agent,
        checkpoint=checkpoint,
        authors=_str_list(src, "authors", data["authors"], allow_empty=False),
        reference=reference,
        training=training,
        scenarios=scenarios,
        suite=suite,
        published_as=published_as,
        multimodality=multimodality,
        group=group,
        training_logs=logs,
        budget=budget,
        replays=replays,
        seeds=seeds,
        track=track,
    )


def _track_scenarios(src: Path, track: str, scenarios: tuple[str, ...]) -> None:
    """A multi-agent entry is scored on scenarios with several controlled aircraft, its track's
    headline scenario among them; a single-agent entry on scenarios with the ownship alone (the
    ranking requires its headline scenario: :func:`.data.rank_entries`)."""
    from cdr_bench.scenarios import load_scenario

    headline = TRACK_HEADLINE[track]
    for i, name in enumerate(scenarios):
        c = load_scenario(name)
        controlled = c.n_controlled
        if track == "multi-agent" and controlled < 2:
            raise SubmissionError(
                src,
                f"scenarios[{i}]",
                f"{name!r} has one controlled aircraft; a multi-agent entry is scored where the "
                "traffic is controlled (the 'marl' suite)",
            )
        if track == "single-agent" and controlled > 1:
            raise SubmissionError(
                src,
                f"scenarios[{i}]",
                f"{name!r} has {controlled} controlled aircraft; declare `track: multi-agent`",
            )
    if track == "multi-agent" and headline not in scenarios:
        raise SubmissionError(
            src, "scenarios", f"the {track} track ranks on {headline!r}: it must be scored there"
        )


TEXT_FIELDS: dict[str, int] = {
    "display_name": tx.NAME_MAX,
    "description": tx.DESCRIPTION_MAX,
    "trained_on": tx.DESCRIPTION_MAX,
    "reference": tx.REFERENCE_MAX,
    "training": tx.TRAINING_MAX,
}
"""Free-text fields and their length caps (``authors``: :data:`~.text.AUTHOR_MAX` each)."""


def _text_problems(data: dict[str, Any]) -> list[tuple[str, str]]:
    """The first problem of each free-text field given as a string (other types are reported
    by the field's own check): see :func:`cdr_bench.leaderboard.text.text_problems`."""
    values: list[tuple[str, Any, int]] = [(k, data.get(k), n) for k, n in TEXT_FIELDS.items()]
    authors = data.get("authors")
    out: list[tuple[str, str]] = []
    if isinstance(authors, list):
        if len(authors) > tx.AUTHORS_MAX:
            out.append(
                ("authors", f"expected at most {tx.AUTHORS_MAX} authors, got {len(authors)}")
            )
        values += [
            (f"authors[{i}]", a, tx.AUTHOR_MAX) for i, a in enumerate(authors[: tx.AUTHORS_MAX])
        ]
    for field, v, limit in values:
        if isinstance(v, str):
            name = field == "display_name"
            out += [(field, m) for m in tx.text_problems(v.strip(), limit=limit, name=name)[:1]]
    training = data.get("training")
    if isinstance(training, str) and "`" in training:
        out.append(("training", "a backtick is not allowed (the command is shown as code)"))
    return out


def _key_label(key: Any) -> str:
    """A key as named in a message: itself when short and printable, else quoted and cut."""
    ok = isinstance(key, str) and key.isprintable() and len(key) <= 40
    return str(key) if ok else short_repr(key, 40)


def _url(src: Path, field: str, value: str) -> None:
    """An http(s) URL: a host, no spaces or quotes."""
    try:
        parts = urlsplit(value)
        ok = parts.scheme in ("http", "https") and bool(parts.hostname)
    except ValueError:
        ok = False
    if not ok or any(c.isspace() or c in "\"'<>`" for c in value):
        raise SubmissionError(
            src, field, f"expected an http(s) URL with a host, got {short_repr(value)}"
        )


def _seeds(src: Path, v: Any, root: Path) -> tuple[Seed, ...]:
    if v is None:
        return ()
    if not isinstance(v, list) or len(v) < 2:
        raise SubmissionError(
            src,
            "seeds",
            f"expected a list of two or more {{seed, checkpoint, training_log}}, got {v!r}",
        )
    out: list[Seed] = []
    for i, item in enumerate(v):
        f = f"seeds[{i}]"
        if not isinstance(item, dict) or not (
            {"seed", "checkpoint", "training_log"}
            <= set(item)
            <= {"seed", "checkpoint", "training_log", "parent"}
        ):
            raise SubmissionError(
                src,
                f,
                "expected {seed: K, checkpoint: FILE, training_log: FILE.jsonl[.xz]} "
                f"(and optionally parent: RUN), got {item!r}",
            )
        k = item["seed"]
        if not isinstance(k, int) or isinstance(k, bool) or k < 0:
            raise SubmissionError(src, f"{f}.seed", f"expected a non-negative integer, got {k!r}")
        ck = _str(src, f"{f}.checkpoint", item["checkpoint"])
        log = _str(src, f"{f}.training_log", item["training_log"])
        assert ck is not None and log is not None
        full = _repo_path(src, f"{f}.checkpoint", ck, root)
        if not full.is_file() or full.suffix not in CHECKPOINT_SUFFIXES:
            raise SubmissionError(
                src,
                f"{f}.checkpoint",
                f"expected a file ending in {', '.join(CHECKPOINT_SUFFIXES)}, got {ck}",
            )
        full = _repo_path(src, f"{f}.training_log", log, root)
        if not full.is_file() or not full.name.endswith(TRAINING_LOG_SUFFIXES):
            raise SubmissionError(src, f"{f}.training_log", f"expected {_LOG_FILE}, got {log}")
        parent = _str(src, f"{f}.parent", item.get("parent"), allow_none=True)
        out.append(Seed(k, ck, log, parent))
    for key in ("seed", "checkpoint", "training_log"):
        vals = [getattr(s, key) for s in out]
        if len(set(vals)) != len(vals):
            raise SubmissionError(src, "seeds", f"a {key} is listed twice: {vals}")
    return tuple(out)


def _budget(src: Path, v: Any) -> tuple[int, int] | None:
    if v is None:
        return None
    if not isinstance(v, dict) or set(v) != {"transitions", "seeds"}:
        raise SubmissionError(src, "budget", f"expected {{transitions: N, seeds: K}}, got {v!r}")
    for k in ("transitions", "seeds"):
        x = v[k]
        if not isinstance(x, int) or isinstance(x, bool) or x < 1:
            raise SubmissionError(src, f"budget.{k}", f"expected a positive integer, got {x!r}")
    return (v["transitions"], v["seeds"])


def load_submissions(
    leaderboard_dir: str | os.PathLike[str],
    published_names: Callable[[], set[str]] | None = None,
) -> list[Submission]:
    """Every ``submissions/*.yaml`` of a leaderboard folder, sorted by name."""
    d = Path(leaderboard_dir)
    sub = d / "submissions"
    files = sorted(sub.glob("*.yaml")) if sub.is_dir() else []
    if not files:
        raise UserError(f"{sub}: no submission files (*.yaml)")
    others = sorted(p.name for p in sub.iterdir() if p.suffix in (".yml", ".json"))
    if others:
        raise UserError(f"{sub}: submissions are .yaml files; rename {', '.join(others)}")
    subs, errors = [], []
    for f in files:
        try:
            subs.append(load_submission(f, d.resolve().parent, published_names))
        except SubmissionError as e:
            errors.append(str(e))
    seen: dict[str, Submission] = {}
    for s in subs:
        key = tx.skeleton(s.display_name)
        if key in seen:
            other = seen[key]
            same = "the same as" if other.display_name == s.display_name else "looks like"
            errors.append(
                f"{s.source}: display_name: {short_repr(s.display_name)} {same} "
                f"{short_repr(other.display_name)} of {other.source}; display names must differ "
                "after Unicode normalisation, case folding and confusable letters"
            )
        else:
            seen[key] = s
    if errors:
        raise UserError("\n".join(errors))
    claimed: dict[str, Submission] = {}
    for s in subs:
        for row in s.published_as:
            if row in claimed:
                raise UserError(
                    f"{s.source}: published_as: the paper's row {row!r} is already reproduced "
                    f"by {claimed[row].source}; a row is shown beside one entry"
                )
            claimed[row] = s
    return subs
