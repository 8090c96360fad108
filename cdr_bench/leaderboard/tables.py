"""The results tables of the documentation: which marked block of which file shows what
(:data:`DOC_BLOCKS`), read from the committed files and rendered here (:func:`measured_table`,
:func:`multimodality_table`, ...) with the number formats and Markdown layout of
:mod:`cdr_bench.evaluate.report`; the headline and claims blocks are the leaderboard's own
tables (:mod:`cdr_bench.leaderboard.page_tables`).

A block is the text between ``<!-- name:start -->`` and ``<!-- name:end -->``. Its inputs are
the leaderboard's result files (``leaderboard/results/<entry>.json`` and
``<entry>.multimodal-<scenario>.json``, the one committed copy of each evaluation), its
submissions (display names, the paper row each entry reproduces, the agent folder), the
paper's published tables (``leaderboard/published/``) and, for what is not an evaluation, the
training, tuning and ``cdr-bench latency`` logs in the agent folders. Nothing is evaluated and
no result file is written: :func:`render_docs` rewrites the blocks of the documentation files
only. ``cdr-bench leaderboard build`` and ``cdr-bench leaderboard render-docs`` call it;
``render-docs --check`` and ``tests/leaderboard/test_rendered_blocks.py`` fail when a block
differs from what the files give.

Training logs are read as JSON lines: the leaderboard never imports the trainers
(``cdr_bench.rl``), and they never import it. The training logs of the entries are kept
xz-compressed (``.jsonl.xz``), the logs of runs that are not leaderboard entries (tuning, the
short design runs) and the per-episode file of an analysis run gzip-compressed (``.jsonl.gz``);
every form is read (:mod:`cdr_bench.jsonl`).
"""

from __future__ import annotations

import difflib
import json
import os
import re
import shutil
import tempfile
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any

from cdr_bench.actions import decode
from cdr_bench.errors import UserError
from cdr_bench.evaluate.metrics import SYSTEM_METRICS
from cdr_bench.evaluate.report import Cell, Rows, fmt_metric, fmt_ms, fmt_value, md_table
from cdr_bench.evaluate.results import atomic_write_text, read_result
from cdr_bench.jsonl import GZ, existing, gunzip_file
from cdr_bench.jsonl import read_jsonl as _read_jsonl_any
from cdr_bench.leaderboard.page_tables import (
    DENSITIES,
    MAIN_COLUMNS,
    claims_table,
    fmt_published,
    ranking_table,
)
from cdr_bench.leaderboard.published import METRIC_OF_COLUMN, Published, load_published
from cdr_bench.leaderboard.submission import Submission, load_submissions
from cdr_bench.leaderboard.text import md_text


def result_path(results_dir: Path, name: str) -> Path:
    return results_dir / f"{name}.json"


def multimodal_path(results_dir: Path, name: str, scenario: str) -> Path:
    return results_dir / f"{name}.multimodal-{scenario.replace('/', '_')}.json"


def multimodal_seed_path(results_dir: Path, name: str, seed: int, scenario: str) -> Path:
    """``cdr-bench multimodal`` of training seed ``seed`` of entry ``name`` (its JSON, compact and
    xz-compressed; written by ``sweeps/multimodal_seeds.sh``, read for the multimodality claim)."""
    return results_dir / f"{name}.seed-{seed}.multimodal-{scenario.replace('/', '_')}.json.xz"


def replays_path(results_dir: Path, name: str) -> Path:
    """Recorded trajectories of the entry's ``replays`` scenarios (written by the scorer)."""
    return results_dir / f"{name}.replays.json"


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as e:
        raise UserError(f"{path}: cannot read ({e})") from None


def _read_jsonl(path: Path) -> list[dict[str, Any]]:
    """A JSON-lines file, plain, gzip or xz (``X.jsonl``, ``X.jsonl.gz``, ``X.jsonl.xz``, any
    name)."""
    try:
        return _read_jsonl_any(path)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise UserError(f"{path}: cannot read ({e})") from None


