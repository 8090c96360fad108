"""The multi-agent track: entries that fly every controlled aircraft, scored as a system.

**Headline score** (:data:`HEADLINE_METRIC` on :data:`HEADLINE_SCENARIO`): the share of clean
flights - controlled flights that reach their goal with no loss of separation at all - at
``high`` density with every aircraft controlled (docs/model.md §10.1.3 says why). Its unit of
independence is the episode: the flights of one episode share their sky, so intervals resample
whole episodes. Over training seeds the score is the mean over the entry's units (seeds that
share a parent are one unit) of each run's ratio Σ clean flights / Σ flights, with a two-level
95 % percentile bootstrap: per resample the units drawn with replacement, then the episodes
(the same episode positions for every run of every entry, so differences stay paired). Every
sum is of integers, so the numbers are the same bits on every CPU.

**Ranking**: by that score; a tie group is the best remaining score and the entries after it
down to the first one whose paired difference from that best is significantly below 0, as in
the single-agent ranking (:mod:`cdr_bench.leaderboard.data`). Beside it: LoS and NMAC per
flight hour over every aircraft pair and the other system metrics of the shown seed, and the
paired difference from MVP for every aircraft (:data:`BASELINE`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from cdr_bench.errors import UserError
from cdr_bench.evaluate.metrics import BOOTSTRAP_SEED, SYSTEM_METRICS, get_metric
from cdr_bench.leaderboard.page_tables import signed
from cdr_bench.leaderboard.submission import TRACK_HEADLINE

if TYPE_CHECKING:
    from cdr_bench.leaderboard.data import Entry

HEADLINE_SCENARIO = TRACK_HEADLINE["multi-agent"]
HEADLINE_METRIC = "system_clean_rate"
BASELINE = "mvp-all"
"""The entry every other is compared with: MVP run by every aircraft, each resolving alone."""
RESAMPLES = 10_000
"""Bootstrap resamples of the two-level intervals."""
SHOWN = (
    "system_clean_rate",
    "system_los_per_flight_hour",
    "system_nmac_per_flight_hour",
    "system_success_rate",
    "system_clean_episode_rate",
    "system_delay_s",
    "system_extra_path_km",
    "system_manoeuvres",
    "system_delay_spread_s",
)
"""The system metrics of the per-scenario tables, in column order."""


def _pairs(run: Entry, sid: str) -> NDArray[np.int64]:
    """``(episodes, 2)``: clean flights and flights of each episode of ``sid`` (file order)."""
    m = get_metric(HEADLINE_METRIC)
    rows = [m.paired(ep["aircraft"]) for ep in run.episodes if ep["scenario"] == sid]
    return np.asarray(rows, dtype=np.float64).round().astype(np.int64).reshape(-1, 2)


def _units(e: Entry) -> list[list[Entry]]:
    from cdr_bench.leaderboard.data import _units as units

    return units(e)


def _weights(n: int, reps: int, seed: int) -> NDArray[np.int64]:
    """``(reps, n)``: how often each episode is drawn in each resample."""
    idx = np.random.default_rng(seed).integers(0, n, (reps, n))
    flat = (np.arange(reps, dtype=np.int64)[:, None] * n + idx).ravel()
    return np.bincount(flat, minlength=reps * n).reshape(reps, n)


class Scores:
    """Headline scores and paired differences over seeds, each computed once; one episode
    resampling (:func:`_weights`) shared by every run, so that differences stay paired."""

    def __init__(self, n: int, reps: int = RESAMPLES, seed: int = BOOTSTRAP_SEED) -> None:
        self.n, self.reps = n, reps
        self.w = _weights(n, reps, seed)
        self.seed = seed
        self._pairs: dict[str, list[list[NDArray[np.int64]]]] = {}

    def units(self, e: Entry) -> list[list[NDArray[np.int64]]]:
        if e.name not in self._pairs:
            got = [[_pairs(r, HEADLINE_SCENARIO) for r in u] for u in _units(e)]
            for u in got:
                for p in u:
                    if p.shape[0] != self.n:
                        raise UserError(
                            f"{e.path}: {p.shape[0]} episodes of {HEADLINE_SCENARIO}, the other "
                            f"multi-agent entries have {self.n}"
                        )
            self._pairs[e.name] = got
        return self._pairs[e.name]

    def _point(self, e: Entry) -> float:
        per_unit = [np.mean([p[:, 0].sum() / p[:, 1].sum() for p in u]) for u in self.units(e)]
        return float(np.mean(per_unit))

    def _resampled(self, e: Entry, rng: np.random.Generator) -> NDArray[np.float64]:
        """``(reps,)``: the score of each resample (units drawn with ``rng``, then episodes)."""
        units = self.units(e)
        # per run, the resampled ratio: integer sums, then one division
        per_run = [[(self.w @ p[:, 0]) / np.maximum(self.w @ p[:, 1], 1) for p in u] for u in units]
        unit_means = np.stack([np.mean(np.stack(r), axis=0) for r in per_run])  # (units, reps)
        pick = rng.integers(0, len(units), (self.reps, len(units)))
        return unit_means[pick, np.arange(self.reps)[:, None]].mean(axis=1)

    def score(self, e: Entry) -> dict[str, Any]:
        rng = np.random.default_rng([self.seed, 1])
        r = self._resampled(e, rng)
        lo, hi = np.percentile(r, [2.5, 97.5])
        units = self.units(e)
        return {
            "value": round(self._point(e), 6),
            "ci95": [round(float(lo), 6), round(float(hi), 6)],
            "seeds": sum(len(u) for u in units),
            "units": len(units),
        }

    def diff(self, a: Entry, b: Entry) -> dict[str, Any]:
        """b - a, averaged over seeds, with its paired two-level 95 % interval."""
        rng = np.random.default_rng([self.seed, 2])
        ra, rb = self._resampled(a, rng), self._resampled(b, rng)
        d = rb - ra
        lo, hi = np.percentile(d, [2.5, 97.5])
        value = self._point(b) - self._point(a)
        return {
            "diff": round(value, 6),
            "ci95": [round(float(lo), 6), round(float(hi), 6)],
            "significant": bool(lo > 0 or hi < 0),
        }


def _system(e: Entry, sid: str) -> dict[str, Any]:
    s = e.scenario(sid)
    if s is None or s.get("system_metrics") is None:
        raise UserError(f"{e.path}: no system metrics on {sid} (one controlled aircraft?)")
    return s["system_metrics"]  # type: ignore[no-any-return]


def track_data(entries: list[Entry]) -> dict[str, Any] | None:
    """Everything the pages show of the multi-agent track (None: no entry in it)."""
    from cdr_bench.leaderboard.data import entry_facts

    if not entries:
        return None
    missing = [e.name for e in entries if e.scenario(HEADLINE_SCENARIO) is None]
    if missing:
        raise UserError(
            f"multi-agent entries {', '.join(missing)} are not scored on {HEADLINE_SCENARIO}, "
            "the track's headline scenario"
        )
    n = int(_system(entries[0], HEADLINE_SCENARIO)["episodes"])
    sc = Scores(n)
    score = {e.name: sc.score(e) for e in entries}
    by_name = {e.name: e for e in entries}
    order = sorted(entries, key=lambda e: (-score[e.name]["value"], e.name))
    # tie groups, as in the single-agent ranking
    ranks: dict[str, str] = {}
    above: dict[str, dict[str, Any] | None] = {}
    i = 0
    while i < len(order):
        lead = order[i]
        group = [lead]
        j = i + 1
        while j < len(order) and not sc.diff(lead, order[j])["significant"]:
            group.append(order[j])
            j += 1
        label = f"{i + 1}=" if len(group) > 1 else str(i + 1)
        for g in group:
            ranks[g.name] = label
        i = j
    for k, e in enumerate(order):
        above[e.name] = None if k == 0 else sc.diff(order[k - 1], e)
    base = by_name.get(BASELINE)
    vs_base = {e.name: (sc.diff(base, e) if base is not None and e is not base else None)
               for e in order}  # fmt: skip

    scenario_ids: list[str] = []
    for e in entries:
        for s in e.result["scenarios"]:
            if s["id"] not in scenario_ids:
                scenario_ids.append(s["id"])
    tables = []
    for sid in scenario_ids:
        rows = []
        for e in order:
            s = e.scenario(sid)
            if s is None:
                continue
            sm = _system(e, sid)
            rows.append(
                {
                    "entry": e.name,
                    "rank": ranks[e.name],
                    "episodes": sm["episodes"],
                    "flights": sm["flights"],
                    "metrics": {k: {"value": sm[k]["value"], "ci95": sm[k]["ci95"]} for k in SHOWN},
                }
            )
        cfg = next(e.scenario(sid) for e in order if e.scenario(sid) is not None)
        tables.append(
            {
                "scenario": sid,
                "description": (cfg or {}).get("config", {}).get("description", ""),
                "rows": rows,
            }
        )
    return {
        "scenario": HEADLINE_SCENARIO,
        "metric": HEADLINE_METRIC,
        "baseline": BASELINE if base is not None else None,
        "resamples": RESAMPLES,
        "episodes": n,
        "metrics": {k: get_metric(k).header for k in SHOWN},
        "higher": {k: get_metric(k).higher for k in SHOWN},
        "entries": [entry_facts(e) for e in order],
        "ranking": [
            {
                "entry": e.name,
                "rank": ranks[e.name],
                "group": e.sub.group,
                "acting": e.result.get("acting", "decentralised"),
                "score": score[e.name],
                "vs_above": above[e.name],
                "vs_top": None if e is order[0] else sc.diff(order[0], e),
                "vs_baseline": vs_base[e.name],
                "side": {
                    k: _system(e, HEADLINE_SCENARIO)[k]["value"]
                    for k in (
                        "system_los_per_flight_hour",
                        "system_nmac_per_flight_hour",
                        "system_delay_s",
                    )
                },
            }
            for e in order
        ],
        "tables": tables,
        "system_metrics": [m.key for m in SYSTEM_METRICS],
    }


def _pct(x: float) -> str:
    return f"{100 * x:.1f} %"


def _pp(d: dict[str, Any]) -> str:
    lo, hi = d["ci95"]
    return f"{signed(100 * d['diff'])} points [{signed(100 * lo)}, {signed(100 * hi)}]"


def conclusion(track: dict[str, Any], names: dict[str, str]) -> list[str]:
    """The track's one-minute summary, generated from its data."""
    rows = track["ranking"]
    sid = track["scenario"]
    top = rows[0]
    out = [
        f"With every aircraft controlled on `{sid}`, {names[top['entry']]} has the most clean "
        f"flights: {_pct(top['score']['value'])} [{_pct(top['score']['ci95'][0])}, "
        f"{_pct(top['score']['ci95'][1])}], with "
        f"{top['side']['system_los_per_flight_hour']:.3g} losses of separation per flight hour."
    ]
    base = track["baseline"]
    if base is None:
        return out
    learned = [r for r in rows if r["group"] in ("learned", "hybrid") and r["entry"] != base]
    others = [r for r in rows if r["entry"] != base and r["vs_baseline"] is not None]
    if learned:
        best = learned[0]
        d = best["vs_baseline"]
        verdict = (
            "learning beats MVP here"
            if d["significant"] and d["diff"] > 0
            else (
                "learning does not beat MVP here"
                if not d["significant"]
                else "learning is significantly below MVP here"
            )
        )
        out.append(
            f"The best learned entry, {names[best['entry']]}, differs from "
            f"{names[base]} by {_pp(d)} in clean flights (paired over the same episodes, two-level "
            f"bootstrap over seeds and episodes): {verdict}."
        )
        b = next(r for r in rows if r["entry"] == base)
        los, los_b = (x["side"]["system_los_per_flight_hour"] for x in (best, b))
        delay, delay_b = (x["side"]["system_delay_s"] for x in (best, b))
        fewer = "fewer" if los < los_b else "more" if los > los_b else "as many"
        than = "as" if fewer == "as many" else "than"
        out.append(
            f"Per flight hour it has {fewer} losses of separation {than} {names[base]} "
            f"({los:.3g} vs {los_b:.3g}), and its successful flights take {delay:+.0f} s against "
            f"the direct time ({names[base]}: {delay_b:+.0f} s): a share of clean flights also "
            "rises when flights are shorter."
        )
        if best is not top and top["group"] not in ("learned", "hybrid"):
            lead = best["vs_top"]  # best - top
            ahead = {"diff": -lead["diff"], "ci95": [-lead["ci95"][1], -lead["ci95"][0]]}
            out.append(f"The top entry, {names[top['entry']]}, is ahead of it by {_pp(ahead)}.")
    for r in others:
        if r in learned[:1]:
            continue
        d = r["vs_baseline"]
        sig = "significant" if d["significant"] else "not significant"
        out.append(f"{names[r['entry']]} vs {names[base]}: {_pp(d)} ({sig}).")
    return [out[0], " ".join(out[1:])] if len(out) > 1 else out


