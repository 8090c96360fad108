"""Aggregates over training seeds, as Agarwal et al. (2021, "Deep RL at the edge of the
statistical precipice", the ``rliable`` library) recommend: the interquartile mean (IQM) of the
scores of every (run, task), 95 % percentile intervals from the *stratified* bootstrap (the runs
resampled with replacement within each task, the tasks kept), and the probability of improvement
``P(X > Y)``: for each task the chance that a random run of X scores above a random run of Y
(ties count one half; the Mann-Whitney U statistic over ``n_x n_y``), averaged over the tasks.

A run is one training seed, a task one scenario, a score one rate of that run on that task over
the same evaluation episodes. Scores are given as integer counts ``k`` over a common number of
episodes ``n`` (``k / n`` is the rate). Everything is computed on the integers, so the point
estimates are exact fractions and the bootstrap's resampled statistics are the same bits on
every CPU; the resampling indices come from ``numpy.random.default_rng(BOOTSTRAP_SEED)``.

The formulas are rliable's (``rliable.metrics.aggregate_iqm`` is ``scipy.stats.trim_mean(x,
0.25)`` over the flattened runs x tasks; ``probability_of_improvement`` as above);
``tests/evaluate/test_aggregate.py`` checks the point estimates against scipy and against a
brute-force enumeration. rliable itself is not a dependency (its bootstrap needs ``arch``).

One run gives no interval over seeds: the interval is then ``None``, never an interval over
identical replicas.
"""

from __future__ import annotations

from fractions import Fraction
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cdr_bench.evaluate.metrics import BOOTSTRAP_SEED

RESAMPLES = 50_000
"""Bootstrap resamples (rliable's default ``reps``)."""
TRIM = Fraction(1, 4)
"""Proportion cut from each end for the interquartile mean."""


def _counts(k: Any) -> NDArray[np.int64]:
    a = np.asarray(k)
    if a.ndim != 2 or a.shape[0] < 1 or a.shape[1] < 1:
        raise ValueError(f"expected counts of shape (runs, tasks), got shape {a.shape}")
    if a.dtype.kind not in "iu":
        raise ValueError(f"expected integer counts, got dtype {a.dtype}")
    return a.astype(np.int64)


def _cut(size: int) -> int:
    """Values cut from each end of ``size`` sorted values (scipy's ``int(0.25 * size)``)."""
    return int(TRIM * size)


def iqm(k: Any, n: int) -> float:
    """Interquartile mean of the rates ``k / n`` over all (run, task) cells."""
    a = np.sort(_counts(k), axis=None)
    c = _cut(a.size)
    mid = a[c : a.size - c]
    return float(Fraction(int(mid.sum()), int(mid.size) * n))


def _iqm_rows(samples: NDArray[np.int64], n: int) -> NDArray[np.float64]:
    """IQM of each row of ``samples`` (resamples x cells), from integer sums."""
    s = np.sort(samples, axis=1)
    c = _cut(s.shape[1])
    mid = s[:, c : s.shape[1] - c]
    return mid.sum(axis=1) / float(mid.shape[1] * n)


def _resample(a: NDArray[np.int64], rng: np.random.Generator, reps: int) -> NDArray[np.int64]:
    """Stratified bootstrap: per resample and task, the runs drawn with replacement within the
    task. Returns (reps, runs, tasks)."""
    runs, tasks = a.shape
    idx = rng.integers(0, runs, size=(reps, runs, tasks))
    return a[idx, np.arange(tasks)]


def _percentiles(x: NDArray[np.float64]) -> list[float]:
    lo, hi = np.percentile(x, [2.5, 97.5])
    return [float(lo), float(hi)]


def iqm_interval(
    k: Any, n: int, reps: int = RESAMPLES, seed: int = BOOTSTRAP_SEED, episodes: bool = False
) -> list[float] | None:
    """95 % stratified-bootstrap interval of :func:`iqm`; ``None`` with a single run. With
    ``episodes`` two-level: each resampled run's episodes are resampled too (a count k of n
    becomes Binomial(n, k / n)), and a single run has its episode interval."""
    a = _counts(k)
    if a.shape[0] < 2 and not episodes:
        return None
    rng = np.random.default_rng(seed)
    s = _resample(a, rng, reps).reshape(reps, -1)
    if episodes:
        s = rng.binomial(n, s / n)
    return _percentiles(_iqm_rows(s, n))


def _poi_sums(x: NDArray[np.int64], y: NDArray[np.int64]) -> NDArray[np.int64]:
    """Twice the Mann-Whitney U of x over y per task, summed over tasks; works on stacked
    resamples (..., runs, tasks)."""
    gt = (x[..., :, None, :] > y[..., None, :, :]).sum(axis=(-3, -2))
    eq = (x[..., :, None, :] == y[..., None, :, :]).sum(axis=(-3, -2))
    return (2 * gt + eq).sum(axis=-1)