def _read_result_gz(path: Path) -> dict[str, Any]:
    """:func:`read_result` of a result JSON whose per-episode file is kept compressed beside it
    (``<episodes_file>.gz``): checked, as always, against the decompressed file (in a
    temporary folder). A plain per-episode file is read as it is."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        name = data["episodes_file"]
        packed = path.parent / f"{name}{GZ}"
        compressed = not (path.parent / name).exists() and packed.is_file()
    except (OSError, UnicodeDecodeError, ValueError, TypeError, KeyError):
        compressed = False  # read_result names what is wrong
    if not compressed:
        return read_result(path)
    tmp = Path(tempfile.mkdtemp(prefix="cdr-bench-result-"))
    try:
        shutil.copyfile(path, tmp / path.name)
        gunzip_file(packed, tmp / name)
        try:
            return read_result(tmp / path.name)
        except ValueError as e:
            raise ValueError(str(e).replace(str(tmp), str(path.parent))) from None
    except OSError as e:
        raise ValueError(f"{packed}: cannot read ({e})") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _final(log: Path) -> dict[str, Any]:
    finals = [r["final"] for r in _read_jsonl(log) if "final" in r]
    if not finals:
        raise UserError(f"{log}: no final line (an unfinished training log?)")
    last: dict[str, Any] = finals[-1]
    return last


class Repo:
    """A repository's leaderboard folder and agent folders, each file read at most once."""

    def __init__(self, leaderboard_dir: str | os.PathLike[str]):
        self.lb_dir = Path(leaderboard_dir)
        self.root = self.lb_dir.resolve().parent
        self.results_dir = self.lb_dir / "results"
        self._results: dict[tuple[str, bool], dict[str, Any]] = {}
        self._analysis: dict[tuple[str, str, tuple[str, ...]], Any] = {}

    @cached_property
    def published(self) -> Published:
        return load_published(self.lb_dir)

    @cached_property
    def submissions(self) -> dict[str, Submission]:
        return {s.name: s for s in load_submissions(self.lb_dir, self.published.names)}

    def submission(self, name: str) -> Submission:
        if name not in self.submissions:
            raise UserError(f"{self.lb_dir}/submissions/{name}.yaml: no such leaderboard entry")
        return self.submissions[name]

    def label(self, name: str) -> str:
        """The entry's display name as Markdown text (the blocks are Markdown tables)."""
        return md_text(self.submission(name).display_name)

    def result(self, name: str, roles: bool = True) -> dict[str, Any]:
        """The entry's result with its metrics; ``roles=False``: the system metrics only
        (:func:`~cdr_bench.evaluate.results.read_result`)."""
        if (name, roles) not in self._results:
            self.submission(name)
            self._results[name, roles] = self._read(name, name, roles)
        return self._results[name, roles]

    def _read(self, entry: str, run: str, roles: bool) -> dict[str, Any]:
        try:
            return read_result(result_path(self.results_dir, run), roles=roles)
        except ValueError as e:
            raise UserError(f"{e}; run `cdr-bench leaderboard build --evaluate {entry}`") from None

    def seed_results(
        self, name: str, roles: bool = True
    ) -> list[tuple[int | None, dict[str, Any]]]:
        """``(seed, result)`` of every training seed of an entry, its ``checkpoint`` first
        (``results/<name>.json``), then the others (``results/<name>.seed-<k>.json``); one
        ``(None, result)`` for an entry without seeds. ``roles`` as :meth:`result`."""
        sub = self.submission(name)
        runs: list[tuple[int | None, dict[str, Any]]] = [(sub.seed, self.result(name, roles))]
        for view in sub.seed_views():
            runs.append((int(view.name.rsplit("-", 1)[1]), self._read(name, view.name, roles)))
        return runs

    def paper_rows(self, name: str) -> list[PaperRow]:
        """The paper's rows the entry reproduces (its ``published_as``), one per density."""
        rows = self.submission(name).published_as
        return [
            PaperRow(
                label=f"{r.row} — paper {r.table} (published)",
                scenario=r.density,
                episodes=r.episodes,
                values={METRIC_OF_COLUMN[k]: v for k, v in r.values.items()},
            )
            for r in self.published.rows
            if r.row in rows
        ]

    def multimodal(self, name: str) -> list[tuple[str, dict[str, Any]]]:
        """The entry's ``cdr-bench multimodal`` results, in its submission's order."""
        return [
            (self.label(name), _read_json(multimodal_path(self.results_dir, name, sc)))
            for sc in self.submission(name).multimodality
        ]

    def agent_dir(self, name: str) -> Path:
        p = self.root / self.submission(name).agent
        return p if p.is_dir() else p.parent

    def analysis(
        self, folder: str, label: str, multimodal: Sequence[str]
    ) -> tuple[dict[str, Any], list[tuple[str, dict[str, Any]]]]:
        """An agent's analysis run outside the leaderboard: ``<folder>/result.json`` (written
        by ``cdr-bench evaluate --out``; its per-episode file plain or as ``.jsonl.gz``) and,
        per scenario of ``multimodal``,
        ``<folder>/multimodal-<scenario>.json`` (``cdr-bench multimodal --out``); returns
        ``(result, [(label, multimodality JSON), ...])``."""
        key = (folder, label, tuple(multimodal))
        if key not in self._analysis:
            d = self.root / folder
            try:
                res = _read_result_gz(d / "result.json")
            except ValueError as e:
                raise UserError(str(e)) from None
            mm = [
                (label, _read_json(d / f"multimodal-{sc.replace('/', '_')}.json"))
                for sc in multimodal
            ]
            self._analysis[key] = (res, mm)
        return self._analysis[key]

    def latency(self, name: str) -> dict[str, Any]:
        """``<agent folder>/analysis/latency.json`` (written by ``cdr-bench latency``)."""
        data: dict[str, Any] = _read_json(self.agent_dir(name) / "analysis" / "latency.json")
        return data