# ----------------------------------------------------------------------------------------------
# Pages

TRACK_NOTE = (
    "Every aircraft of the sector is controlled by the entry, acting *decentralised* (the agent "
    "decides for each aircraft on that aircraft's own observation) or *joint* (the agent sees "
    "the observations of every controlled aircraft of an episode at once and decides for them "
    'together: `act_joint`, CONTRIBUTING.md "Add an agent"); docs/model.md §8.4. '
    "**Headline score: the "
    "share of clean flights on `{sc}`** - controlled flights that reach their goal with no loss "
    "of separation at all - over the entry's training seeds (the mean of its seeds; seeds sharing "
    "a parent count as one), with a two-level bootstrap interval (seeds, then whole episodes: the "
    "flights of one episode share their sky and are not independent). Beside it, from the seed "
    "the entry shows: losses of separation and NMACs per flight hour over every aircraft pair, "
    "and the paired difference from {base} on the same episodes (▲/▼ when significant). A tie "
    "group shares a rank (`2=`) as in the single-agent ranking. {n} episodes per scenario; the "
    "system metrics are defined in docs/model.md §10.1.3."
)


def _names(track: dict[str, Any]) -> dict[str, str]:
    from cdr_bench.leaderboard.text import md_text

    return {e["name"]: md_text(e["display_name"]) for e in track["entries"]}


