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
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from typing import Any

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
    means = x[resample_indices(x.size, resamples, seed)].mean(axis=1)
    lo, hi = np.percentile(means, [2.5, 97.5])
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


def group_metrics(records: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Every metric over a list of per-aircraft episode records (see the module docstring)."""
    n = len(records)
    outcome = [r["outcome"] for r in records]
    unknown = set(outcome) - set(OUTCOMES)
    if unknown:
        raise ValueError(f"unknown outcome(s) {sorted(unknown)}; expected one of {OUTCOMES}")
    out: dict[str, Any] = {"episodes": n}
    for name in OUTCOMES:
        out[RATE_KEYS[name]] = rate(sum(o == name for o in outcome), n)
    los = [bool(r["los"]) for r in records]
    out["los_rate"] = rate(sum(los), n)
    out["clean_success_rate"] = rate(
        sum(o == "success" and not lo for o, lo in zip(outcome, los, strict=True)), n
    )
    out["avg_steps_success"] = mean(
        [r["steps"] for r, o in zip(records, outcome, strict=True) if o == "success"]
    )
    out["goal_reward"] = mean([r["goal_reward"] for r in records])
    out["safety_reward"] = mean([r["safety_reward"] for r in records])
    decisions = sum(int(r["steps"]) for r in records)
    out["invalid_action_rate"] = rate(sum(int(r["invalid_actions"]) for r in records), decisions)

    out["los_events"] = mean([r["los_events"] for r in records])
    out["los_time_s"] = mean([r["los_s"] for r in records])
    out["intrusion_severity"] = mean([r["severity"] for r in records if r["los"]])
    out["conflicts"] = mean([r["conflicts"] for r in records])
    ok = [r for r, o in zip(records, outcome, strict=True) if o == "success"]
    out["extra_path_km"] = mean([r["path_km"] - r["direct_km"] for r in ok])
    out["delay_s"] = mean([r["flight_s"] - r["direct_s"] for r in ok])
    out["manoeuvres"] = mean([r["manoeuvres"] for r in records])
    hours = sum(float(r["flight_s"]) for r in records) / 3600.0
    out["nmac_per_flight_hour"] = poisson_rate(sum(int(r["nmac_events"]) for r in records), hours)
    return out


def role_of(aircraft_id: str) -> str:
    """``ownship`` for ``ownship_0``, ``intruders`` for learning intruders."""
    return "ownship" if aircraft_id.startswith("ownship") else "intruders"


def scenario_metrics(episodes: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Metrics of the ownship and (where present) of the learning intruders, reported apart."""
    groups: dict[str, list[dict[str, Any]]] = {"ownship": [], "intruders": []}
    for ep in episodes:
        for ac in ep["aircraft"]:
            groups[role_of(ac["id"])].append(ac)
    return {role: group_metrics(recs) for role, recs in groups.items() if recs}


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
