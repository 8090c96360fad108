"""From result files to the leaderboard's numbers (``leaderboard.json``): a pure function of the
submissions, the result files, the training logs they name and the published tables.

Every entry must have been run on identical episodes (same scenario config hash, episode count
and seeds); the per-episode file must reproduce the metrics of the result JSON; every paired
difference is the evaluator's paired bootstrap (:func:`cdr_bench.evaluate.compare.compare`).

**The headline score** (:data:`HEADLINE_METRIC` on :data:`HEADLINE_SCENARIO`): the ownship's
clean success rate on ``high``, goal reached with no loss of separation at all, over the
entry's training seeds (:class:`SeedPaired`): the mean of its independent units (seeds; seeds
sharing a ``parent`` are one unit) up to four, their IQM beyond, a scripted entry's one run;
with a 95 % two-level bootstrap interval (units, then the episodes of each drawn run). Paired
differences (tie groups, the row above, the baseline) average the per-episode difference over
seeds with the same two-level bootstrap, on ``compare``'s per-scenario episode indices.
Success alone does not separate agents (on ``high`` the never-manoeuvring
``direct`` agent reaches its goal in 99 % of the episodes, the learned agents in 99.5-99.8 %):
an agent that flies through a LoS still succeeds. Clean success counts the episodes an
air-traffic controller would accept, rewards resolving rather than luck, and cannot be gamed
by failing (a timeout, a boundary exit or an NMAC is not a clean success). Entries are ranked
by it. Inside a tie group entries are ordered by :data:`TIE_BREAK` (extra path flown by
successful flights, lower first: among agents that succeed equally often, the one that detours
less), except that an entry never ranks above a member whose score is significantly higher;
the first of the first group is the leader. A tie group is the best remaining score and the
entries after it in score order down
to the first one significantly below it; groups share a rank (``2=``) and follow each other
strictly by score; each row also shows the paired difference from the row above. Entries are
``scripted``, ``learned`` (from scratch), ``hybrid`` (MVP with a learned override) or
``ablation``; the summary compares learned agents and hybrids with MVP apart, each "k of n"
Holm-corrected.

**Best values** are marked only on metrics whose better value cannot come from failing
(:data:`MARK_BEST`): never on steps, extra path, delay or manoeuvres (an agent that ends early
by a LoS or succeeds only on easy episodes has fewer steps), nor on the timeout rate or the
rewards (shaped, and lower timeouts come with LoS endings).

**Fixed encounters**: a scenario whose episodes all start from the identical state (every state
array of the simulator equal across the episodes' seeds; :func:`fixed_geometry`) is one
encounter flown many times; its result is shown as the single outcome (``success``, ``LoS at
step 7``), never as a rate with an interval.
"""

from __future__ import annotations

import json
import lzma
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cdr_bench.errors import UserError
from cdr_bench.evaluate import aggregate
from cdr_bench.evaluate.compare import compare, holm, scenario_indices, scenario_seed
from cdr_bench.evaluate.loader import agent_identity
from cdr_bench.evaluate.report import COLUMNS
from cdr_bench.evaluate.results import SCHEMA_VERSION, log_text, read_episodes, read_result
from cdr_bench.leaderboard.claims import build_claims
from cdr_bench.leaderboard.page_tables import DENSITIES, MAIN_COLUMNS
from cdr_bench.leaderboard.published import METRIC_OF_COLUMN, Published
from cdr_bench.leaderboard.submission import GROUPS, Submission
from cdr_bench.leaderboard.tables import (
    multimodal_path,
    multimodal_seed_path,
    replays_path,
    result_path,
)

DEFAULT_REFERENCE = "diffusion-ac"
DATA_VERSION = 6
HEADLINE_SCENARIO = "high"
HEADLINE_METRIC = "clean_success_rate"
ALPHA = 0.05
"""Significance level of every test on the pages (after Holm's correction where a statement
combines several)."""
TIE_BREAK = "extra_path_km"
"""Lower is better; breaks ties among the entries statistically tied with the leader."""
PAPER_FIVE = ("success_rate", "los_rate", "nmac_rate", "timeout_rate", "avg_steps_success")
MARK_BEST = frozenset(
    {"success_rate", "clean_success_rate", "los_rate", "nmac_rate", "invalid_action_rate"}
    | {"latency_ms"}
)
"""Columns whose best value is marked: safety and headline metrics (a better value cannot come
from failing), the share of masked actions and the decision latency."""
BASELINE = "mvp"
"""The scripted resolver the learned agents are compared with in the conclusion."""
TACTICAL_PREFIX = "tactical/"


def current_identity(sub: Submission, root: Path) -> dict[str, Any]:
    """The agent identity the evaluator records for this submission now (its files' hashes;
    the ``sha256`` is the evaluator's, the paths are absolute). Changes no working directory or
    environment variable: the check calls it from two threads at once, and the earlier version
    (chdir + ``CDR_BENCH_CHECKPOINT`` set and restored around the call) let one thread hash a
    seed's agent with the other's checkpoint."""
    ck = str(root / sub.checkpoint) if sub.checkpoint else None
    return agent_identity(root / sub.agent, checkpoint=ck)


@dataclass
class Entry:
    sub: Submission
    path: Path
    result: dict[str, Any]
    multimodal: dict[str, dict[str, Any]] = field(default_factory=dict)
    multimodal_seeds: dict[str, dict[int, dict[str, Any]]] = field(default_factory=dict)
    """Per multimodality scenario, ``cdr-bench multimodal`` of each training seed that has one
    (:func:`cdr_bench.leaderboard.tables.multimodal_seed_path`), by seed."""
    episodes: list[dict[str, Any]] = field(default_factory=list)
    """The per-episode records (all scenarios, in file order)."""
    replays: dict[str, Any] | None = None
    runs: list[tuple[int | None, Entry]] = field(default_factory=list)
    """Every training seed's scored run ``(seed, entry)``, this one first; ``[(None, self)]``
    for an entry of one seed."""

    @property
    def name(self) -> str:
        return self.sub.name

    def scenario(self, sid: str) -> dict[str, Any] | None:
        for s in self.result["scenarios"]:
            if s["id"] == sid:
                return s
        return None