# ----------------------------------------------------------------------------------------------
# The tables of the documentation (pure functions of what :class:`Repo` reads)


@dataclass(frozen=True)
class PaperRow:
    """A row of the paper's tables, shown beside a measured row of the same scenario."""

    label: str
    scenario: str
    episodes: int | None
    values: Mapping[str, float]
    """Metric key (as in :data:`COLUMNS`) -> value as published (rates in %)."""


def measured_table(
    entries: Iterable[tuple[str, dict[str, Any], Sequence[PaperRow]]],
    scenarios: Sequence[str] | None = None,
    ci: bool = True,
) -> str:
    """Ownship metrics of results (``(label, result, paper rows)``), one row per result and
    scenario (``scenarios``: these only, in the result's order), each followed by the paper's
    rows of the same scenario, marked *published*."""
    head = ["agent", "scenario", "episodes", *[c.header for c in MAIN_COLUMNS]]
    rows: Rows = []
    for label, res, paper in entries:
        for sc in res["scenarios"]:
            if scenarios is not None and sc["id"] not in scenarios:
                continue
            m = sc["metrics"]["ownship"]
            rows.append(
                [Cell(label), Cell(sc["id"]), Cell(str(m["episodes"]))]
                + [Cell(fmt_metric(c.kind, m[c.key], ci)) for c in MAIN_COLUMNS]
            )
            for p in paper:
                if p.scenario == sc["id"]:
                    rows.append(
                        [
                            Cell(p.label),
                            Cell(p.scenario),
                            Cell("-" if p.episodes is None else str(p.episodes)),
                        ]
                        + [Cell(fmt_published(c.kind, p.values.get(c.key))) for c in MAIN_COLUMNS]
                    )
    return md_table(head, rows, numeric_from=2)


def system_table(
    entries: Iterable[tuple[str, dict[str, Any]]], scenarios: Sequence[str] | None = None
) -> str:
    """System metrics (every controlled aircraft, docs/model.md §10.1.3) of results
    (``(label, result)``), one row per result and scenario that has them, with 95 % intervals."""
    head = ["agent", "scenario", "episodes", "flights", *[c.header for c in SYSTEM_METRICS]]
    rows: Rows = []
    for label, res in entries:
        for sc in res["scenarios"]:
            m = sc.get("system_metrics")
            if not m or (scenarios is not None and sc["id"] not in scenarios):
                continue
            rows.append(
                [Cell(label), Cell(sc["id"]), Cell(str(m["episodes"])), Cell(str(m["flights"]))]
                + [Cell(fmt_metric(c.kind, m[c.key])) for c in SYSTEM_METRICS]
            )
    return md_table(head, rows, numeric_from=2)


_PSI = {-1: "left", 0: "hold", 1: "right"}
_V = {-1: "slower", 0: "keep", 1: "faster"}
_H = {-1: "descend", 0: "level", 1: "climb"}


def action_label(a: int) -> str:
    p, v, h = decode(a)
    return f"{a} {_PSI[p]}/{_V[v]}/{_H[h]}"


def multimodality_table(runs: Iterable[tuple[str, dict[str, Any]]]) -> str:
    """``cdr-bench multimodal`` results (``(label, its JSON)``): first-action samples, and the
    mean number of manoeuvre families (left, right, climb, descend, speed) per episode that the
    successful samples reach, beside the mean the search finds (docs/model.md §10.4)."""
    head = [
        "agent",
        "scenario",
        "episodes x samples",
        "families per episode",
        "found by search",
        "follow-on success",
        "modes (successful)",
        "normalised entropy",
        "distinct first actions",
        "most sampled first actions (share of all samples)",
    ]
    rows: Rows = []
    for label, d in runs:
        counts = d["all"]
        top = sorted(range(len(counts)), key=lambda a: (-counts[a], a))[:3]
        total = sum(counts) or 1
        tops = ", ".join(
            f"{action_label(a)} ({100 * counts[a] / total:.0f} %)" for a in top if counts[a]
        )
        fam, found = d.get("families_mean"), d.get("feasible_families_mean")
        thr = d.get("threshold")
        ent = d.get("normalised_entropy")
        rows.append(
            [
                Cell(label),
                Cell(d["scenario"]),
                Cell(f"{d.get('episodes', 1)} x {d['samples']}"),
                Cell("-" if fam is None else f"{fam:.2f}"),
                Cell("-" if found is None else f"{found:.2f}"),
                Cell(fmt_value("rate", d["success_rate"])),
                Cell(f"{d['modes']}" + ("" if thr is None else f" (≥ {100 * thr:g} %)")),
                Cell("-" if ent is None else f"{ent:.3f}"),
                Cell(str(sum(1 for c in counts if c))),
                Cell(tops or "-"),
            ]
        )
    return md_table(head, rows, numeric_from=2, text_from=len(head) - 1)