def probability_of_improvement(kx: Any, ky: Any) -> float:
    """``P(X > Y)`` averaged over tasks (ties count one half)."""
    x, y = _counts(kx), _counts(ky)
    if x.shape[1] != y.shape[1]:
        raise ValueError(f"different task counts: {x.shape[1]} and {y.shape[1]}")
    total = int(_poi_sums(x, y))
    return float(Fraction(total, 2 * x.shape[0] * y.shape[0] * x.shape[1]))


def probability_of_improvement_interval(
    kx: Any, ky: Any, reps: int = RESAMPLES, seed: int = BOOTSTRAP_SEED
) -> list[float] | None:
    """95 % interval of :func:`probability_of_improvement`, the runs of X and of Y resampled
    independently within each task; ``None`` when neither has two runs."""
    x, y = _counts(kx), _counts(ky)
    if x.shape[0] < 2 and y.shape[0] < 2:
        return None
    rng = np.random.default_rng(seed)
    chunks = []
    step = 5000  # bounds the pairwise array's memory
    for start in range(0, reps, step):
        r = min(step, reps - start)
        xs = _resample(x, rng, r) if x.shape[0] > 1 else np.broadcast_to(x, (r, *x.shape))
        ys = _resample(y, rng, r) if y.shape[0] > 1 else np.broadcast_to(y, (r, *y.shape))
        chunks.append(_poi_sums(xs, ys))
    s = np.concatenate(chunks) / float(2 * x.shape[0] * y.shape[0] * x.shape[1])
    return _percentiles(s)


def summary(k: Any, n: int, episodes: bool = False) -> dict[str, Any]:
    """IQM with its interval (two-level with ``episodes``: :func:`iqm_interval`), and the runs'
    spread (min, max of the per-run mean over tasks)."""
    a = _counts(k)
    per_run = [float(Fraction(int(r.sum()), a.shape[1] * n)) for r in a]
    ci = iqm_interval(a, n, episodes=episodes)
    return {
        "iqm": round(iqm(a, n), 6),
        "ci95": None if ci is None else [round(v, 6) for v in ci],
        "runs": a.shape[0],
        "tasks": a.shape[1],
        "per_run": [round(v, 6) for v in per_run],
        "min": round(min(per_run), 6),
        "max": round(max(per_run), 6),
    }


# --- Two-level bootstrap: seeds, then episodes -----------------------------------------------
#
# The intervals above resample seeds only: with three seeds the interval is the range of three
# values, and one run has none. The functions below add the episode noise: each resample draws
# the independent units (seeds; seeds that share a parent are one unit) with replacement, then
# the episodes of each drawn seed's run with replacement. For a yes/no outcome per episode a run
# of k successes in n episodes resampled over its episodes has Binomial(n, k / n) successes, and
# is drawn as such (the same distribution as resampling the n episodes, without the (n, n)
# index array).

Units = list[list[int]]
"""The independent units of an entry (one per seed, or per parent that several seeds share),
each the success counts of its seeds' runs over the same ``n`` episodes."""

MEAN_UP_TO = 4
"""With at most this many units the aggregate is their mean: the interquartile mean of four or
fewer values cuts at most one from each end of few values (rliable's IQM needs more runs)."""


def _check_units(units: Units, n: int) -> list[list[int]]:
    if not units or any(not u for u in units):
        raise ValueError(f"expected non-empty units of seed counts, got {units!r}")
    out = [[int(k) for k in u] for u in units]
    if any(not 0 <= k <= n for u in out for k in u):
        raise ValueError(f"counts must lie in [0, {n}], got {units!r}")
    return out


def aggregate_name(units: int) -> str:
    """How :func:`seed_score` aggregates ``units`` units: ``IQM``, ``mean`` or ``one run``."""
    return "one run" if units == 1 else ("mean" if units <= MEAN_UP_TO else "IQM")


def _agg_rows(u: NDArray[np.float64]) -> NDArray[np.float64]:
    """The aggregate of each row of ``u`` (resamples x units): mean, or IQM beyond
    :data:`MEAN_UP_TO` units."""
    m = u.shape[1]
    if m <= MEAN_UP_TO:
        return u.mean(axis=1)
    s = np.sort(u, axis=1)
    c = _cut(m)
    return s[:, c : m - c].mean(axis=1)


def seed_score(units: Units, n: int) -> float:
    """The score of an entry over its units: each unit's rate is the mean of its seeds' rates;
    their mean (at most :data:`MEAN_UP_TO` units) or interquartile mean (exact fractions)."""
    us = sorted(Fraction(sum(u), len(u) * n) for u in _check_units(units, n))
    c = 0 if len(us) <= MEAN_UP_TO else _cut(len(us))
    mid = us[c : len(us) - c]
    return float(sum(mid, Fraction(0)) / len(mid))