def check_result(sub: Submission, path: Path) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Read a submission's result file and check it against the submission and its own
    per-episode file; :class:`UserError` naming the file otherwise. Returns the result and its
    per-episode records."""
    try:
        # a multi-agent entry is shown by its system metrics only
        result = read_result(path, roles=sub.track == "single-agent")
        episodes = read_episodes(path, result)
    except ValueError as e:
        raise UserError(str(e)) from None
    except (json.JSONDecodeError, KeyError, TypeError) as e:
        raise UserError(f"{path}: malformed result ({type(e).__name__}: {e})") from None
    if result.get("schema_version") != SCHEMA_VERSION:
        raise UserError(
            f"{path}: schema_version {result.get('schema_version')}: a leaderboard result must "
            f"be schema {SCHEMA_VERSION} (its decisions recorded, so that --check can replay "
            f"it); re-evaluate: cdr-bench leaderboard build --evaluate {sub.name}"
        )
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
    return result, episodes


def load_multimodal(path: Path) -> dict[str, Any]:
    """The JSON of ``cdr-bench multimodal`` (xz-compressed when the name ends in ``.xz``)."""
    try:
        raw = path.read_bytes()
        if path.suffix == ".xz":
            raw = lzma.decompress(raw)
        d = json.loads(raw.decode("utf-8"))
    except (OSError, lzma.LZMAError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise UserError(f"{path}: not a multimodality file ({e})") from None
    keys = ("scenario", "samples", "seed", "all", "success", "success_rate", "modes")
    if not isinstance(d, dict) or any(k not in d for k in keys):
        raise UserError(f"{path}: expected the JSON of `cdr-bench multimodal` ({', '.join(keys)})")
    for k in ("all", "success"):
        v = d[k]
        if not (isinstance(v, list) and len(v) == 27 and all(isinstance(x, int) for x in v)):
            raise UserError(f"{path}: {k}: expected 27 integer counts")
    return d


def _checked_entry(view: Submission, results_dir: Path, what: str, name: str) -> Entry:
    """The checked result of one run (a submission or one of its seeds)."""
    p = result_path(results_dir, view.name)
    if not p.exists():
        raise UserError(
            f"{p}: no result file for {what}; run `cdr-bench leaderboard build --evaluate {name}`"
        )
    result, episodes = check_result(view, p)
    return Entry(view, p, result, episodes=episodes)


def load_entries(subs: list[Submission], results_dir: Path) -> list[Entry]:
    """Every submission's checked result (and multimodality files), in submission order."""
    entries = []
    for sub in subs:
        e = _checked_entry(sub, results_dir, f"submission {sub.name}", sub.name)
        if sub.replays:
            rp = replays_path(results_dir, sub.name)
            if not rp.exists():
                raise UserError(
                    f"{rp}: missing; run `cdr-bench leaderboard build --evaluate {sub.name}`"
                )
            e.replays = load_replays(rp, sub)
        for sc in sub.multimodality:
            mp = multimodal_path(results_dir, sub.name, sc)
            if not mp.exists():
                raise UserError(f"{mp}: missing; run `cdr-bench leaderboard build --evaluate`")
            e.multimodal[sc] = load_multimodal(mp)
        e.runs = [(sub.seed, e)]
        for view, seed in zip(
            sub.seed_views(), [x for x in sub.seeds if x.checkpoint != sub.checkpoint], strict=True
        ):
            run = _checked_entry(view, results_dir, f"seed {seed.seed} of {sub.name}", sub.name)
            e.runs.append((seed.seed, run))
        for sc in sub.multimodality:
            for k, _ in e.runs:
                mp = multimodal_seed_path(results_dir, sub.name, 1 if k is None else k, sc)
                if mp.exists():
                    e.multimodal_seeds.setdefault(sc, {})[1 if k is None else k] = load_multimodal(
                        mp
                    )
        entries.append(e)
    known = {result_path(results_dir, v.name).name for s in subs for v in (s, *s.seed_views())}
    stale = sorted(
        p.name
        for p in results_dir.glob("*.json")
        if ".multimodal-" not in p.name
        and not p.name.endswith(".replays.json")
        and p.name not in known
    )
    if stale:
        raise UserError(f"{results_dir}: result files without a submission: {', '.join(stale)}")
    _same_episodes([r for e in entries for _, r in e.runs])
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


def _metric(m: dict[str, Any] | None) -> dict[str, Any]:
    """``{value, ci95}`` of a measured metric; a metric the result does not hold (an older
    result file) is ``None`` ("not measured")."""
    if m is None:
        return {"value": None, "ci95": [None, None]}
    return {"value": m["value"], "ci95": m["ci95"]}


def _ownship(e: Entry, sid: str) -> dict[str, Any]:
    s = e.scenario(sid)
    if s is None:
        raise UserError(f"{e.path}: no scenario {sid}")
    m: dict[str, Any] = s["metrics"]["ownship"]
    return m


def _diff(row: dict[str, Any]) -> dict[str, Any]:
    lo, hi = row["ci95"]
    return {
        "diff": _round(row["diff"]),
        "ci95": [_round(lo), _round(hi)],
        "significant": row["significant"],
    }