def note(track: dict[str, Any]) -> str:
    base = _names(track).get(track["baseline"] or "", "MVP for every aircraft")
    return TRACK_NOTE.format(sc=track["scenario"], base=base, n=track["episodes"])


def ranking_table(track: dict[str, Any]) -> tuple[list[str], Any, list[str]]:
    from cdr_bench.evaluate.report import Cell, fmt_metric
    from cdr_bench.leaderboard.page_tables import fmt_diff

    names = _names(track)
    head = [
        "#",
        "entry",
        "group",
        "acting",
        f"clean flights ({track['scenario']})",
        "vs row above",
        f"vs {names.get(track['baseline'] or '', 'MVP')}",
        "LoS / flight h",
        "NMAC / flight h",
        "seeds",
    ]
    rows, groups = [], []
    for r in track["ranking"]:
        s = r["score"]
        label = fmt_metric("rate", s) + (f", mean of {s['seeds']} seeds" if s["seeds"] > 1 else "")
        rows.append(
            [
                Cell(r["rank"], sort=int(r["rank"].rstrip("="))),
                Cell(names[r["entry"]]),
                Cell(r["group"]),
                Cell(r["acting"]),
                Cell(label, sort=s["value"]),
                Cell(fmt_diff("rate", r["vs_above"])),
                Cell(fmt_diff("rate", r["vs_baseline"]) if r["vs_baseline"] else "reference"),
                Cell(f"{r['side']['system_los_per_flight_hour']:.3g}"),
                Cell(f"{r['side']['system_nmac_per_flight_hour']:.3g}"),
                Cell(str(s["seeds"]) if s["seeds"] > 1 else "-"),
            ]
        )
        groups.append(r["group"])
    return head, rows, groups


def scenario_table(track: dict[str, Any], t: dict[str, Any]) -> tuple[list[str], Any]:
    from cdr_bench.evaluate.metrics import get_metric
    from cdr_bench.evaluate.report import Cell, fmt_metric

    names = _names(track)
    head = ["#", "entry", "flights", *(track["metrics"][k] for k in SHOWN)]
    rows = []
    for r in t["rows"]:
        rows.append(
            [
                Cell(r["rank"]),
                Cell(names[r["entry"]]),
                Cell(str(r["flights"])),
                *(Cell(fmt_metric(get_metric(k).aggregate, r["metrics"][k])) for k in SHOWN),
            ]
        )
    return head, rows
