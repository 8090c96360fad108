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
* **Fresh episodes** (:func:`fresh_run`, :func:`fresh_verdict`, every entry at each check): the
  agent flies :data:`FRESH_EPISODES` episodes of the headline scenario that nobody has seen,
  from a base seed drawn at check time (and an agent reset seed derived with a secret key,
  :func:`cdr_bench.evaluate.runner.batch_seed`), and its headline rate there must be consistent
  with the committed one: Fisher's exact test, two-sided, fails at p < :data:`FRESH_ALPHA`.
  Replay and re-run prove that the committed episodes are the agent's; this proves that the
  score is not tied to those episodes (an agent that recognises the public episodes and flies a
  plan made with knowledge of their traffic, or decisions forged on enough episodes to move
  the score, fail it). Under an honest entry the committed and the fresh episodes are draws
  from one distribution, so a check raises a false alarm for an entry with probability at most
  :data:`FRESH_ALPHA` (Fisher's test is exact and conservative).
"""

from __future__ import annotations

import functools
import json
import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cdr_bench.evaluate.results import SCHEMA_VERSION, read_episodes, read_result
from cdr_bench.evaluate.runner import ReplayMismatch, run_batch
from cdr_bench.scenarios import load_scenario

MIN_AGREEMENT = 0.99
"""The share of re-run decisions that must equal the recorded ones (per entry and check)."""

FRESH_EPISODES = 200
"""Fresh episodes of the headline scenario flown per entry at each check."""

FRESH_ALPHA = 1e-4
"""Two-sided significance level of the fresh-episode test: the false-alarm probability per
honest entry and check is at most this (about 0.2 % for 16 entries)."""

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
        replay = [
            {str(a.get("id")): str(a.get("actions", "")) for a in e["aircraft"]} for e in committed
        ]
        key = str(result.get("agent_seed_key", ""))  # the scorer's, recorded after the run
        got = run_batch(agent, config, base_seed, batch, size, n, replay=replay, agent_key=key)
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
    replay = [{str(a.get("id")): str(a.get("actions", "")) for a in e["aircraft"]} for e in first]
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


def fisher_exact(k1: int, n1: int, k2: int, n2: int) -> float:
    """Two-sided p-value of Fisher's exact test of equal rates, ``k1`` of ``n1`` against ``k2``
    of ``n2`` (the tables with the same margins no more probable than the observed one; exact
    integer arithmetic, the tolerance of ``scipy.stats.fisher_exact``)."""
    if not (0 <= k1 <= n1 and 0 <= k2 <= n2) or n1 + n2 == 0:
        raise ValueError(f"fisher_exact: counts {k1}/{n1}, {k2}/{n2} are not rates")
    total, k = n1 + n2, k1 + k2
    lo, hi = max(0, k - n2), min(k, n1)
    weights = {x: math.comb(n1, x) * math.comb(n2, k - x) for x in range(lo, hi + 1)}
    observed = weights[k1]
    limit = observed + observed // 10**7  # exact integers: no float overflow
    tail = sum(w for w in weights.values() if w <= limit)
    return min(1.0, tail / math.comb(total, k))


def fresh_run(
    agent: Any, scenario: str, base_seed: int, episodes: int, agent_key: str, batch_size: int
) -> dict[str, Any]:
    """``agent`` on ``episodes`` fresh episodes of ``scenario`` (base seed ``base_seed``, agent
    reset seeds derived with ``agent_key``): the count and rate of every headline-style metric
    the check compares (the ownship's ``clean_success_rate`` and ``success_rate``)."""
    config = _scenario(scenario)
    records: list[dict[str, Any]] = []
    for k in range(-(-episodes // batch_size)):
        got = run_batch(agent, config, base_seed, k, batch_size, episodes, agent_key=agent_key)
        records += got["episodes"]
    return {
        "scenario": scenario,
        "base_seed": base_seed,
        "episodes": episodes,
        "metrics": ownship_metrics(records),
    }


def ownship_metrics(episodes: list[dict[str, Any]]) -> dict[str, Any]:
    """The :data:`FRESH_METRICS` of the ownship over these episode records (only those: the
    other metrics, and their bootstrap intervals, are not computed)."""
    from cdr_bench.evaluate.metrics import get_metric, role_of

    own = [ac for ep in episodes for ac in ep["aircraft"] if role_of(ac["id"]) == "ownship"]
    return {m: get_metric(m).compute(own) for m in FRESH_METRICS}


def committed_ownship(path: str | Path, scenario: str) -> dict[str, Any]:
    """The ownship's :data:`FRESH_METRICS` on ``scenario`` of a committed result (read from its
    per-episode log)."""
    result = read_result(path, metrics=False)
    return ownship_metrics([ep for ep in read_episodes(path, result) if ep["scenario"] == scenario])


FRESH_METRICS = ("clean_success_rate",)
"""The metrics the fresh-episode test compares (the headline: what ranks an entry)."""


def fresh_verdict(name: str, committed: dict[str, Any], fresh: dict[str, Any]) -> tuple[str, bool]:
    """A one-line verdict on the fresh-episode test and whether it passes: ``committed`` is the
    committed result's ownship metrics on the scenario, ``fresh`` what :func:`fresh_run`
    returned."""
    parts, ok = [], True
    for m in FRESH_METRICS:
        a, b = committed[m], fresh["metrics"][m]
        p = fisher_exact(int(a["count"]), int(a["n"]), int(b["count"]), int(b["n"]))
        bad = p < FRESH_ALPHA
        ok = ok and not bad
        parts.append(
            f"{m} {100 * a['count'] / a['n']:.1f} % committed ({a['count']}/{a['n']}), "
            f"{100 * b['count'] / b['n']:.1f} % on fresh episodes ({b['count']}/{b['n']}), "
            f"Fisher exact p = {p:.2g}"
            + (f" < {FRESH_ALPHA:g}: the committed score does not generalise" if bad else "")
        )
    text = (
        f"{name}: {fresh['episodes']} fresh {fresh['scenario']} episodes (base seed "
        f"{fresh['base_seed']}): " + "; ".join(parts)
    )
    return text, ok


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