class Paired:
    """Paired bootstrap differences between entries (the evaluator's ``compare``), each pair and
    scenario computed once: ``get(a, b, sid)[metric]`` is b - a on the ownship."""

    def __init__(self) -> None:
        self._cache: dict[tuple[str, str, str], dict[str, dict[str, Any]]] = {}
        self.seeds = SeedPaired()
        """Scores and paired differences over seeds (the ranking's)."""

    def all(self, a: Entry, b: Entry) -> dict[tuple[str, str], dict[str, Any]]:
        shown = list(dict.fromkeys([*(c.key for c in MAIN_COLUMNS), HEADLINE_METRIC]))
        rows = compare(a.path, b.path, None, shown)["rows"]
        out = {(r["scenario"], r["metric"]): r for r in rows if r["aircraft"] == "ownship"}
        for sid in {k[0] for k in out}:
            self._cache[(a.name, b.name, sid)] = {m: r for (s, m), r in out.items() if s == sid}
        return out

    def get(self, a: Entry, b: Entry, sid: str) -> dict[str, dict[str, Any]]:
        """The headline metric's difference b - a on ``sid`` (every metric if :meth:`all` of
        the pair ran before)."""
        return self._get(a, b, sid, HEADLINE_METRIC)

    def metric(self, a: Entry, b: Entry, sid: str, metric: str) -> dict[str, Any]:
        """One metric's paired difference b - a on ``sid``."""
        return self._get(a, b, sid, metric)[metric]

    def _get(self, a: Entry, b: Entry, sid: str, metric: str) -> dict[str, dict[str, Any]]:
        key = (a.name, b.name, sid)
        if metric not in self._cache.get(key, {}):
            back = self._cache.get((b.name, a.name, sid), {})
            if metric in back:  # the same resampled episodes: b - a = -(a - b)
                self._cache.setdefault(key, {}).update(
                    {
                        m: {
                            **r,
                            "diff": -r["diff"],
                            "ci95": [-r["ci95"][1], -r["ci95"][0]],
                            **(
                                {
                                    "mcnemar": {
                                        **r["mcnemar"],
                                        "b": r["mcnemar"]["c"],
                                        "c": r["mcnemar"]["b"],
                                    }
                                }  # fmt: skip
                                if "mcnemar" in r
                                else {}
                            ),
                        }
                        for m, r in back.items()
                    }
                )
            else:
                rows = compare(a.path, b.path, [sid], [metric])["rows"]
                self._cache.setdefault(key, {}).update(
                    {r["metric"]: r for r in rows if r["aircraft"] == "ownship"}
                )
        return self._cache[key]


def _units(e: Entry) -> list[list[Entry]]:
    """The independent units of an entry's runs: one per seed, except that seeds with the same
    ``parent`` (trained on from one run) are one unit."""
    parent = {s.seed: s.parent for s in e.sub.seeds}
    out: dict[Any, list[Entry]] = {}
    for seed, run in _runs(e):
        p = parent.get(seed) if seed is not None else None
        out.setdefault(("parent", p) if p else ("seed", seed), []).append(run)
    return list(out.values())


def _outcomes(run: Entry, sid: str, metric: str) -> Any:
    """The ownship's 0/1 outcome of ``metric`` per episode of ``sid`` (file order)."""
    return episode_outcomes(run.episodes, run.path, sid, metric)


def episode_outcomes(episodes: list[dict[str, Any]], path: Path, sid: str, metric: str) -> Any:
    """The ownship's 0/1 outcome of ``metric`` per episode of ``sid`` in ``episodes`` (the
    records of the result ``path``, in file order)."""
    import numpy as np

    from cdr_bench.evaluate.metrics import get_metric, role_of

    paired = get_metric(metric).paired
    out = []
    for ep in episodes:
        if ep["scenario"] != sid:
            continue
        num = den = 0.0
        for ac in ep["aircraft"]:
            if role_of(ac["id"]) == "ownship":
                a, b = paired(ac)
                num, den = num + a, den + b
        if den != 1 or num not in (0, 1):
            raise UserError(f"{path}: {metric} is not one yes/no outcome per episode")
        out.append(int(num))
    return np.array(out, dtype=np.int64)


class SeedPaired:
    """The ranked score of each entry over its seeds and the paired differences between entries
    averaged over seeds (:mod:`cdr_bench.evaluate.aggregate`'s two-level bootstrap), on one
    metric; each computed once."""

    def __init__(self, metric: str = HEADLINE_METRIC) -> None:
        self.metric = metric
        self._score: dict[tuple[str, str], dict[str, Any]] = {}
        self._diff: dict[tuple[str, str, str], dict[str, Any]] = {}
        self._out: dict[tuple[str, str], list[list[Any]]] = {}

    def _vectors(self, e: Entry, sid: str) -> list[list[Any]]:
        key = (e.name, sid)
        if key not in self._out:
            self._out[key] = [[_outcomes(r, sid, self.metric) for r in u] for u in _units(e)]
        return self._out[key]

    def score(self, e: Entry, sid: str) -> dict[str, Any]:
        """``{value, ci95, seeds, units, aggregate}``: the mean (at most four units) or IQM over
        the entry's units with its two-level 95 % interval (seeds, then episodes)."""
        key = (e.name, sid)
        if key not in self._score:
            vec = self._vectors(e, sid)
            n = len(vec[0][0])
            counts = [[int(r.sum()) for r in u] for u in vec]
            lo, hi = aggregate.seed_score_interval(counts, n, seed=scenario_seed(sid, e.name))
            self._score[key] = {
                "value": round(aggregate.seed_score(counts, n), 6),
                "ci95": [round(lo, 6), round(hi, 6)],
                "seeds": sum(len(u) for u in vec),
                "units": len(vec),
                "aggregate": aggregate.aggregate_name(len(vec)),
            }
        return self._score[key]

    def diff(self, a: Entry, b: Entry, sid: str) -> dict[str, Any]:
        """b - a: the per-episode paired difference averaged over seeds (each side's mean over
        its units), with its two-level 95 % interval; with one run each, ``compare``'s."""
        key = (a.name, b.name, sid)
        if key not in self._diff:
            back = self._diff.get((b.name, a.name, sid))
            if back is not None:
                lo, hi = back["ci95"]
                self._diff[key] = {**back, "diff": -back["diff"], "ci95": [-hi, -lo]}
            else:
                va, vb = self._vectors(a, sid), self._vectors(b, sid)
                idx = scenario_indices(sid, len(va[0][0]))
                self._diff[key] = aggregate.paired_seed_difference(
                    va, vb, idx, seed=scenario_seed(sid, f"/{a.name}/{b.name}")
                )
        return self._diff[key]


