"""The metrics of docs/model.md §10 from per-episode logs, with 95 % intervals.

Input: per-aircraft episode records (one dict per aircraft and episode, as written to the
per-episode JSONL) with ``outcome`` (``success``, ``nmac``, ``los``, ``boundary``, ``timeout``),
``steps`` (steps flown = decisions made), ``los`` (at least one LoS during the episode; an NMAC
is also a LoS), ``nmac``, ``goal_reward`` / ``safety_reward`` (episode sums of R_G / R_S) and
``invalid_actions``.

* Outcome rates (``success``, ``nmac``, ``los_terminated``, ``boundary``, ``timeout``) partition
  the episodes: they sum to 1. ``success`` is the paper's success rate (goal without NMAC and,
  where a LoS ends the episode, without LoS).
* ``los_rate``: episodes with >= 1 LoS, whatever the outcome (the paper's LoS rate).
* ``clean_success_rate``: goal reached with no LoS at all.
* ``avg_steps_success``: mean steps of successful episodes.
* ``goal_reward`` / ``safety_reward``: mean episode sums.
* ``invalid_action_rate``: masked actions / decisions.

Field metrics (records of schema 3 also carry ``los_events``, ``los_s``, ``nmac_events``,
``conflicts``, ``manoeuvres``, ``flight_s``, ``path_km``, ``direct_km``, ``direct_s`` and
``severity``; docs/model.md §10.1 defines each):

* per flight: ``los_events``, ``los_time_s``, ``conflicts``, ``manoeuvres`` (means);
* ``intrusion_severity``: mean of ``severity`` = 1 - min separation / LoS threshold over the
  flights with a LoS;
* ``extra_path_km`` and ``delay_s``: means over successful flights of ``path_km - direct_km``
  and ``flight_s - direct_s``;
* ``nmac_per_flight_hour``: NMAC events / flight hours, with the Poisson score interval.

Intervals: Wilson score (z = 1.96) for rates, percentile bootstrap (2000 resamples, fixed seed,
so deterministic) for means. For learning intruders every aircraft-episode counts as one trial.

**One registry.** Each metric is one :class:`Metric` in :data:`METRICS`: its key, the
per-record fact it reads, its aggregate (rate with the Wilson interval, mean with the bootstrap
interval, Poisson rate per flight hour), its direction, its headers and number format, and
whether it is a detail column. Everything else reads it: :func:`group_metrics` (so every result
read), the tables of :mod:`cdr_bench.evaluate.report` (``COLUMNS``) and of the leaderboard
(``MAIN_COLUMNS``, thence its pages and ``leaderboard.json``), the paired comparison of
:mod:`cdr_bench.evaluate.compare` (:meth:`Metric.paired`) and the trainers' quick evaluation
(:meth:`Metric.point`). :func:`register_metric` adds one at run time over facts already in the
records; no result file changes (files hold facts, metrics are computed when read).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, overload

import numba
import numpy as np
from numpy.typing import NDArray

Z95 = 1.959963984540054
BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_SEED = 20240611
OUTCOMES = ("success", "nmac", "los", "boundary", "timeout")
RATE_KEYS = {
    "success": "success_rate",
    "nmac": "nmac_rate",
    "los": "los_terminated_rate",
    "boundary": "boundary_rate",
    "timeout": "timeout_rate",
}
PAPER_FIVE = ("success_rate", "los_rate", "nmac_rate", "timeout_rate", "avg_steps_success")


def wilson_interval(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion k / n (``(nan, nan)`` when n = 0)."""
    if n <= 0:
        return (math.nan, math.nan)
    p = k / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    lo = 0.0 if k == 0 else max(0.0, centre - half)  # exact bounds at 0 and n
    hi = 1.0 if k == n else min(1.0, centre + half)
    return (lo, hi)