def latency_table(runs: Iterable[tuple[str, dict[str, Any]]]) -> str:
    """``cdr-bench latency`` results (``(label, its JSON)``): one decision per call, and per
    decision at the largest batch measured."""
    head = [
        "agent",
        "threads",
        "median ms / decision (batch 1)",
        "p99 ms (batch 1)",
        "largest batch",
        "median ms / decision (largest batch)",
    ]
    rows: Rows = []
    for label, d in runs:
        by_batch = {r["batch"]: r for r in d["rows"]}
        one = by_batch.get(1)
        big = by_batch[max(by_batch)]
        rows.append(
            [
                Cell(label),
                Cell(str(d.get("threads", "-"))),
                Cell("-" if one is None else fmt_ms(one["median_ms_per_decision"])),
                Cell("-" if one is None else fmt_ms(one["p99_ms"])),
                Cell(str(big["batch"])),
                Cell(fmt_ms(big["median_ms_per_decision"])),
            ]
        )
    return md_table(head, rows, numeric_from=1)


def latency_detail_table(d: dict[str, Any]) -> str:
    """Every batch size of one ``cdr-bench latency`` result."""
    head = ["batch", "calls", "median ms / call", "p99 ms / call", "median ms / decision"]
    rows = [
        [
            Cell(str(r["batch"])),
            Cell(str(r.get("calls", "-"))),
            Cell(f"{r['median_ms']:.3f}"),
            Cell(f"{r['p99_ms']:.3f}"),
            Cell(f"{r['median_ms_per_decision']:.4f}"),
        ]
        for r in d["rows"]
    ]
    note = f"{d.get('threads', '-')} thread(s), scenario `{d.get('scenario', '-')}`."
    return md_table(head, rows, numeric_from=0) + "\n\n" + note


def training_summary(final: dict[str, Any], log: str, stages: int | None = None) -> str:
    """One sentence from the ``final`` line of a Diffusion-AC training log."""
    of = f" of {stages}" if stages else ""
    return (
        f"Training (`{log}`): {final['step']:,} transitions, {final['updates']:,} updates, "
        f"{final['wall_s'] / 60:.0f} min wall, final DPSC stage {final['stage']}{of}."
    )


def quick_eval_table(runs: Iterable[tuple[str, dict[str, Any]]], scenario: str) -> str:
    """The trainers' own quick evaluation (``final`` lines of training logs) on ``scenario``."""
    head = ["run", "transitions", "success", "LoS", "NMAC", "timeout", "episodes"]
    rows: Rows = []
    for label, f in runs:
        e = f[f"eval/{scenario}"]
        rows.append(
            [Cell(label), Cell(f"{f['step']:,}")]
            + [Cell(fmt_value("rate", e[k])) for k in ("success", "los", "nmac", "timeout")]
            + [Cell(str(e["episodes"]))]
        )
    return md_table(head, rows, numeric_from=1)


TUNING_FLAGS = ("ent_coef", "combine", "lr", "n_envs", "curriculum", "scenario", "total_steps")


def tuning_table(runs: Iterable[tuple[str, str, dict[str, Any], list[dict[str, Any]]]]) -> str:
    """Tuning runs (``(agent, run, its arguments, its log lines)``): the trainer's quick
    evaluation per density, or the last rolling training success of a run cut before its
    budget."""
    head = [
        "agent",
        "run",
        "key flags",
        "transitions",
        "DPSC stage",
        "success low / medium / high",
        "LoS low / medium / high",
    ]
    rows: Rows = []
    for agent, run, args, lines in runs:
        finals = [r["final"] for r in lines if "final" in r]
        flags = ", ".join(f"{k}={args[k]}" for k in TUNING_FLAGS if k in args)
        if finals:
            f = finals[-1]
            ev = [f[f"eval/{d}"] for d in DENSITIES]
            cells = [
                f"{f['step']:,}",
                str(f["stage"]),
                " / ".join(f"{e['success']:.2f}" for e in ev),
                " / ".join(f"{e['los']:.2f}" for e in ev),
            ]
        else:
            last = lines[-1]
            cells = [
                f"{last['step']:,} (cut)",
                str(last.get("curriculum/stage", "-")),
                f"rolling training success {last.get('charts/success_rolling', 0):.2f}",
                "-",
            ]
        rows.append([Cell(agent), Cell(run), Cell(flags)] + [Cell(c) for c in cells])
    return md_table(head, rows, numeric_from=3, text_from=5)