def _value(e: Entry, sid: str, key: str) -> float | None:
    m = _ownship(e, sid).get(key)
    return None if m is None else m["value"]


def rank_entries(entries: list[Entry], paired: Paired) -> dict[str, Any]:
    """The ranking by the headline score over seeds (see the module docstring)."""
    sid = HEADLINE_SCENARIO
    missing = [e.name for e in entries if e.scenario(sid) is None]
    if missing:
        raise UserError(
            f"entries {', '.join(missing)} are not scored on {sid}, the headline scenario "
            f"({HEADLINE_METRIC} on {sid} ranks the leaderboard)"
        )
    sp = paired.seeds
    score = {e.name: sp.score(e, sid) for e in entries}

    def head(e: Entry) -> float:
        v = score[e.name]["value"]
        return -math.inf if v is None else float(v)

    def tie(e: Entry) -> float:
        v = _value(e, sid, TIE_BREAK)
        return math.inf if v is None else v

    def below(o: Entry, e: Entry) -> bool:
        """e significantly below o."""
        d = sp.diff(o, e, sid)
        return bool(d["significant"] and d["diff"] < 0)

    by_score = sorted(entries, key=lambda e: (-head(e), e.name))
    tiers: list[list[Entry]] = []
    remaining = by_score
    while remaining:
        # a tie group: the best remaining score and the entries after it in score order, down
        # to the first one significantly below it (so groups never interleave by score)
        top = remaining[0]
        group = [top]
        for e in remaining[1:]:
            if head(e) < head(top) and below(top, e):
                break
            group.append(e)
        left = sorted(group, key=lambda e: (tie(e), -head(e), e.name))
        ordered = []
        while left:
            pick = next(
                (
                    e
                    for e in left
                    if not any(head(o) > head(e) and below(o, e) for o in left if o is not e)
                ),
                left[0],
            )
            ordered.append(pick)
            left.remove(pick)
        tiers.append(ordered)
        remaining = remaining[len(group) :]
    order = [e for t in tiers for e in t]
    tied = tiers[0]
    best = [e for e in tied if head(e) == head(by_score[0])]
    first_of = {e.name: order.index(t[0]) + 1 for t in tiers for e in t if len(t) > 1}
    group_of = {e.name: i for i, t in enumerate(tiers) for e in t}
    leader = order[0]
    rows = []
    for i, e in enumerate(order):
        m = _ownship(e, sid)
        above = None if i == 0 else _diff(sp.diff(order[i - 1], e, sid))
        vs_leader = None if i == 0 else _diff(sp.diff(leader, e, sid))
        rows.append(
            {
                "entry": e.name,
                "group": e.sub.group,
                "rank": i + 1,
                "shared_rank": order.index(tiers[group_of[e.name]][0]) + 1,
                "tie_group": group_of[e.name],
                "tie_group_size": len(tiers[group_of[e.name]]),
                "tied_with": first_of.get(e.name) if first_of.get(e.name) != i + 1 else None,
                "headline": score[e.name],
                "shown_seed": _metric(m.get(HEADLINE_METRIC)),
                "tie_break": _metric(m.get(TIE_BREAK)),
                "vs_above": above,
                "vs_leader": vs_leader,
                "metrics": {k: _metric(m.get(k)) for k in PAPER_FIVE},
            }
        )
    outside = [e for e in order if e not in tied]
    runner_up = outside[0] if outside else None
    base = next((e for e in entries if e.name == BASELINE), None)

    def vs_base(group: str) -> list[dict[str, Any]]:
        if base is None:
            return []
        rows = [
            {"entry": e.name, **_diff(sp.diff(base, e, sid)), "p": sp.diff(base, e, sid)["p"]}
            for e in order
            if e.sub.group == group
        ]
        # "k of the n entries are above / below the baseline" combines n tests: Holm
        for r, p in zip(rows, holm([r["p"] for r in rows]), strict=True):
            r["p_holm"] = p
            r["significant_holm"] = bool(p < ALPHA)
        return rows

    return {
        "scenario": sid,
        "metric": HEADLINE_METRIC,
        "tie_break": TIE_BREAK,
        "leader": leader.name,
        "tied": [e.name for e in tied],
        "tiers": [[e.name for e in t] for t in tiers],
        "rows": rows,
        "top_score": [e.name for e in best],
        "runner_up": None if runner_up is None else runner_up.name,
        "gap": None
        if runner_up is None
        else {"from": best[0].name, **_diff(sp.diff(best[0], runner_up, sid))},
        "baseline": None if base is None else base.name,
        "learned_vs_baseline": vs_base("learned"),
        "hybrid_vs_baseline": vs_base("hybrid"),
    }


HEADROOM_DIR = "headroom"
"""The folder of the leaderboard that holds the headroom planner's result
(:mod:`cdr_bench.evaluate.headroom`), ``<headline scenario>.json`` and its log."""


def headroom_path(lb_dir: Path, sid: str = HEADLINE_SCENARIO) -> Path:
    """Where the headroom planner's result on ``sid`` lives."""
    return lb_dir / HEADROOM_DIR / f"{sid}.json"