def bootstrap_mean_interval(
    values: Sequence[float] | NDArray[np.floating],
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[float, float]:
    """95 % percentile-bootstrap interval of the mean (deterministic: fixed seed)."""
    x = np.asarray(values, dtype=float)
    if x.size == 0:
        return (math.nan, math.nan)
    if x.size == 1:
        return (float(x[0]), float(x[0]))
    means = _resampled_sums(x, resample_indices(x.size, resamples, seed)) / x.size
    lo, hi = np.percentile(means, [2.5, 97.5])
    return (float(lo), float(hi))


def ratio_interval(
    nd: NDArray[np.floating], resamples: int = BOOTSTRAP_RESAMPLES, seed: int = BOOTSTRAP_SEED
) -> tuple[float, float]:
    """95 % percentile-bootstrap interval of Σ numerator / Σ denominator over units (rows of
    ``nd``: numerator, denominator), the units resampled with replacement (the indices of
    :func:`resample_indices`); resamples whose denominators sum to 0 are left out. ``(nan,
    nan)`` without a unit with a denominator."""
    x = np.asarray(nd, dtype=float).reshape(-1, 2)
    if not (x[:, 1] > 0).any():
        return (math.nan, math.nan)
    if x.shape[0] == 1:
        v = x[0, 0] / x[0, 1]
        return (v, v)
    sums = _resampled_row_sums(
        np.ascontiguousarray(x), resample_indices(x.shape[0], resamples, seed)
    )
    ok = sums[:, 1] > 0
    ratios = sums[ok, 0] / sums[ok, 1]
    lo, hi = np.percentile(ratios, [2.5, 97.5])
    return (float(lo), float(hi))


@functools.lru_cache(maxsize=8)
def resample_indices(
    n: int, resamples: int = BOOTSTRAP_RESAMPLES, seed: int = BOOTSTRAP_SEED
) -> NDArray[np.int64]:
    """The bootstrap's resampled positions, ``(resamples, n)``: the first draw of
    ``default_rng(seed).integers(0, n, ...)``, the same for every sample of size ``n``, so it is
    drawn once per size (read-only) and every interval is unchanged. Drawing it was 3/4 of the
    time of an interval, and a leaderboard build computes thousands of them."""
    idx = np.random.default_rng(seed).integers(0, n, (resamples, n))
    idx.flags.writeable = False
    return idx


@numba.njit(cache=True)
def _block_sum(x: NDArray[np.float64], row: NDArray[np.int64], lo: int, n: int) -> float:
    """``x[row[lo:lo + n]].sum()`` for ``n <= 128`` in numpy's order (8 interleaved sums)."""
    if n < 8:
        res = -0.0
        for i in range(lo, lo + n):
            res += x[row[i]]
        return res
    r0, r1, r2, r3 = x[row[lo]], x[row[lo + 1]], x[row[lo + 2]], x[row[lo + 3]]
    r4, r5, r6, r7 = x[row[lo + 4]], x[row[lo + 5]], x[row[lo + 6]], x[row[lo + 7]]
    i, m = 8, n - n % 8
    while i < m:
        r0 += x[row[lo + i]]
        r1 += x[row[lo + i + 1]]
        r2 += x[row[lo + i + 2]]
        r3 += x[row[lo + i + 3]]
        r4 += x[row[lo + i + 4]]
        r5 += x[row[lo + i + 5]]
        r6 += x[row[lo + i + 6]]
        r7 += x[row[lo + i + 7]]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += x[row[lo + i]]
        i += 1
    return res


@numba.njit(cache=True)
def _pairwise_sum(x: NDArray[np.float64], row: NDArray[np.int64]) -> float:
    """``x[row].sum()`` added in numpy's pairwise order, the same bits as numpy's: blocks of up
    to 128 (:func:`_block_sum`), a longer range halved at a multiple of 8 and its halves'
    sums added (numpy recurses; here a stack of pending ranges and of finished sums)."""
    todo = np.empty((128, 3), dtype=np.int64)  # lo, n, 1 = add the last two sums
    sums = np.empty(128)
    t, v = 1, 0
    todo[0, 0], todo[0, 1], todo[0, 2] = 0, row.size, 0
    while t > 0:
        t -= 1
        lo, n, join = todo[t, 0], todo[t, 1], todo[t, 2]
        if join:
            v -= 1
            sums[v - 1] = sums[v - 1] + sums[v]
        elif n <= 128:
            sums[v] = _block_sum(x, row, lo, n)
            v += 1
        else:
            n2 = n // 2
            n2 -= n2 % 8
            todo[t, 0], todo[t, 1], todo[t, 2] = 0, 0, 1
            todo[t + 1, 0], todo[t + 1, 1], todo[t + 1, 2] = lo + n2, n - n2, 0
            todo[t + 2, 0], todo[t + 2, 1], todo[t + 2, 2] = lo, n2, 0
            t += 3
    return sums[0]


@numba.njit(cache=True)
def _resampled_sums(x: NDArray[np.float64], idx: NDArray[np.int64]) -> NDArray[np.float64]:
    """``x[idx].sum(axis=1)`` bit for bit, without the ``(resamples, n)`` gathered copy."""
    out = np.empty(idx.shape[0])
    for r in range(idx.shape[0]):
        out[r] = _pairwise_sum(x, idx[r])
    return out


@numba.njit(cache=True)
def _resampled_row_sums(x: NDArray[np.float64], idx: NDArray[np.int64]) -> NDArray[np.float64]:
    """``x[idx].sum(axis=1)`` of a 2-D ``x`` bit for bit (numpy adds the rows in order)."""
    out = np.zeros((idx.shape[0], x.shape[1]))
    for r in range(idx.shape[0]):
        for c in range(idx.shape[1]):
            for j in range(x.shape[1]):
                out[r, j] += x[idx[r, c], j]
    return out


def _r(x: float) -> float | None:
    return None if x is None or not math.isfinite(x) else round(float(x), 6)


def rate(k: int, n: int) -> dict[str, Any]:
    lo, hi = wilson_interval(k, n)
    return {"value": _r(k / n) if n else None, "ci95": [_r(lo), _r(hi)], "count": k, "n": n}


def mean(values: Sequence[float]) -> dict[str, Any]:
    x = np.asarray(values, dtype=float)
    lo, hi = bootstrap_mean_interval(x)
    return {"value": _r(float(x.mean())) if x.size else None, "ci95": [_r(lo), _r(hi)], "n": x.size}


def poisson_rate(k: int, exposure: float, z: float = Z95) -> dict[str, Any]:
    """Events per unit of exposure with the score interval of a Poisson rate:
    (k + z²/2 ± z √(k + z²/4)) / exposure (lower bound 0 when k = 0)."""
    if exposure <= 0:
        return {"value": None, "ci95": [None, None], "count": k, "exposure_h": _r(exposure)}
    centre = k + z * z / 2
    half = z * math.sqrt(k + z * z / 4)
    lo = 0.0 if k == 0 else (centre - half) / exposure
    return {
        "value": _r(k / exposure),
        "ci95": [_r(lo), _r((centre + half) / exposure)],
        "count": k,
        "exposure_h": _r(exposure),
    }


FIELD_METRICS = (
    "los_events",
    "los_time_s",
    "intrusion_severity",
    "conflicts",
    "extra_path_km",
    "delay_s",
    "manoeuvres",
    "nmac_per_flight_hour",
)
"""Keys of the field-standard metrics, in display order (docs/model.md §10.1)."""


# ----------------------------------------------------------------------------------------------
# The registry: every metric defined once

Record = Mapping[str, Any]
"""One per-aircraft episode record (a line of the per-episode log, one aircraft)."""

AGGREGATES = ("rate", "mean", "per_h")
FORMATS = ("rate", "mean", "per_h")
SCOPES = ("aircraft", "system")


@dataclass(frozen=True)
class Metric:
    """One metric: the per-episode fact it reads, how the facts aggregate, and how it is shown.

    The fact is a function of one per-aircraft record; what it means depends on ``aggregate``:

    * ``rate``: ``value(r)`` counts events (a bool: the episode had it; or an int, e.g. masked
      decisions) out of ``over(r)`` trials (an int; default 1: the episode is one trial). The
      group's value is events / trials with the Wilson interval.
    * ``mean``: ``value(r)`` is the record's value, over the records where ``over(r)`` is true
      (default: every record). The group's value is the mean with the bootstrap interval.
    * ``per_h``: ``value(r)`` counts events (an int) over ``over(r)`` seconds of exposure
      (required). The group's value is events per hour with the Poisson score interval.

    The paired comparison (``cdr-bench compare``, the leaderboard's marks) uses the same facts
    per episode, as a ratio of sums: :meth:`paired`.
    """

    key: str
    """Key in a result's ``metrics``, in ``cdr-bench compare`` and in ``leaderboard.json``."""
    header: str
    """Column header of the tables."""
    aggregate: str
    """``rate``, ``mean`` or ``per_h`` (see the class docstring)."""
    higher: bool
    """Higher is better."""
    value: Callable[[Any], Any]
    """The per-record fact (see the class docstring; a system metric's reads an episode's
    records, :attr:`scope`)."""
    over: Callable[[Any], Any] | None = None
    """rate: trials of the record (None: 1); mean: whether the record counts (None: every
    record); per_h: exposure of the record in seconds."""
    short: str = ""
    """Header of the compact terminal summary; empty: not in it."""
    detail: bool = True
    """Only in the full per-result tables (``cdr-bench evaluate --wide`` / ``report``) and in
    ``leaderboard.json``; False: also a column of the leaderboard's pages and the docs' tables."""
    fmt: str = ""
    """Number format: ``rate`` (in %, one decimal), ``mean`` (two decimals) or ``per_h`` (three
    significant digits); empty: the aggregate's."""
    doc: str = ""
    """What it measures, in a sentence."""
    scope: str = "aircraft"
    """``aircraft``: ``value`` and ``over`` read one per-aircraft record, and the records of a
    role are the trials (the class docstring). ``system``: they read the records of one
    episode's controlled aircraft together (every role), and the episode is the unit:
    :meth:`compute_system`."""

    def __post_init__(self) -> None:
        if self.aggregate not in AGGREGATES:
            raise ValueError(f"metric {self.key}: aggregate must be one of {AGGREGATES}")
        if self.scope not in SCOPES:
            raise ValueError(f"metric {self.key}: scope must be one of {SCOPES}")
        if self.scope == "system" and self.over is None:
            raise ValueError(f"metric {self.key}: a system metric needs its denominator (over)")
        if self.fmt and self.fmt not in FORMATS:
            raise ValueError(f"metric {self.key}: fmt must be one of {FORMATS}")
        if self.aggregate == "per_h" and self.over is None:
            raise ValueError(f"metric {self.key}: a per_h metric needs its exposure (over)")

    @property
    def kind(self) -> str:
        """How its numbers are shown (``rate``, ``mean`` or ``per_h``): the format."""
        return self.fmt or self.aggregate

    def compute(self, records: Sequence[Record]) -> dict[str, Any]:
        """The group's value with its 95 % interval (:func:`rate`, :func:`mean` or
        :func:`poisson_rate`)."""
        f, over = self.value, self.over
        if self.aggregate == "rate":
            k = sum(int(f(r)) for r in records)
            n = len(records) if over is None else sum(int(over(r)) for r in records)
            return rate(k, n)
        if self.aggregate == "mean":
            return mean(
                [f(r) for r in records] if over is None else [f(r) for r in records if over(r)]
            )
        assert over is not None
        hours = sum(float(over(r)) for r in records) / 3600.0
        return poisson_rate(sum(int(f(r)) for r in records), hours)

    def compute_system(self, episodes: Sequence[Sequence[Record]]) -> dict[str, Any]:
        """A system metric over episodes (each the list of its controlled aircraft's records):
        the ratio Σ value / Σ over of the per-episode numerators and denominators (rate: events
        / trials; mean: a sum / its count; per_h: events / seconds of exposure, per hour), with
        the 95 % percentile-bootstrap interval over episodes (:func:`ratio_interval`: the
        aircraft of one episode are not independent, so the episode is resampled whole).
        Reported like the aircraft metrics (``count`` and ``n`` for a rate, ``n`` for a mean,
        ``count`` and ``exposure_h`` per hour), plus ``episodes``: those with a denominator."""
        if self.scope != "system" or self.over is None:
            raise ValueError(f"metric {self.key} is not a system metric")
        nd = np.array(
            [[float(self.value(ep)), float(self.over(ep))] for ep in episodes], dtype=float
        ).reshape(-1, 2)
        if self.aggregate == "per_h":
            nd[:, 1] /= 3600.0
        num, den = float(nd[:, 0].sum()), float(nd[:, 1].sum())
        lo, hi = ratio_interval(nd)
        out: dict[str, Any] = {
            "value": _r(num / den) if den > 0 else None,
            "ci95": [_r(lo), _r(hi)],
        }
        if self.aggregate == "rate":
            out |= {"count": int(round(num)), "n": int(round(den))}
        elif self.aggregate == "mean":
            out["n"] = int(round(den))
        else:
            out |= {"count": int(round(num)), "exposure_h": _r(den)}
        out["episodes"] = int((nd[:, 1] > 0).sum())
        return out

    def paired(self, record: Record) -> tuple[float, float]:
        """``(numerator, denominator)`` of one record for the paired comparison, which sums both
        over an episode's records and takes their ratio: events and trials (rates; per
        episode: a binary outcome), the value where it counts and whether it counts (means),
        events and exposure in hours (per_h)."""
        f, over = self.value, self.over
        if self.scope == "system":  # ``record``: the records of one episode
            assert over is not None
            den = float(over(record))
            return float(f(record)), den / 3600.0 if self.aggregate == "per_h" else den
        if self.aggregate == "rate":
            return float(f(record)), 1.0 if over is None else float(over(record))
        if self.aggregate == "mean":
            if over is None:
                return float(f(record)), 1.0
            counts = over(record)
            return (float(f(record)) if counts else 0.0), float(counts)
        assert over is not None
        return float(f(record)), float(over(record)) / 3600.0

    def point(self, records: Sequence[Record]) -> float:
        """The unrounded value over ``records`` (NaN without trials), no interval: the ratio of
        the summed :meth:`paired` terms (the trainers' quick evaluation)."""
        if not records:
            return math.nan
        nd = np.array([self.paired(r) for r in records], dtype=float)
        d = nd[:, 1].sum()
        return float(nd[:, 0].sum() / d) if d > 0 else math.nan


def _outcome(name: str) -> Callable[[Record], bool]:
    return lambda r: r["outcome"] == name


def _success(r: Record) -> bool:
    return bool(r["outcome"] == "success")


_BUILTIN: tuple[Metric, ...] = (
    Metric(
        "success_rate",
        "success",
        "rate",
        True,
        _success,
        short="success",
        detail=False,
        doc="Goal reached without NMAC (and without LoS where a LoS ends the episode).",
    ),
    Metric(
        "los_rate",
        "LoS",
        "rate",
        False,
        lambda r: r["los"],
        short="LoS",
        detail=False,
        doc="At least one loss of separation, whatever the outcome (an NMAC is also a LoS).",
    ),
    Metric(
        "nmac_rate",
        "NMAC",
        "rate",
        False,
        _outcome("nmac"),
        short="NMAC",
        detail=False,
        doc="Ended by a near mid-air collision.",
    ),
    Metric(
        "timeout_rate",
        "timeout",
        "rate",
        False,
        _outcome("timeout"),
        short="timeout",
        detail=False,
        doc="Ran out of steps.",
    ),
    Metric(
        "los_terminated_rate",
        "ended by LoS",
        "rate",
        False,
        _outcome("los"),
        doc="Ended by a LoS (only where a LoS ends the episode).",
    ),
    Metric(
        "boundary_rate",
        "boundary",
        "rate",
        False,
        _outcome("boundary"),
        doc="Ended by leaving the sector (only where that ends the episode).",
    ),
    Metric(
        "avg_steps_success",
        "steps (success)",
        "mean",
        False,
        lambda r: r["steps"],
        _success,
        short="steps",
        detail=False,
        doc="Steps of the successful episodes.",
    ),
    Metric(
        "clean_success_rate",
        "clean success",
        "rate",
        True,
        lambda r: r["outcome"] == "success" and not r["los"],
        short="clean",
        detail=False,
        doc="Goal reached with no LoS at all.",
    ),
    Metric(
        "goal_reward",
        "R_G",
        "mean",
        True,
        lambda r: r["goal_reward"],
        detail=False,
        doc="Episode sum of the goal reward R_G.",
    ),
    Metric(
        "safety_reward",
        "R_S",
        "mean",
        True,
        lambda r: r["safety_reward"],
        detail=False,
        doc="Episode sum of the safety reward R_S.",
    ),
    Metric(
        "invalid_action_rate",
        "invalid",
        "rate",
        False,
        lambda r: r["invalid_actions"],
        lambda r: r["steps"],
        detail=False,
        doc="Masked (invalid) actions / decisions.",
    ),
    Metric(
        "los_events",
        "LoS events",
        "mean",
        False,
        lambda r: r["los_events"],
        doc="LoS events per flight (pairs entering a LoS).",
    ),
    Metric(
        "los_time_s",
        "LoS time s",
        "mean",
        False,
        lambda r: r["los_s"],
        doc="Seconds in LoS per flight.",
    ),
    Metric(
        "intrusion_severity",
        "severity",
        "mean",
        False,
        lambda r: r["severity"],
        lambda r: r["los"],
        doc="1 - min separation / LoS threshold, over the flights with a LoS.",
    ),
    Metric(
        "conflicts",
        "conflicts",
        "mean",
        False,
        lambda r: r["conflicts"],
        doc="Predicted conflicts per flight.",
    ),
    Metric(
        "extra_path_km",
        "extra path km",
        "mean",
        False,
        lambda r: r["path_km"] - r["direct_km"],
        _success,
        doc="Path flown beyond the direct distance, over successful flights.",
    ),
    Metric(
        "delay_s",
        "delay s",
        "mean",
        False,
        lambda r: r["flight_s"] - r["direct_s"],
        _success,
        doc="Flight time beyond the direct time, over successful flights.",
    ),
    Metric(
        "manoeuvres",
        "manoeuvres",
        "mean",
        False,
        lambda r: r["manoeuvres"],
        doc="Decisions other than hold, per flight.",
    ),
    Metric(
        "nmac_per_flight_hour",
        "NMAC / flight h",
        "per_h",
        False,
        lambda r: r["nmac_events"],
        lambda r: r["flight_s"],
        doc="NMAC events per flight hour.",
    ),
)


# System metrics (docs/model.md §10.1.3): the records of one episode's controlled aircraft
# together, the episode the unit.

Episode = Sequence[Record]
"""The records of one episode's controlled aircraft (every role)."""


def _pair_events(kind: str) -> Callable[[Episode], float]:
    """Pairs entering a LoS / NMAC in the episode, each pair once: the aircraft's events, less
    half of those with another controlled aircraft (in both aircraft's records)."""
    own, shared = f"{kind}_events", f"{kind}_events_ac"
    return lambda ep: sum(r[own] for r in ep) - sum(r.get(shared, 0) for r in ep) / 2


def _delays(ep: Episode) -> list[float]:
    return [r["flight_s"] - r["direct_s"] for r in ep if _success(r)]


def _delay_spread(ep: Episode) -> float:
    d = _delays(ep)
    return float(np.std(d)) if len(d) >= 2 else 0.0


def _flights(ep: Episode) -> int:
    return len(ep)


def _flight_s(ep: Episode) -> float:
    return float(sum(r["flight_s"] for r in ep))


_SYSTEM: tuple[Metric, ...] = (
    Metric(
        "system_success_rate",
        "flights success",
        "rate",
        True,
        lambda ep: sum(_success(r) for r in ep),
        _flights,
        short="success",
        scope="system",
        doc="Share of the controlled flights that reached their goal.",
    ),
    Metric(
        "system_clean_rate",
        "clean flights",
        "rate",
        True,
        lambda ep: sum(_success(r) and not r["los"] for r in ep),
        _flights,
        short="clean",
        scope="system",
        doc="Share of the controlled flights that reached their goal with no LoS at all.",
    ),
    Metric(
        "system_clean_episode_rate",
        "clean episodes",
        "rate",
        True,
        lambda ep: not any(r["los"] for r in ep),
        lambda ep: 1,
        short="clean ep",
        scope="system",
        doc="Share of the episodes in which no controlled aircraft had a LoS.",
    ),
    Metric(
        "system_los_per_flight_hour",
        "LoS / flight h",
        "per_h",
        False,
        _pair_events("los"),
        _flight_s,
        short="LoS/h",
        scope="system",
        doc="Pairs entering a LoS (controlled-controlled once, controlled-background) per hour "
        "flown by the controlled aircraft.",
    ),
    Metric(
        "system_nmac_per_flight_hour",
        "NMAC / flight h",
        "per_h",
        False,
        _pair_events("nmac"),
        _flight_s,
        short="NMAC/h",
        scope="system",
        doc="Pairs entering an NMAC per hour flown by the controlled aircraft.",
    ),
    Metric(
        "system_delay_s",
        "delay s",
        "mean",
        False,
        lambda ep: sum(_delays(ep)),
        lambda ep: len(_delays(ep)),
        short="delay s",
        scope="system",
        doc="Flight time beyond the direct time, per successful flight.",
    ),
    Metric(
        "system_extra_path_km",
        "extra path km",
        "mean",
        False,
        lambda ep: sum(r["path_km"] - r["direct_km"] for r in ep if _success(r)),
        lambda ep: sum(_success(r) for r in ep),
        short="extra km",
        scope="system",
        doc="Path flown beyond the direct distance, per successful flight.",
    ),
    Metric(
        "system_manoeuvres",
        "manoeuvres",
        "mean",
        False,
        lambda ep: sum(r["manoeuvres"] for r in ep),
        _flights,
        short="manoeuvres",
        scope="system",
        doc="Decisions other than hold, per controlled flight.",
    ),
    Metric(
        "system_delay_spread_s",
        "delay spread s",
        "mean",
        False,
        _delay_spread,
        lambda ep: len(_delays(ep)) >= 2,
        short="spread s",
        scope="system",
        doc="Standard deviation of the delay across an episode's successful flights (who pays "
        "for the resolutions), averaged over the episodes with at least two.",
    ),
)

_REGISTRY: dict[str, Metric] = {m.key: m for m in (*_BUILTIN, *_SYSTEM)}
_RESERVED = {"episodes"}


class MetricView(Sequence[Metric]):
    """The registered metrics (those passing ``keep``), in registration order, read from the
    registry at each use: a metric registered later is in every view."""

    def __init__(self, keep: Callable[[Metric], bool] | None = None) -> None:
        self._keep = keep

    def _now(self) -> tuple[Metric, ...]:
        ms = tuple(_REGISTRY.values())
        return ms if self._keep is None else tuple(m for m in ms if self._keep(m))

    @overload
    def __getitem__(self, i: int) -> Metric: ...
    @overload
    def __getitem__(self, i: slice) -> tuple[Metric, ...]: ...
    def __getitem__(self, i: int | slice) -> Metric | tuple[Metric, ...]:
        return self._now()[i]

    def __len__(self) -> int:
        return len(self._now())

    def __iter__(self) -> Iterator[Metric]:
        return iter(self._now())

    def __repr__(self) -> str:
        return f"MetricView({[m.key for m in self._now()]})"


METRICS = MetricView(lambda m: m.scope == "aircraft")
"""Every metric of a role's records, in display order: the built-in ones (docs/model.md §10,
§10.1), then those added with :func:`register_metric`."""
SYSTEM_METRICS = MetricView(lambda m: m.scope == "system")
"""The system metrics (docs/model.md §10.1.3): over every controlled aircraft of an episode,
the episode the unit; in a result's ``system_metrics`` where an episode has several."""
MAIN_METRICS = MetricView(lambda m: m.scope == "aircraft" and not m.detail)
"""The metrics that are columns of the leaderboard's pages and the docs' tables."""


def register_metric(metric: Metric) -> Metric:
    """Add a metric over the per-episode facts: from then on it is computed with every result
    read (:func:`group_metrics`), is a column of the per-result tables (a detail column unless
    ``detail=False``) and of ``leaderboard.json``, and ``cdr-bench compare`` compares it.
    Nothing is written: result files hold facts only."""
    if metric.key in _REGISTRY or metric.key in _RESERVED:
        raise ValueError(f"metric {metric.key!r} is already defined")
    _REGISTRY[metric.key] = metric
    _GENERATION[0] += 1
    return metric


def unregister_metric(key: str) -> None:
    """Remove a metric added with :func:`register_metric` (the built-in ones stay)."""
    if key in {m.key for m in (*_BUILTIN, *_SYSTEM)}:
        raise ValueError(f"metric {key!r} is built in")
    if key not in _REGISTRY:
        raise KeyError(f"no metric {key!r}")
    del _REGISTRY[key]
    _GENERATION[0] += 1


_GENERATION = [0]


def registry_generation() -> int:
    """A number that changes whenever a metric is registered or removed (what a cache of
    computed metrics is keyed by, beside the facts they come from)."""
    return _GENERATION[0]


def get_metric(key: str) -> Metric:
    """The registered metric ``key`` (:class:`KeyError` if none)."""
    return _REGISTRY[key]


def group_metrics(records: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Every registered metric over a list of per-aircraft episode records (see the module
    docstring), after ``episodes``."""
    outcome = [r["outcome"] for r in records]
    unknown = set(outcome) - set(OUTCOMES)
    if unknown:
        raise ValueError(f"unknown outcome(s) {sorted(unknown)}; expected one of {OUTCOMES}")
    out: dict[str, Any] = {"episodes": len(records)}
    for m in METRICS:
        out[m.key] = m.compute(records)
    return out


ROLES = ("ownship", "intruders", "traffic")
"""The roles scored apart: the ownship, learning intruders, controlled airway aircraft."""


def role_of(aircraft_id: str) -> str:
    """``ownship`` for ``ownship_0``, ``traffic`` for controlled airway aircraft
    (``aircraft_i``), ``intruders`` for learning intruders."""
    if aircraft_id.startswith("ownship"):
        return "ownship"
    return "traffic" if aircraft_id.startswith("aircraft") else "intruders"


def scenario_metrics(episodes: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Metrics of the ownship and (where present) of the learning intruders and of the
    controlled airway aircraft, reported apart."""
    groups: dict[str, list[dict[str, Any]]] = {role: [] for role in ROLES}
    for ep in episodes:
        for ac in ep["aircraft"]:
            groups[role_of(ac["id"])].append(ac)
    return {role: group_metrics(recs) for role, recs in groups.items() if recs}


def system_metrics(episodes: Sequence[dict[str, Any]]) -> dict[str, Any] | None:
    """Every system metric (:data:`SYSTEM_METRICS`) over a scenario's episodes, after
    ``episodes`` and ``flights``; None where no episode has more than one controlled
    aircraft."""
    eps = [ep["aircraft"] for ep in episodes]
    if not eps or max(len(a) for a in eps) < 2:
        return None
    out: dict[str, Any] = {"episodes": len(eps), "flights": sum(len(a) for a in eps)}
    for m in SYSTEM_METRICS:
        out[m.key] = m.compute_system(eps)
    return out


def latency_summary(per_decision_ms: Sequence[float], per_call_ms: Sequence[float]) -> dict:
    """Median and p99 decision latency in ms (per decision: a call's time / decisions in it)."""
    d = np.asarray(per_decision_ms, dtype=float)
    c = np.asarray(per_call_ms, dtype=float)

    def q(x: NDArray[np.floating], p: float) -> float | None:
        return round(float(np.percentile(x, p)), 6) if x.size else None

    return {
        "per_decision_ms": {"median": q(d, 50), "p99": q(d, 99)},
        "per_call_ms": {"median": q(c, 50), "p99": q(c, 99)},
        "calls": int(c.size),
    }