# ----------------------------------------------------------------------------------------------
# What each block shows


def measured(
    repo: Repo, entries: Iterable[str], scenarios: Sequence[str] | None = None, ci: bool = True
) -> str:
    """Entries' result files, each row followed by the paper's row it reproduces."""
    return measured_table(
        [(repo.label(n), repo.result(n), repo.paper_rows(n)) for n in entries], scenarios, ci
    )


def seed_runs(
    repo: Repo, entries: Iterable[str], roles: bool = True
) -> list[tuple[str, dict[str, Any]]]:
    """``(label, result)`` of every training seed of each entry (the leaderboard's per-seed
    result files; an entry without seeds is one run, labelled with its name alone); ``roles``
    as :meth:`Repo.result`."""
    return [
        (repo.label(n) if seed is None else f"{repo.label(n)}, seed {seed}", res)
        for n in entries
        for seed, res in repo.seed_results(n, roles)
    ]


def measured_seeds(
    repo: Repo, entries: Iterable[str], scenarios: Sequence[str] | None = None
) -> str:
    """Every training seed of each entry, one row per seed and scenario."""
    return measured_table([(label, res, []) for label, res in seed_runs(repo, entries)], scenarios)


def system_seeds(repo: Repo, entries: Iterable[str]) -> str:
    """The system metrics of every training seed of each entry, one row per seed and
    scenario (the per-role metrics, which it does not show, are not computed)."""
    return system_table(seed_runs(repo, entries, roles=False))


def multimodality(repo: Repo, entries: Iterable[str]) -> str:
    return multimodality_table([run for n in entries for run in repo.multimodal(n)])


def latency(repo: Repo, entries: Iterable[str]) -> str:
    return latency_table([(repo.label(n), repo.latency(n)) for n in entries])


def training(repo: Repo, name: str, stages: str = "scenarios/curriculum") -> str:
    log = existing(repo.agent_dir(name) / "training_log.jsonl")  # plain or .jsonl.xz
    n_stages = len(list((repo.root / stages).glob("stage-*.yaml")))
    return training_summary(_final(log), log.relative_to(repo.root).as_posix(), n_stages or None)


STAGE_SWEEPS = ("sweeps/landed/dac-stability", "sweeps/landed/dac-clip")
"""Landed Diffusion-AC trials whose training logs the stage table shows beside the shipped
seeds (each folder's trials, labelled from their ``trial.json`` flags)."""


def _flags_label(flags: dict[str, Any]) -> str:
    words = []
    if flags.get("ablation"):
        part = str(flags["ablation"]).removeprefix("no-")
        words.append(
            "no " + {"double-q": "double Q", "dpsc": "DPSC"}.get(part, part.replace("-", " "))
        )
    if flags.get("soft-boundary"):
        words.append("soft boundary")
    if flags.get("q-target-max") is not None:
        words.append(f"TD target ≤ {float(flags['q-target-max']):g}")
    return ", ".join(words) or "reference recipe"


def stage_runs(repo: Repo) -> list[tuple[str, Path]]:
    """The Diffusion-AC training logs of the stage table: ``(label, log)``."""
    d = repo.root / "agents" / "diffusion_ac"
    runs = [("seed 1", existing(d / "training_log.jsonl"))]
    seed_dirs = sorted((d / "seeds").glob("*/"), key=lambda p: int(p.name))
    runs += [(f"seed {p.name}", existing(p / "training_log.jsonl")) for p in seed_dirs]
    runs.append(
        (
            "cdr-bench 0.1 reference run",
            existing(d / "analysis" / "reference-0.1" / "training_log.jsonl"),
        )
    )
    abl = d / "ablations" / "no-double-q"
    runs.append(("no double Q, seed 1", existing(abl / "training_log.jsonl")))
    runs += [
        (f"no double Q, seed {p.name}", existing(p / "training_log.jsonl"))
        for p in sorted((abl / "seeds").glob("*/"), key=lambda p: int(p.name))
    ]
    for sweep in STAGE_SWEEPS:
        trials = []
        for tj in sorted((repo.root / sweep).glob("*/trial.json")):
            t = _read_json(tj)
            label = f"{_flags_label(t['train_flags'])}, seed {t['seed']}"
            trials.append((label, existing(tj.parent / "log.jsonl")))
        runs += sorted(trials)
    return runs