def headroom_data(
    path: Path, entries: list[Entry], ranking: dict[str, Any]
) -> dict[str, Any] | None:
    """The unranked headroom row: the planner's headline metrics on the ranking's episodes, and
    its paired difference with the baseline (McNemar's exact test on the same episodes) and with
    the top score. None when there is no such file; :class:`UserError` when it is not the
    planner's result on the very episodes of the ranking."""
    from cdr_bench.evaluate.compare import mcnemar_exact
    from cdr_bench.evaluate.headroom import NAME

    if not path.exists():
        return None
    sid = ranking["scenario"]
    try:
        result = read_result(path)
        episodes = read_episodes(path, result)
    except ValueError as e:
        raise UserError(str(e)) from None
    if result["agent"].get("name") != NAME or [s["id"] for s in result["scenarios"]] != [sid]:
        raise UserError(f"{path}: expected the headroom planner's result on {sid} alone")
    by_name = {e.name: e for e in entries}
    base = by_name.get(ranking["baseline"] or "") or by_name[ranking["leader"]]
    mine, theirs = result["scenarios"][0], base.scenario(sid) or {}
    same = (result["base_seed"], mine["config_hash"], mine["episodes"], mine["seeds_sha256"])
    if same != (
        base.result["base_seed"],
        theirs.get("config_hash"),
        theirs.get("episodes"),
        theirs.get("seeds_sha256"),
    ):
        raise UserError(
            f"{path}: not on the ranking's episodes of {sid} (base seed, configuration and "
            "episodes must be those of the entries); re-run `cdr-bench leaderboard headroom`"
        )
    a = episode_outcomes(episodes, path, sid, HEADLINE_METRIC)
    b = episode_outcomes(base.episodes, base.path, sid, HEADLINE_METRIC)
    better, worse = int(((a == 1) & (b == 0)).sum()), int(((a == 0) & (b == 1)).sum())
    m = mine["metrics"]["ownship"]
    top = ranking["rows"][0]
    return {
        "scenario": sid,
        "episodes": mine["episodes"],
        "base_seed": result["base_seed"],
        "metrics": {k: _metric(m.get(k)) for k in (HEADLINE_METRIC, *PAPER_FIVE, TIE_BREAK)},
        "vs_baseline": {
            "entry": base.name,
            "diff": _round(float(a.mean() - b.mean())),
            "better": better,
            "worse": worse,
            "p": mcnemar_exact(better, worse),
        },
        "vs_top": {
            "entry": top["entry"],
            "diff": _round(float(m[HEADLINE_METRIC]["value"]) - float(top["headline"]["value"])),
        },
    }


def fixed_geometry(scenario: dict[str, Any], base_seed: int) -> bool:
    """Whether every episode of a result's scenario starts from the identical simulator state
    (a fixed encounter flown many times) rather than a family drawn per episode. Decided by
    resetting the scenario's simulator with the episodes' seeds and comparing every state
    array: whatever the scenario's source of randomness, a fixed encounter is one whose
    episodes do not differ. The scenario is the registry's when its config hash is the
    result's, else rebuilt from the config the result holds (with this version's defaults for
    fields it lacks)."""
    import numpy as np

    from cdr_bench.evaluate.seeds import episode_seeds
    from cdr_bench.scenarios import load_scenario
    from cdr_bench.scenarios.schema import from_mapping
    from cdr_bench.sim.core import Simulator

    sid, chash = scenario["id"], scenario["config_hash"]
    cfg = None
    try:
        reg = load_scenario(sid)
        cfg = reg if reg.config_hash() == chash else None
    except Exception:  # noqa: BLE001 - a registry that moved on: the result's own config
        pass
    if cfg is None:
        try:
            cfg = from_mapping(scenario["config"], sid)
        except Exception as e:  # noqa: BLE001 - any schema problem is reported the same way
            raise UserError(
                f"scenario {sid}: the config in the result file does not load with this "
                f"cdr-bench ({type(e).__name__}: {str(e)[:200]}); re-evaluate with "
                "`cdr-bench leaderboard build --evaluate`"
            ) from None
    n = int(scenario["episodes"])
    seeds = episode_seeds(base_seed, sid, chash, 0, n)
    for count in (min(2, n), n):  # two episodes decide most scenarios
        sim = Simulator(cfg, count)
        sim.reset(seeds[:count])
        for arr in sim.state:
            a = np.asarray(arr)
            if a.ndim and a.shape[0] == count and not (a == a[:1]).all():
                return False
    return True


_OUTCOME_TEXT = {
    "nmac": "NMAC at step {steps}",
    "los": "LoS at step {steps}",
    "timeout": "timeout after {steps} steps",
    "boundary": "left the sector at step {steps}",
}


def outcome_text(rec: dict[str, Any]) -> str:
    """One flight's outcome in words: ``success``, ``success after a LoS``, ``LoS at step 7``."""
    if rec["outcome"] == "success":
        return "success after a LoS" if rec["los"] else "success"
    return _OUTCOME_TEXT.get(rec["outcome"], rec["outcome"] + " at step {steps}").format(
        steps=rec["steps"]
    )


def _ownship_records(e: Entry, sid: str) -> list[dict[str, Any]]:
    return [
        ac
        for ep in e.episodes
        if ep["scenario"] == sid
        for ac in ep["aircraft"]
        if ac["id"].startswith("ownship")
    ]


def tactical_cells(e: Entry, sid: str, fixed: bool) -> dict[str, Any]:
    """An entry's result on one tactical scenario: the success rate with its interval (a
    family), or the single outcome of a fixed encounter (or, for an agent that draws its
    actions, how often the repeated encounter succeeded, without an interval: the episodes
    differ only by the agent's own randomness)."""
    m = _ownship(e, sid)
    if not fixed:
        return {"kind": "rate", **_metric(m["success_rate"]), "n": m["episodes"]}
    recs = _ownship_records(e, sid)
    shapes = {(r["outcome"], r["steps"], bool(r["los"])) for r in recs}
    if len(shapes) == 1:
        return {"kind": "outcome", "text": outcome_text(recs[0]), "outcome": recs[0]["outcome"]}
    return {
        "kind": "varies",
        "success": m["success_rate"]["value"],
        "n": m["episodes"],
        "text": f"varies: success in {100 * m['success_rate']['value']:.0f} % of "
        f"{m['episodes']} runs",
    }


def _read_log(path: Path) -> list[dict[str, Any]]:
    """A training log, plain ``.jsonl`` or xz ``.jsonl.xz`` (:func:`log_text`)."""
    try:
        lines = log_text(path, "training log").splitlines()
        return [json.loads(x) for x in lines if x.strip()]
    except (ValueError, RecursionError) as e:  # json.JSONDecodeError is a ValueError
        raise UserError(f"{path}: cannot read the training log ({e})") from None


