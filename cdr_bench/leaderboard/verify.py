"""Verification of committed results by replay (``cdr-bench leaderboard build --check``).

A per-episode record carries the decisions its aircraft took (``actions``: one character per
decision, :data:`~cdr_bench.evaluate.runner.ACTION_CODE`). Two checks follow from that:

* **Replay** (:func:`replay_result`, every committed episode of every entry and seed): the
  recorded decisions are flown again through the simulator of this checkout, in the episode's
  own batch, and the records that come out must equal the committed ones character for
  character. No agent runs, so this is exact on any x86-64 CPU (the simulator's floating point
  is pinned: docs/model.md §12) and fast. It proves that the file is what the simulator gives
  for those decisions: no outcome, distance or event was edited.
* **Agent re-run** (:func:`agreement_verdict`, a sample drawn at random at each check): the
  entry's agent is asked again, in its sandbox, at every step of a sampled batch (the same
  observations, masks and reset seed as when it was scored), while the recorded decisions are
  flown. At least :data:`MIN_AGREEMENT` of its decisions must equal the recorded ones. This
  proves that the decisions are the agent's, and tolerates what differs between CPUs for an
  agent that runs an ordinary PyTorch network: a near-tie between two actions (two Q-values or
  logits within float rounding) can fall the other way on another CPU's kernels; such
  disagreements are listed, and the check fails only when they exceed the tolerance.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cdr_bench.evaluate.results import SCHEMA_VERSION, read_episodes, read_result
from cdr_bench.evaluate.runner import ReplayMismatch, run_batch
from cdr_bench.scenarios import load_scenario

MIN_AGREEMENT = 0.99
"""The share of re-run decisions that must equal the recorded ones (per entry and check)."""

_LIMIT = 3


def record_line(scenario: str, record: dict[str, Any]) -> str:
    """A per-episode record as the log writes it (without the newline)."""
    return json.dumps({"scenario": scenario, **record}, separators=(",", ":"))


def batches_of(result: dict[str, Any]) -> Iterator[tuple[str, int]]:
    """Every (scenario id, batch index) of a result, in run order."""
    size = int(result["batch_size"])
    for s in result["scenarios"]:
        for k in range(-(-int(s["episodes"]) // size)):
            yield s["id"], k


@dataclass
class BatchCheck:
    scenario: str
    batch: int
    differences: list[str]
    """Readable lines, the first few (of ``mismatches`` records that differ)."""
    episodes: int = 0
    mismatches: int = 0
    agreement: dict[str, Any] | None = None


def check_batch(
    result: dict[str, Any],
    episodes: list[dict[str, Any]],
    scenario: str,
    batch: int,
    agent: Any = None,
) -> BatchCheck:
    """Replay one batch of a result (with ``agent``: and ask it at every step) and compare the
    records with the committed ones."""
    size = int(result["batch_size"])
    base_seed = int(result["base_seed"])
    sc = next(s for s in result["scenarios"] if s["id"] == scenario)
    n = int(sc["episodes"])
    start, stop = batch * size, min((batch + 1) * size, n)
    committed = [e for e in episodes if e.get("scenario") == scenario][start:stop]
    out = BatchCheck(scenario, batch, [], episodes=len(committed))
    config = _scenario(scenario)
    if config.config_hash() != sc["config_hash"]:
        out.differences.append(
            f"scenario {scenario}: its configuration changed since the evaluation (config hash "
            f"{sc['config_hash'][:12]} committed, {config.config_hash()[:12]} now)"
        )
        return out
    if [e.get("episode") for e in committed] != list(range(start, stop)):
        out.differences.append(f"{scenario} batch {batch}: episodes missing or out of order")
        return out
    try:
        replay = [[str(a.get("actions", "")) for a in e["aircraft"]] for e in committed]
        got = run_batch(agent, config, base_seed, batch, size, n, replay=replay)
    except (ReplayMismatch, ValueError, KeyError, TypeError) as e:
        out.differences.append(f"{scenario} batch {batch}: cannot be replayed ({e})")
        return out
    for old, new in zip(committed, got["episodes"], strict=True):
        a = record_line(scenario, {k: v for k, v in old.items() if k != "scenario"})
        b = record_line(scenario, new)
        if a == b:
            continue
        out.mismatches += 1
        if len(out.differences) < _LIMIT:
            out.differences.append(
                f"{scenario} episode {old.get('episode')}: {_fields(old, new)}\n"
                f"    committed: {_short(a)}\n    replayed:  {_short(b)}"
            )
    out.agreement = got.get("agreement")
    return out


def replayed_traces(
    result: dict[str, Any], episodes: list[dict[str, Any]], scenario: str, n: int
) -> list[dict[str, Any]]:
    """The trajectories of the first ``n`` episodes of ``scenario`` flown from their recorded
    decisions (what :func:`cdr_bench.evaluate.api.record_traces` records with the agent, for
    an honest record: the same first batch, seeds and decisions)."""
    size, base_seed = int(result["batch_size"]), int(result["base_seed"])
    sc = next(s for s in result["scenarios"] if s["id"] == scenario)
    total = int(sc["episodes"])
    first = [e for e in episodes if e.get("scenario") == scenario][: min(size, total)]
    replay = [[str(a.get("actions", "")) for a in e["aircraft"]] for e in first]
    got = run_batch(None, _scenario(scenario), base_seed, 0, size, total, trace=n, replay=replay)
    return list(got["traces"])


def replay_result(path: str | Path, first: int | None = None) -> tuple[int, list[str]]:
    """Replay every committed episode of a result file (only the first ``first`` episodes of
    each scenario, rounded up to whole batches, when given). Returns (episodes replayed,
    differences as readable lines; empty: the file is what the simulator gives)."""
    p = Path(path)
    try:
        result = read_result(p, metrics=False)
        episodes = read_episodes(p, result)
    except ValueError as e:
        return 0, [str(e)]
    if result.get("schema_version") != SCHEMA_VERSION:
        return 0, [f"{p}: schema {result.get('schema_version')}: no decisions to replay"]
    size = int(result["batch_size"])
    n_done, diffs = 0, []
    for scenario, k in batches_of(result):
        if first is not None and k * size >= first:
            continue
        chk = check_batch(result, episodes, scenario, k)
        n_done += chk.episodes
        diffs += chk.differences
        more = chk.mismatches - len(chk.differences)
        if more > 0:
            diffs.append(f"  ... and {more} more episodes of {scenario} batch {k} differ")
    return n_done, diffs


@functools.lru_cache(maxsize=64)
def _scenario(name: str) -> Any:
    return load_scenario(name)


def agreement_verdict(name: str, batches: list[dict[str, Any]]) -> tuple[str, bool]:
    """A one-paragraph verdict on an agent re-run (``batches``: the ``agreement`` of each
    re-run batch with its ``scenario`` and ``batch``) and whether it passes."""
    asked = sum(int(b["decisions"]) for b in batches)
    agree = sum(int(b["agree"]) for b in batches)
    share = agree / asked if asked else 1.0
    where = ", ".join(f"{b['scenario']} batch {b['batch']}" for b in batches)
    ok = share >= MIN_AGREEMENT
    text = (
        f"{name}: agent re-run on {where}: {agree} of {asked} decisions equal the record "
        f"({100 * share:.2f} %, tolerance {100 * MIN_AGREEMENT:g} %)"
    )
    dis = [d for b in batches for d in b.get("disagreements", [])]
    if dis:
        shown = "; ".join(
            f"episode {d[0]} {d[1]} decision {d[2]}: recorded {d[3]}, now {d[4]}" for d in dis[:5]
        )
        text += f"; disagreements (near-ties on another CPU, or not the agent's): {shown}"
    return text, ok


def _fields(old: dict[str, Any], new: dict[str, Any]) -> str:
    """Which fields of two records differ, e.g. ``ownship_0.los committed false, replayed
    true``."""
    out = [
        f"{k} committed {json.dumps(old.get(k))}, replayed {json.dumps(new.get(k))}"
        for k in sorted(set(old) | set(new))
        if k not in ("aircraft", "scenario") and old.get(k) != new.get(k)
    ]
    a_old, a_new = old.get("aircraft") or [], new.get("aircraft") or []
    for i in range(max(len(a_old), len(a_new))):
        x = a_old[i] if i < len(a_old) and isinstance(a_old[i], dict) else {}
        y = a_new[i] if i < len(a_new) else {}
        who = y.get("id", f"aircraft {i}")
        out += [
            f"{who}.{k} committed {_short(json.dumps(x.get(k)), 40)}, "
            f"replayed {_short(json.dumps(y.get(k)), 40)}"
            for k in sorted(set(x) | set(y))
            if x.get(k) != y.get(k)
        ]
    return "; ".join(out[:6]) + (f" (and {len(out) - 6} more)" if len(out) > 6 else "")


def _short(line: str, width: int = 300) -> str:
    return line if len(line) <= width else line[:width] + " ..."