def stage_table(repo: Repo, stage: int = 12) -> str:
    """Each run of :func:`stage_runs` over its lines at ``stage``
    (:func:`cdr_bench.leaderboard.stage_stats.stage_summary`)."""
    from cdr_bench.leaderboard.stage_stats import stage_summary

    def at(x: tuple[float, int] | None, fmt: str = "{:+.2f}") -> str:
        return "-" if x is None else f"{fmt.format(x[0])} at {x[1]:,}"

    head = [
        "run",
        f"stage {stage} from",
        "rolling success min / mean / max",
        "max TD loss",
        "max mean Q",
        "max Q",
        "max TD target",
        "max timeout share",
        "clean success on the fixed set: min / mean / last",
    ]
    rows: Rows = []
    for label, log in stage_runs(repo):
        s = stage_summary(_read_jsonl_any(log), stage)
        rel = log.relative_to(repo.root).as_posix()
        if s is None:
            rows.append(
                [Cell(f"{label} (`{rel}`)"), Cell(f"never reached stage {stage}")] + [Cell("-")] * 7
            )
            continue
        sc, cv = s["success"], s["curve"]
        rows.append(
            [
                Cell(f"{label} (`{rel}`)"),
                Cell(f"{s['from']:,}", s["from"]),
                Cell(f"{sc['min']:.2f} / {sc['mean']:.2f} / {sc['max']:.2f}", sc["min"]),
                Cell(at(s["td_loss"], "{:.2f}")),
                Cell(at(s["q_mean"])),
                Cell(at(s["q_max"])),
                Cell(at(s["target_max"])),
                Cell(at(s["timeout"], "{:.2f}")),
                Cell(
                    "-" if cv is None else f"{cv['min']:.2f} / {cv['mean']:.2f} / {cv['last']:.2f}"
                ),
            ]
        )
    return md_table(head, rows, numeric_from=1)


def quick_evals(repo: Repo, logs: Iterable[tuple[str, str]], scenario: str) -> str:
    """``(label, training log relative to the repository)`` of short runs."""
    return quick_eval_table([(label, _final(repo.root / log)) for label, log in logs], scenario)


def tuning(repo: Repo, pattern: str = "agents/*/tuning/*.log.jsonl") -> str:
    """Every tuning run: ``<run>.log.jsonl`` (or ``<run>.log.jsonl.gz``) with its
    ``<run>.args.json`` beside it."""
    logs: dict[Path, Path] = {}
    for log in sorted([*repo.root.glob(pattern), *repo.root.glob(pattern + GZ)]):
        logs.setdefault(log.with_name(log.name.removesuffix(GZ)), log)  # one per run
    runs = []
    for plain, log in sorted(logs.items()):
        run = plain.name.removesuffix(".log.jsonl")
        args = _read_json(log.with_name(f"{run}.args.json"))
        runs.append((log.parent.parent.name, run, args, _read_jsonl(log)))
    return tuning_table(runs)


LEARNED = ("diffusion-ac", "ppo", "maskable-ppo", "td3", "safe-dqn-x", "rainbow")
"""Leaderboard entries of the learned agents shipped in ``agents/``."""
CLASSICAL = ("direct", "random", "mvp")
ABLATIONS = (
    "diffusion-ac",
    "diffusion-ac-no-diffusion",
    "diffusion-ac-no-double-q",
    "diffusion-ac-no-dpsc",
    "diffusion-ac-no-value-guidance",
)
"""Diffusion-AC's Table-3 ablations at the reference budget, the complete method first."""
MULTIMODAL = ("diffusion-ac", "ppo", "ppo-sampled")
SAMPLE_TARGET = ("agents/diffusion_ac/analysis/sample-target", "Diffusion-AC, sample target")
"""The reference-budget run of ``--diffusion-target sample`` (seed 1; not a leaderboard entry)."""
TACTICAL = ("tactical/head-on", "tactical/crossing", "tactical/overtaking")
DESIGN_RUNS = ("default-26k", "default-40k", "linear", "ce-none", "ce-noise")
"""Short Diffusion-AC runs of the schedule and terminal-CE experiments."""


TUTORIAL = ("agents/ppo_tutorial/analysis/test", "agents/ppo_tutorial/training_log.jsonl.xz")
"""The PPO tutorial's shipped policy scored once on the test episodes of ``high``
(``cdr-bench evaluate ... --split test --out <folder>/result.json``; not a leaderboard entry)
and its training log."""
TUTORIAL_REFERENCES = ("direct", "mvp", "maskable-ppo")
"""The entries the tutorial's policy is compared with (every training seed of a learned one)."""