def training_info(
    sub: Submission, root: Path
) -> tuple[dict[str, Any] | None, list[Any], list[Any]]:
    """``(budget, curves, fixed)`` of an entry: the transitions and seeds of its training (from
    the ``final`` lines of its logs, else as declared; ``None`` for a scripted entry); per log,
    its rolling training success against transitions; and per log that has them, the clean
    success of its greedy policy on the fixed evaluation set (the trainers' ``curve/`` lines)
    against transitions."""
    if sub.group == "scripted":
        return None, [], []
    finals, curves, fixed = [], [], []
    for rel in sub.training_logs:
        rows = _read_log(root / rel)
        fin = [r["final"] for r in rows if "final" in r]
        if not fin or not isinstance(fin[-1].get("step"), int):
            raise UserError(f"{root / rel}: no final line with 'step' (an unfinished log?)")
        finals.append(fin[-1]["step"])
        curves.append(
            [
                [r["step"], round(float(r["charts/success_rolling"]), 4)]
                for r in rows
                if "step" in r and r.get("charts/success_rolling") is not None
            ]
        )
        points = [
            [r["step"], round(float(r["curve/clean_success"]), 4)]
            for r in rows
            if isinstance(r.get("step"), int) and r.get("curve/clean_success") is not None
        ]
        if points:
            fixed.append(points)
    if finals:
        transitions: int | list[int] | None = (
            finals[0] if len(set(finals)) == 1 else [min(finals), max(finals)]
        )
        budget = {"transitions": transitions, "seeds": len(finals), "source": "training logs"}
        if sub.budget is not None and (
            len(set(finals)) != 1 or sub.budget != (finals[0], len(finals))
        ):
            raise UserError(
                f"{sub.source}: budget {{transitions: {sub.budget[0]}, seeds: {sub.budget[1]}}} "
                f"but its training logs give {transitions} transitions, {len(finals)} seed(s)"
            )
    elif sub.budget is not None:
        budget = {"transitions": sub.budget[0], "seeds": sub.budget[1], "source": "declared"}
    else:
        budget = {"transitions": None, "seeds": None, "source": None}
    return budget, curves, fixed


def total_transitions(budget: dict[str, Any] | None) -> int | list[int] | None:
    """An entry's training transitions, its parent's included (:func:`add_parent_budgets`)."""
    t = (budget or {}).get("transitions")
    p = (budget or {}).get("parent_transitions")
    return t + p if isinstance(t, int) and isinstance(p, int) else t


def add_parent_budgets(entries: list[Entry], info: dict[str, Any]) -> None:
    """An entry whose seeds continue another entry's run (``parent: NAME seed K``) trained for
    its parent's transitions too: ``budget["parent_transitions"]`` is the parent entry's (when
    every seed names one parent of a known budget), so the pages can show the total."""
    for e in entries:
        budget = info[e.name][0]
        parents = {s.parent for s in e.sub.seeds}
        if not budget or not isinstance(budget.get("transitions"), int) or None in parents:
            continue
        names = {str(p).split(" seed ")[0].strip() for p in parents}
        if len(names) != 1 or (name := names.pop()) not in info:
            continue
        pb = info[name][0] or {}
        if isinstance(pb.get("transitions"), int):
            budget["parent_transitions"] = pb["transitions"]
            budget["parent"] = name


SEED_METRIC = "clean_success_rate"
"""The score aggregated over training seeds (the headline metric)."""


def _runs(e: Entry) -> list[tuple[int | None, Entry]]:
    return e.runs or [(None, e)]


def _seed_counts(e: Entry, sids: list[str]) -> tuple[Any, int]:
    """Counts ``(runs, tasks)`` of :data:`SEED_METRIC` (the ownship) and their common ``n``."""
    import numpy as np

    k, ns = [], set()
    for _, run in _runs(e):
        row = []
        for sid in sids:
            sc = run.scenario(sid)
            assert sc is not None
            m = sc["metrics"]["ownship"][SEED_METRIC]
            row.append(int(m["count"]))
            ns.add(int(m["n"]))
        k.append(row)
    if len(ns) != 1:
        raise UserError(f"{e.path}: episode counts {sorted(ns)} differ between scenarios or seeds")
    return np.array(k, dtype=np.int64), ns.pop()


def _fixed_runs(e: Entry, info: tuple[Any, list[Any], list[Any]]) -> list[tuple[Any, int]]:
    """``(fixed-set curve, transitions)`` of each seed whose log has one (the claims' DPSC
    convergence): the transitions of a seed are its curve's last step at least, and its
    log's final step when all seeds trained the same number."""
    budget, _, fixed = info
    total = budget["transitions"] if budget and isinstance(budget["transitions"], int) else None
    return [(c, max(int(c[-1][0]), total or 0)) for c in fixed if c]