def _unit_rates(
    units: list[list[int]], n: int, rng: np.random.Generator, reps: int
) -> NDArray[np.float64]:
    """``(reps, units)``: per resample the units drawn with replacement, each drawn unit's rate
    the mean of its seeds' runs, each run's episodes resampled (binomial)."""
    m = len(units)
    draws = rng.integers(0, m, (reps, m))
    out = np.empty((reps, m))
    for j, u in enumerate(units):
        p = np.array(u, dtype=np.float64) / n
        # every position gets its own episode resample of unit j (a unit drawn twice is
        # resampled twice); the positions that drew j keep theirs
        rates = rng.binomial(n, p, size=(reps, m, len(u))).sum(axis=2) / (len(u) * n)
        hit = draws == j
        out[hit] = rates[hit]
    return out


def seed_score_interval(
    units: Units, n: int, reps: int = RESAMPLES, seed: int = BOOTSTRAP_SEED
) -> list[float]:
    """95 % two-level bootstrap interval of :func:`seed_score`: units, then episodes. Never
    zero-width from seeds alone: one run still has its episode noise."""
    us = _check_units(units, n)
    rng = np.random.default_rng(seed)
    return _percentiles(_agg_rows(_unit_rates(us, n, rng, reps)))


def _poi_two_level(
    ux: Units, uy: Units, n: int, reps: int, seed: int
) -> tuple[float, NDArray[np.float64]]:
    x, y = _check_units(ux, n), _check_units(uy, n)
    vx = np.array([float(Fraction(sum(u), len(u) * n)) for u in x])
    vy = np.array([float(Fraction(sum(u), len(u) * n)) for u in y])

    def poi(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
        gt = (a[..., :, None] > b[..., None, :]).sum(axis=(-2, -1))
        eq = (a[..., :, None] == b[..., None, :]).sum(axis=(-2, -1))
        return (gt + 0.5 * eq) / (a.shape[-1] * b.shape[-1])

    rng = np.random.default_rng(seed)
    rx, ry = _unit_rates(x, n, rng, reps), _unit_rates(y, n, rng, reps)
    return float(poi(vx, vy)), poi(rx, ry)


def paired_seed_difference(
    ux: list[list[NDArray[np.int64]]],
    uy: list[list[NDArray[np.int64]]],
    idx: NDArray[np.int64],
    seed: int = BOOTSTRAP_SEED,
) -> dict[str, Any]:
    """The paired difference Y - X of the mean rate over units (each unit the mean of its seeds'
    runs), runs given as 0/1 outcome vectors on the same ``n`` episodes, with a 95 % two-level
    bootstrap interval: per resample the units of each side drawn with replacement
    (``default_rng(seed)``, X's draws first), and the episodes resampled jointly for every run of
    both sides (``idx``: ``(resamples, n)``, the positions of :func:`cdr_bench.evaluate.compare.
    scenario_indices`), so every run keeps its pairing with the others. With one run per side
    this is exactly ``cdr-bench compare``'s interval (the same positions, the same sums)."""
    rng = np.random.default_rng(seed)
    reps, n = idx.shape

    def side(units: list[list[NDArray[np.int64]]]) -> tuple[float, NDArray[np.float64]]:
        point = float(
            sum(Fraction(int(sum(int(r.sum()) for r in u)), len(u) * n) for u in units) / len(units)
        )
        per_unit = np.stack(
            [sum(np.asarray(r)[idx].sum(axis=1) for r in u) / (len(u) * n) for u in units],
            axis=1,
        )  # (reps, units)
        if len(units) == 1:
            return point, per_unit[:, 0]
        draws = rng.integers(0, len(units), (reps, len(units)))
        return point, np.take_along_axis(per_unit, draws, axis=1).mean(axis=1)

    px, bx = side(ux)
    py, by = side(uy)
    d = by - bx
    lo, hi = _percentiles(d)
    # two-sided bootstrap p-value: twice the share of resamples on the far side of 0
    p = min(1.0, 2.0 * min(float(np.mean(d <= 0)), float(np.mean(d >= 0))))
    return {"diff": py - px, "ci95": [lo, hi], "significant": bool(lo > 0 or hi < 0), "p": p}


def probability_of_improvement_two_level(
    ux: list[Units], uy: list[Units], n: int, reps: int = 10_000, seed: int = BOOTSTRAP_SEED
) -> tuple[float, list[float]]:
    """``P(X > Y)`` between the units of X and of Y (each a unit's mean rate; ties one half),
    averaged over tasks (``ux[t]``: X's units on task t), and its 95 % two-level bootstrap
    interval (per task the units of each side drawn, then the episodes of every drawn run):
    against a single run the interval still has the episode noise."""
    if len(ux) != len(uy) or not ux:
        raise ValueError(f"different or no task counts: {len(ux)} and {len(uy)}")
    pts, res = zip(
        *(
            _poi_two_level(x, y, n, reps, seed + t)
            for t, (x, y) in enumerate(zip(ux, uy, strict=True))
        ),
        strict=True,
    )
    return float(np.mean(pts)), _percentiles(np.mean(np.stack(res), axis=0))
