"""From result files to the leaderboard's numbers (``leaderboard.json``): a pure function of the
submissions, the result files and the published tables.

Every entry must have been run on identical episodes (same scenario config hash, episode count
and seeds); the per-episode file must reproduce the metrics of the result JSON; differences from
the reference entry are the evaluator's paired bootstrap
(:func:`cdr_bench.evaluate.compare.compare`).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cdr_bench.errors import UserError
from cdr_bench.evaluate.compare import compare
from cdr_bench.evaluate.loader import CHECKPOINT_ENV, agent_identity
from cdr_bench.evaluate.metrics import scenario_metrics
from cdr_bench.evaluate.report import DENSITIES, MAIN_COLUMNS
from cdr_bench.evaluate.results import read_episodes, read_result
from cdr_bench.leaderboard.published import METRIC_OF_COLUMN, Published
from cdr_bench.leaderboard.submission import Submission
from cdr_bench.leaderboard.tables import multimodal_path, result_path

DEFAULT_REFERENCE = "diffusion-ac"
DATA_VERSION = 1


@contextmanager
def _checkpoint_env(value: str | None) -> Iterator[None]:
    old = os.environ.get(CHECKPOINT_ENV)
    if value is None:
        os.environ.pop(CHECKPOINT_ENV, None)
    else:
        os.environ[CHECKPOINT_ENV] = value
    try:
        yield
    finally:
        if old is None:
            os.environ.pop(CHECKPOINT_ENV, None)
        else:
            os.environ[CHECKPOINT_ENV] = old


def current_identity(sub: Submission, root: Path) -> dict[str, Any]:
    """The agent identity the evaluator records for this submission now (its files' hashes)."""
    cwd = os.getcwd()
    try:
        os.chdir(root)
        with _checkpoint_env(sub.checkpoint):
            return agent_identity(sub.agent)
    finally:
        os.chdir(cwd)


@dataclass
class Entry:
    sub: Submission
    path: Path
    result: dict[str, Any]
    multimodal: dict[str, dict[str, Any]] = field(default_factory=dict)

    def scenario(self, sid: str) -> dict[str, Any] | None:
        for s in self.result["scenarios"]:
            if s["id"] == sid:
                return s
        return None


def check_result(sub: Submission, path: Path) -> dict[str, Any]:
    """Read a submission's result file and check it against the submission and its own
    per-episode file; :class:`UserError` naming the file otherwise."""
    try:
        result = read_result(path)
        episodes = read_episodes(path, result)
    except ValueError as e:
        raise UserError(str(e)) from None
    except (json.JSONDecodeError, KeyError, TypeError) as e:
        raise UserError(f"{path}: malformed result ({type(e).__name__}: {e})") from None
    ids = [s["id"] for s in result["scenarios"]]
    if ids != list(sub.scenarios):
        raise UserError(
            f"{path}: scenarios {ids} but {sub.source.name} asks for {list(sub.scenarios)}; "
            f"re-evaluate: cdr-bench leaderboard build --evaluate {sub.name}"
        )
    for s in result["scenarios"]:
        eps = [e for e in episodes if e.get("scenario") == s["id"]]
        if len(eps) != s["episodes"]:
            raise UserError(
                f"{path}: {s['id']}: {len(eps)} episodes in {result['episodes_file']}, "
                f"{s['episodes']} in the JSON"
            )
        if canonical_json(scenario_metrics(eps)) != canonical_json(s["metrics"]):
            raise UserError(
                f"{path}: {s['id']}: the metrics do not match the per-episode file "
                f"{result['episodes_file']} (edited by hand?)"
            )
    return result


def canonical_json(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"))


def load_multimodal(path: Path) -> dict[str, Any]:
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as e:
        raise UserError(f"{path}: not a multimodality file ({e})") from None
    keys = ("scenario", "samples", "seed", "all", "success", "success_rate", "modes")
    if not isinstance(d, dict) or any(k not in d for k in keys):
        raise UserError(f"{path}: expected the JSON of `cdr-bench multimodal` ({', '.join(keys)})")
    for k in ("all", "success"):
        v = d[k]
        if not (isinstance(v, list) and len(v) == 27 and all(isinstance(x, int) for x in v)):
            raise UserError(f"{path}: {k}: expected 27 integer counts")
    return d


def load_entries(subs: list[Submission], results_dir: Path) -> list[Entry]:
    """Every submission's checked result (and multimodality files), in submission order."""
    entries = []
    for sub in subs:
        p = result_path(results_dir, sub.name)
        if not p.exists():
            raise UserError(
                f"{p}: no result file for submission {sub.name}; run "
                f"`cdr-bench leaderboard build --evaluate {sub.name}`"
            )
        e = Entry(sub, p, check_result(sub, p))
        for sc in sub.multimodality:
            mp = multimodal_path(results_dir, sub.name, sc)
            if not mp.exists():
                raise UserError(f"{mp}: missing; run `cdr-bench leaderboard build --evaluate`")
            e.multimodal[sc] = load_multimodal(mp)
        entries.append(e)
    known = {result_path(results_dir, s.name).name for s in subs}
    stale = sorted(
        p.name
        for p in results_dir.glob("*.json")
        if ".multimodal-" not in p.name and p.name not in known
    )
    if stale:
        raise UserError(f"{results_dir}: result files without a submission: {', '.join(stale)}")
    _same_episodes(entries)
    return entries


def _same_episodes(entries: list[Entry]) -> None:
    first: dict[str, tuple[str, tuple[Any, ...]]] = {}
    for e in entries:
        for s in e.result["scenarios"]:
            key = (s["config_hash"], s["episodes"], s["seeds_sha256"])
            if s["id"] not in first:
                first[s["id"]] = (e.sub.name, key)
            elif first[s["id"]][1] != key:
                other = first[s["id"]][0]
                raise UserError(
                    f"{e.path}: {s['id']} was not run on the same episodes as {other} "
                    f"(config hash, episodes, seeds: {key} vs {first[s['id']][1]}); "
                    "re-evaluate with `cdr-bench leaderboard build --evaluate`"
                )


def _metric(m: dict[str, Any]) -> dict[str, Any]:
    return {"value": m["value"], "ci95": m["ci95"]}


def _rank_key(metrics: dict[str, Any], name: str) -> tuple[Any, ...]:
    def v(k: str, sign: float) -> float:
        x = metrics[k]["value"]
        return math.inf if x is None else sign * x

    return (v("success_rate", -1), v("los_rate", 1), v("nmac_rate", 1), name)


def build_data(
    entries: list[Entry], published: Published, reference: str = DEFAULT_REFERENCE
) -> dict[str, Any]:
    """Everything the pages show, as one JSON-able dict (deterministic: no timestamps)."""
    by_name = {e.sub.name: e for e in entries}
    ref = by_name.get(reference)
    if ref is None:
        raise UserError(
            f"reference entry {reference!r} has no submission (entries: {', '.join(by_name)})"
        )
    scenario_ids: list[str] = []
    for e in entries:
        for s in e.result["scenarios"]:
            if s["id"] not in scenario_ids:
                scenario_ids.append(s["id"])

    paired: dict[str, dict[tuple[str, str], dict[str, Any]]] = {}
    for e in entries:
        if e is ref:
            continue
        shared = [s for s in e.result["scenarios"] if ref.scenario(s["id"]) is not None]
        if len(shared) != len(e.result["scenarios"]) or len(shared) != len(ref.result["scenarios"]):
            raise UserError(
                f"{e.sub.name}: scored on other scenarios than the reference {reference}; "
                "paired comparison needs the same scenarios"
            )
        rows = compare(ref.path, e.path)["rows"]
        paired[e.sub.name] = {
            (r["scenario"], r["metric"]): r for r in rows if r["aircraft"] == "ownship"
        }

    tables = []
    for sid in scenario_ids:
        rows = []
        config = None
        for e in entries:
            s = e.scenario(sid)
            if s is None:
                continue
            config = s["config"]
            m = s["metrics"]["ownship"]
            lat = e.result["timing"]["decision_latency"][sid]["per_decision_ms"]
            vs: dict[str, Any] = {}
            for key in (c.key for c in MAIN_COLUMNS):
                if e is ref:
                    vs[key] = "reference"
                    continue
                r = paired[e.sub.name][(sid, key)]
                lo, hi = r["ci95"]
                vs[key] = {
                    "diff": _round(r["diff"]),
                    "ci95": [_round(lo), _round(hi)],
                    "significant": r["significant"],
                    "direction": (
                        ("higher" if r["diff"] > 0 else "lower") if r["significant"] else "same"
                    ),
                }
            rows.append(
                {
                    "entry": e.sub.name,
                    "episodes": m["episodes"],
                    "metrics": {c.key: _metric(m[c.key]) for c in MAIN_COLUMNS},
                    "latency_ms": {"median": lat["median"], "p99": lat["p99"]},
                    "vs_reference": vs,
                }
            )
        rows.sort(key=lambda r: _rank_key(r["metrics"], r["entry"]))
        prev, rank = None, 0
        for i, r in enumerate(rows):
            k = _rank_key(r["metrics"], "")
            if k != prev:
                rank, prev = i + 1, k
            r["rank"] = rank
        best: dict[str, list[str]] = {}
        for c in MAIN_COLUMNS:
            best[c.key] = _best(
                [(r["entry"], r["metrics"][c.key]["value"]) for r in rows], c.higher
            )
        best["latency_ms"] = _best([(r["entry"], r["latency_ms"]["median"]) for r in rows], False)
        assert config is not None
        tables.append(
            {
                "scenario": sid,
                "description": config.get("description", ""),
                "episodes": rows[0]["episodes"],
                "rows": rows,
                "best": best,
            }
        )

    side_by_side = []
    for e in entries:
        if e.sub.published_as is None:
            continue
        for sid in DENSITIES:
            pub = published.lookup(e.sub.published_as, sid)
            s = e.scenario(sid)
            if pub is None or s is None:
                continue
            m = s["metrics"]["ownship"]
            side_by_side.append(
                {
                    "entry": e.sub.name,
                    "published_as": e.sub.published_as,
                    "table": pub.table,
                    "scenario": sid,
                    "rows": [
                        {
                            "column": col,
                            "published": val,
                            "measured": _metric(m[METRIC_OF_COLUMN[col]]),
                            "metric": METRIC_OF_COLUMN[col],
                        }
                        for col, val in pub.values.items()
                    ],
                }
            )

    return {
        "data_version": DATA_VERSION,
        "reference": reference,
        "scenarios": scenario_ids,
        "entries": [
            {
                "name": e.sub.name,
                "display_name": e.sub.display_name,
                "description": e.sub.description,
                "agent": e.sub.agent,
                "checkpoint": e.sub.checkpoint,
                "authors": list(e.sub.authors),
                "reference": e.sub.reference,
                "training": e.sub.training,
                "published_as": e.sub.published_as,
                "agent_sha256": e.result["agent"]["sha256"],
                "result_file": f"results/{e.path.name}",
                "base_seed": e.result["base_seed"],
                "batch_size": e.result["batch_size"],
                "cdr_bench_version": e.result["versions"].get("cdr-bench"),
            }
            for e in entries
        ],
        "tables": tables,
        "published_vs_measured": side_by_side,
        "multimodality": [
            {
                "entry": e.sub.name,
                "scenario": sc,
                "samples": d["samples"],
                "seed": d["seed"],
                "threshold": d.get("threshold"),
                "all": d["all"],
                "success": d["success"],
                "success_rate": d["success_rate"],
                "modes": d["modes"],
                "normalised_entropy": d.get("normalised_entropy"),
            }
            for e in entries
            for sc, d in sorted(e.multimodal.items())
        ],
    }


def _round(x: float) -> float | None:
    return None if x is None or not math.isfinite(x) else round(float(x), 6)


def _best(values: list[tuple[str, float | None]], higher: bool) -> list[str]:
    """Entries holding the best value; none when every entry ties (nothing to mark)."""
    vals = [(n, v) for n, v in values if v is not None]
    if len(vals) < 2:
        return [n for n, _ in vals] if len(values) > 1 else []
    target = max(v for _, v in vals) if higher else min(v for _, v in vals)
    winners = [n for n, v in vals if v == target]
    return [] if len(winners) == len(values) else winners