def seed_aggregates(
    entries: list[Entry],
    order: list[str],
    headline: str,
    comparators: tuple[str, ...],
    fixed: dict[str, bool],
    paired: SeedPaired,
) -> dict[str, Any]:
    """Aggregates over training seeds (:mod:`cdr_bench.evaluate.aggregate`, rliable's
    recommendations with the episode noise added): per entry the headline score of every seed,
    the ranked score over its units (mean up to four, IQM beyond; seeds sharing a parent are one
    unit) with its two-level interval (:meth:`SeedPaired.score`), the IQM over the tasks (every
    scenario all entries share but fixed encounters; two-level stratified interval), and the
    probability of improvement over each comparator on those tasks (two-level interval)."""
    by_name = {e.name: e for e in entries}
    tasks = [
        s["id"]
        for s in entries[0].result["scenarios"]
        if all(e.scenario(s["id"]) is not None for e in entries) and not fixed[s["id"]]
    ]
    comps = [c for c in comparators if c in by_name]

    def task_units(e: Entry) -> list[aggregate.Units]:
        units = _units(e)
        out = []
        for sid in tasks:
            out.append(
                [[int(r.scenario(sid)["metrics"]["ownship"][SEED_METRIC]["count"])  # type: ignore[index]
                  for r in u] for u in units]
            )  # fmt: skip
        return out

    rows = []
    for name in order:
        e = by_name[name]
        kh, n = _seed_counts(e, [headline])
        kt, nt = _seed_counts(e, tasks)
        seeds = [s for s, _ in _runs(e)]
        poi = {}
        for c in comps:
            if c == name:
                continue
            _, nc = _seed_counts(by_name[c], tasks)
            if nc != nt:
                raise UserError(f"{e.path}: {nt} episodes per scenario, {c} has {nc}")
            value, ci = aggregate.probability_of_improvement_two_level(
                task_units(e), task_units(by_name[c]), nt
            )
            poi[c] = {"value": round(value, 6), "ci95": [round(v, 6) for v in ci]}
        sc = paired.score(e, headline)
        head: dict[str, Any] = dict(aggregate.summary(kh, n))
        head.update(score=sc["value"], ci95=sc["ci95"], aggregate=sc["aggregate"])
        rows.append(
            {
                "entry": name,
                "seeds": seeds,
                "units": [[s for s, r in _runs(e) if any(r is x for x in u)] for u in _units(e)],
                "headline": head,
                "tasks": aggregate.summary(kt, nt, episodes=True),
                "p_improvement": poi,
            }
        )
    return {
        "metric": SEED_METRIC,
        "scenario": headline,
        "tasks": tasks,
        "comparators": comps,
        "resamples": aggregate.RESAMPLES,
        "mean_up_to": aggregate.MEAN_UP_TO,
        "rows": rows,
    }


def entry_facts(e: Entry) -> dict[str, Any]:
    """What the pages show of an entry beside its numbers: its submission and its result's
    provenance."""
    return {
        "name": e.name,
        "display_name": e.sub.display_name,
        "description": e.sub.description,
        "trained_on": e.sub.trained_on,
        "group": e.sub.group,
        "agent": e.sub.agent,
        "checkpoint": e.sub.checkpoint,
        "authors": list(e.sub.authors),
        "reference": e.sub.reference,
        "training": e.sub.training,
        "training_logs": list(e.sub.training_logs),
        "published_as": list(e.sub.published_as),
        "agent_sha256": e.result["agent"]["sha256"],
        "result_file": f"results/{e.path.name}",
        "base_seed": e.result["base_seed"],
        "batch_size": e.result["batch_size"],
        "cdr_bench_version": e.result["versions"].get("cdr-bench"),
    }


LATENCY_FILE = "latency.json"
"""``<leaderboard>/latency.json``: every single-agent entry's decision latency measured in one
controlled run (``python benchmarks/latency.py --json leaderboard/latency.json``: one after the
other, one thread, nothing else running, the conditions recorded in it)."""


def load_latency(lb_dir: Path) -> dict[str, float]:
    """Entry -> median ms of one decision per call, from :data:`LATENCY_FILE` (empty without
    it); a :class:`UserError` naming the file and field for anything else."""
    path = Path(lb_dir) / LATENCY_FILE
    if not path.exists():
        return {}
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise UserError(f"{path}: cannot read ({e})") from None
    rows = d.get("rows") if isinstance(d, dict) else None
    if not isinstance(rows, list):
        raise UserError(f"{path}: expected an object with a list 'rows'")
    out: dict[str, float] = {}
    for i, r in enumerate(rows):
        med = r.get("single_ms", {}).get("median") if isinstance(r, dict) else None
        if not isinstance(r.get("entry") if isinstance(r, dict) else None, str) or not (
            isinstance(med, (int, float)) and math.isfinite(med) and med > 0
        ):
            raise UserError(
                f"{path}: rows[{i}]: expected an entry name and single_ms.median, a positive "
                "number of ms"
            )
        out[r["entry"]] = float(med)
    return out