def tutorial_test(repo: Repo) -> str:
    """The tutorial's policy against each reference entry (each seed of a learned one) on the
    same test episodes of ``high``: both clean-success rates, the paired difference with its
    95 % paired bootstrap interval and McNemar's exact test
    (:func:`cdr_bench.evaluate.compare.compare`, as ``cdr-bench compare`` prints it), then the
    tutorial's success and LoS rates and its training time (the training log's last line)."""
    from cdr_bench.evaluate.compare import compare

    folder, log = TUTORIAL
    ours = repo.root / folder / "result.json"
    runs: list[tuple[str, Path]] = []
    for name in TUTORIAL_REFERENCES:
        sub = repo.submission(name)
        seeds = [
            (sub.seed, name),
            *((int(v.name.rsplit("-", 1)[1]), v.name) for v in sub.seed_views()),
        ]
        for seed, run in seeds:
            label = repo.label(name) + ("" if seed is None else f", seed {seed}")
            runs.append((label, result_path(repo.results_dir, run)))
    head = [
        "compared with (same 1000 test episodes of `high`)",
        "its clean success",
        "tutorial's clean success",
        "difference",
        "95 % paired interval",
        "McNemar p",
    ]
    rows: Rows = []
    last: dict[str, float] = {}
    for label, path in runs:
        try:
            cmp = compare(path, ours, scenarios=["high"])
        except UserError as e:
            raise UserError(f"{folder}/result.json: {e}") from None
        by = {r["metric"]: r for r in cmp["rows"] if r["aircraft"] == "ownship"}
        r = by["clean_success_rate"]
        last = {k: by[k]["b"] for k in ("clean_success_rate", "success_rate", "los_rate")}
        lo, hi = r["ci95"]
        rows.append(
            [
                Cell(label),
                Cell(f"{100 * r['a']:.1f} %", r["a"]),
                Cell(f"{100 * r['b']:.1f} %", r["b"]),
                Cell(f"{100 * r['diff']:+.1f}" + (" *" if r["significant"] else ""), r["diff"]),
                Cell(f"[{100 * lo:+.1f}, {100 * hi:+.1f}]"),
                Cell(f"{r['mcnemar']['p']:.2g}"),
            ]
        )
    final = _read_jsonl(repo.root / log)[-1]
    note = (
        f"The tutorial's policy on these episodes: clean success "
        f"{100 * last['clean_success_rate']:.1f} %, success {100 * last['success_rate']:.1f} %, "
        f"LoS {100 * last['los_rate']:.1f} %; trained in {final['train_minutes']:.1f} minutes "
        f"({final['global_step']:,} environment steps, `{log}`). *: the interval excludes 0 "
        f"(each comparison on its own, without a correction for the {len(rows)} of them)."
    )
    return md_table(head, rows, numeric_from=1) + "\n\n" + note


def headline(repo: Repo) -> str:
    """The leaderboard's generated conclusion and its ranking by the headline score, from the
    committed ``leaderboard.json`` (the same functions as the leaderboard's pages)."""
    from cdr_bench.leaderboard.render import conclusion

    data = _read_json(repo.lb_dir / "leaderboard.json")
    head, rows, _ = ranking_table(data)
    return "\n\n".join([*conclusion(data), md_table(head, rows, numeric_from=3)])


def multi_agent(repo: Repo) -> str:
    """The multi-agent track's generated conclusion and ranking, from the committed
    ``leaderboard.json`` (the same functions as the leaderboard's pages)."""
    from cdr_bench.leaderboard import multi_agent as ma

    track = _read_json(repo.lb_dir / "leaderboard.json").get("multi_agent")
    if not track:
        return "No multi-agent entry yet."
    head, rows, _ = ma.ranking_table(track)
    return "\n\n".join(
        [*ma.conclusion(track, ma._names(track)), md_table(head, rows, numeric_from=4)]
    )


def claims(repo: Repo) -> str:
    """The paper's claims and our verdicts, from the committed ``leaderboard.json``."""
    data = _read_json(repo.lb_dir / "leaderboard.json")
    head, rows = claims_table(data)
    return md_table(head, rows, numeric_from=len(head))


Block = Callable[[Repo], str]