def build_data(
    entries: list[Entry],
    published: Published,
    reference: str = DEFAULT_REFERENCE,
    sensitivity: dict[str, Any] | None = None,
    latency: dict[str, float] | None = None,
) -> dict[str, Any]:
    """Everything the pages show, as one JSON-able dict (deterministic: no timestamps). The
    recorded trajectories are not in it (they are drawn by ``index.html`` from the replay
    files); ``replays`` says which exist. ``sensitivity``: the study of
    :func:`cdr_bench.leaderboard.sensitivity.load_study` (None: no such section);
    ``latency``: :func:`load_latency` (the latency claim; none without it)."""
    by_name = {e.name: e for e in entries}
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

    paired = Paired()
    vs_ref: dict[str, dict[tuple[str, str], dict[str, Any]]] = {}
    for e in entries:
        if e is ref:
            continue
        shared = [s for s in e.result["scenarios"] if ref.scenario(s["id"]) is not None]
        if len(shared) != len(e.result["scenarios"]) or len(shared) != len(ref.result["scenarios"]):
            raise UserError(
                f"{e.name}: scored on other scenarios than the reference {reference}; "
                "paired comparison needs the same scenarios"
            )
        vs_ref[e.name] = paired.all(ref, e)

    ranking = rank_entries(entries, paired)
    rank_of = {r["entry"]: r["rank"] for r in ranking["rows"]}
    base_seed = ref.result["base_seed"]

    tables = []
    fixed_of: dict[str, bool] = {}
    for sid in scenario_ids:
        rows = []
        config = None
        first = None
        for e in sorted(entries, key=lambda x: rank_of[x.name]):
            s = e.scenario(sid)
            if s is None:
                continue
            first = first or s
            config = s["config"]
            m = s["metrics"]["ownship"]
            lat = e.result["timing"]["decision_latency"][sid]["per_decision_ms"]
            vs: dict[str, Any] = {}
            for key in (c.key for c in MAIN_COLUMNS):
                if e is ref:
                    vs[key] = "reference"
                    continue
                r = vs_ref[e.name][(sid, key)]
                vs[key] = {
                    **_diff(r),
                    "direction": (
                        ("higher" if r["diff"] > 0 else "lower") if r["significant"] else "same"
                    ),
                }
            rows.append(
                {
                    "entry": e.name,
                    "rank": rank_of[e.name],
                    "episodes": m["episodes"],
                    "metrics": {c.key: _metric(m.get(c.key)) for c in COLUMNS},
                    "latency_ms": {"median": lat["median"], "p99": lat["p99"]},
                    "vs_reference": vs,
                }
            )
        assert config is not None and first is not None
        fixed_of[sid] = fixed_geometry(first, base_seed)
        best: dict[str, list[str]] = {}
        for c in MAIN_COLUMNS:
            best[c.key] = (
                _best([(r["entry"], r["metrics"][c.key]["value"]) for r in rows], c.higher)
                if c.key in MARK_BEST
                else []
            )
        best["latency_ms"] = _best([(r["entry"], r["latency_ms"]["median"]) for r in rows], False)
        tables.append(
            {
                "scenario": sid,
                "description": config.get("description", ""),
                "episodes": rows[0]["episodes"],
                "fixed": fixed_of[sid],
                "rows": rows,
                "best": best,
            }
        )

    tactical = [
        {
            "scenario": sid,
            "fixed": fixed_of[sid],
            "cells": {
                e.name: tactical_cells(e, sid, fixed_of[sid])
                for e in sorted(entries, key=lambda x: rank_of[x.name])
                if e.scenario(sid) is not None
            },
        }
        for sid in scenario_ids
        if sid.startswith(TACTICAL_PREFIX)
    ]

    side_by_side = []
    for e, row in ((x, row) for x in entries for row in x.sub.published_as):
        for sid in DENSITIES:
            pub = published.lookup(row, sid)
            s = e.scenario(sid)
            if pub is None or s is None:
                continue
            m = s["metrics"]["ownship"]
            side_by_side.append(
                {
                    "entry": e.name,
                    "published_as": row,
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

    info = {}
    for e in entries:
        root = e.sub.source.resolve().parent.parent.parent
        info[e.name] = training_info(e.sub, root)
    add_parent_budgets(entries, info)

    replay_entries = [e for e in sorted(entries, key=lambda x: rank_of[x.name]) if e.replays]
    replay_scenarios = [
        sid for sid in scenario_ids if any(sid in e.sub.replays for e in replay_entries)
    ]
    return {
        "data_version": DATA_VERSION,
        "reference": reference,
        "scenarios": scenario_ids,
        "groups": [*GROUPS, "published"],
        "entries": [entry_facts(e) | {"budget": info[e.name][0]} for e in entries],
        "ranking": ranking,
        "seeds": seed_aggregates(
            entries,
            [r["entry"] for r in ranking["rows"]],
            ranking["scenario"],
            (BASELINE, reference),
            fixed_of,
            paired.seeds,
        ),
        "claims": build_claims(
            {row: e for e in entries for row in e.sub.published_as},
            paired,
            published,
            {
                (e.name, sc): d["families_mean"]
                for e in entries
                for sc, d in e.multimodal.items()
                if d.get("families_mean") is not None
            },
            latency or {},
            sensitivity,
            {e.name: _fixed_runs(e, info[e.name]) for e in entries},
            {e.name: total_transitions(info[e.name][0]) for e in entries},
            {e.name: e.multimodal_seeds for e in entries if e.multimodal_seeds},
        ),
        "sensitivity": sensitivity,
        "tables": tables,
        "tactical": tactical,
        "published_vs_measured": side_by_side,
        "learning_curves": [
            {
                "entry": e.name,
                "logs": list(e.sub.training_logs),
                "series": info[e.name][1],
                "fixed": info[e.name][2],
            }
            for e in entries
            if info[e.name][1]
        ],
        "replays": {
            "entries": [e.name for e in replay_entries],
            "scenarios": replay_scenarios,
            "episodes": max(
                (int((e.replays or {})["episodes"]) for e in replay_entries), default=0
            ),
            "files": {e.name: f"results/{e.name}.replays.json" for e in replay_entries},
        },
        "multimodality": [
            {
                "entry": e.name,
                "scenario": sc,
                "samples": d["samples"],
                "episodes": d.get("episodes", 1),
                "families_mean": d.get("families_mean"),
                "families_distribution": d.get("families_distribution"),
                "feasible_families_mean": d.get("feasible_families_mean"),
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


def load_replays(path: Path, sub: Submission) -> dict[str, Any]:
    """A submission's recorded trajectories (``<name>.replays.json``, written by the trusted
    scorer), checked for shape; :class:`UserError` naming the file otherwise."""
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as e:
        raise UserError(f"{path}: not a replays file ({e})") from None
    if not isinstance(d, dict) or d.get("kind") != "cdr-bench replays":
        raise UserError(f"{path}: expected the replays of `cdr-bench leaderboard build`")
    traces = d.get("traces")
    if not isinstance(traces, dict) or sorted(traces) != sorted(sub.replays):
        raise UserError(
            f"{path}: traces of {sorted(traces) if isinstance(traces, dict) else traces}, "
            f"{sub.source.name} replays {list(sub.replays)}; re-evaluate: "
            f"cdr-bench leaderboard build --evaluate {sub.name}"
        )
    keys = ("episode", "seed", "dt_s", "size_km", "los_km", "ids", "goals_km", "frames", "outcomes")
    for sc, eps in traces.items():
        if not isinstance(eps, list) or not eps:
            raise UserError(f"{path}: {sc}: expected a list of recorded episodes")
        for i, t in enumerate(eps):
            if not isinstance(t, dict) or any(k not in t for k in keys):
                raise UserError(f"{path}: {sc}[{i}]: expected {', '.join(keys)}")
            if t["episode"] != i or not t["frames"]:
                raise UserError(f"{path}: {sc}[{i}]: expected episode {i} with frames")
    return d