DOC_BLOCKS: dict[str, dict[str, Block]] = {
    "README.md": {
        "headline": headline,
        "multi-agent": multi_agent,
        "claims": claims,
        "learned-agents": lambda r: measured(r, LEARNED, DENSITIES),
        "reference-agents": lambda r: measured(r, CLASSICAL, ci=False),
        "multimodality": lambda r: multimodality(r, MULTIMODAL),
        "latency": lambda r: latency(r, LEARNED),
    },
    "agents/BASELINES.md": {
        "tuning": tuning,
        "learned-agents": lambda r: measured(r, LEARNED, DENSITIES),
    },
    "agents/diffusion_ac/README.md": {
        "paper-suite": lambda r: measured(r, ["diffusion-ac"]),
        "training": lambda r: training(r, "diffusion-ac"),
        "ablations": lambda r: measured(r, ABLATIONS, ["high"]),
        "design-runs": lambda r: quick_evals(
            r, [(n, f"agents/diffusion_ac/ablations/{n}.log.jsonl.gz") for n in DESIGN_RUNS], "high"
        ),
        "multimodality": lambda r: multimodality_table(
            [*r.multimodal("diffusion-ac"), *r.analysis(*SAMPLE_TARGET, TACTICAL)[1]]
        ),
        "sample-target": lambda r: measured_table(
            [
                (f"{r.label('diffusion-ac')}, teacher target", r.result("diffusion-ac"), []),
                (SAMPLE_TARGET[1], r.analysis(*SAMPLE_TARGET, TACTICAL)[0], []),
            ]
        ),
        "latency": lambda r: latency_detail_table(r.latency("diffusion-ac")),
        "ablation-seeds": lambda r: measured_seeds(r, ABLATIONS, ["high"]),
        "stage-12": stage_table,
    },
    "agents/mvp_improve/README.md": {
        "seeds": lambda r: measured_seeds(r, ["mvp-improve", "mvp-improve-2", "mvp"], ["high"]),
    },
    "agents/ippo/README.md": {"seeds": lambda r: system_seeds(r, ["ippo", "mvp-all"])},
    "agents/mappo/README.md": {"seeds": lambda r: system_seeds(r, ["mappo", "mvp-all"])},
    "docs/tutorials/ppo-vector-env.md": {"test": tutorial_test},
}
"""File (relative to the repository root) -> block name -> what renders it."""


# ----------------------------------------------------------------------------------------------
# Blocks in files

_BLOCK = re.compile(r"<!-- ([a-z0-9-]+):start -->\n(.*?)<!-- \1:end -->", re.S)


def marked_blocks(text: str) -> dict[str, str]:
    """Every ``<!-- name:start -->`` ... ``<!-- name:end -->`` block: name -> body."""
    return {m.group(1): m.group(2) for m in _BLOCK.finditer(text)}


def block_body(content: str) -> str:
    """What goes between the markers: the content and a blank line (so that the end marker
    never continues a Markdown table)."""
    return content.rstrip("\n") + "\n\n"


def replace_blocks(text: str, bodies: dict[str, str], where: str = "") -> str:
    """``text`` with the body of each named block replaced; ValueError if a block is missing."""
    missing = sorted(set(bodies) - set(marked_blocks(text)))
    if missing:
        raise ValueError(
            f"{where}: no block "
            + ", ".join(f"<!-- {n}:start --> ... <!-- {n}:end -->" for n in missing)
        )

    def sub(m: re.Match[str]) -> str:
        name = m.group(1)
        if name not in bodies:
            return m.group(0)
        return f"<!-- {name}:start -->\n{bodies[name]}<!-- {name}:end -->"

    return _BLOCK.sub(sub, text)


def rendered_docs(leaderboard_dir: str | os.PathLike[str]) -> dict[str, tuple[str, str]]:
    """Each file of :data:`DOC_BLOCKS` present in the repository holding ``leaderboard_dir``:
    path relative to the repository -> (text on disk, text with every block rendered now)."""
    repo = Repo(leaderboard_dir)
    out = {}
    for rel, blocks in DOC_BLOCKS.items():
        path = repo.root / rel
        if not path.exists():
            continue  # e.g. a leaderboard folder outside this repository
        old = path.read_text(encoding="utf-8")
        bodies = {name: block_body(fn(repo)) for name, fn in blocks.items()}
        try:
            out[rel] = (old, replace_blocks(old, bodies, rel))
        except ValueError as e:
            raise UserError(str(e)) from None
    return out


def render_docs(leaderboard_dir: str | os.PathLike[str], check: bool = False) -> list[str]:
    """Rewrite every documentation block from the files (``check``: write nothing). Returns a
    unified diff per file whose blocks differed from what the files give."""
    root = Path(leaderboard_dir).resolve().parent
    diffs = []
    for rel, (old, new) in rendered_docs(leaderboard_dir).items():
        if old == new:
            continue
        diff = difflib.unified_diff(
            old.splitlines(), new.splitlines(), f"committed/{rel}", f"rendered/{rel}", lineterm=""
        )
        diffs.append("\n".join(diff))
        if not check:
            atomic_write_text(root / rel, new)
    return diffs
