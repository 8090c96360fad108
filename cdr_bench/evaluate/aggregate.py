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
    k: Any, n: int, reps: int = RESAMPLES, seed: int = BOOTSTRAP_SEED
) -> list[float] | None:
    """95 % stratified-bootstrap interval of :func:`iqm`; ``None`` with a single run."""
    a = _counts(k)
    if a.shape[0] < 2:
        return None
    rng = np.random.default_rng(seed)
    s = _resample(a, rng, reps).reshape(reps, -1)
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


def summary(k: Any, n: int) -> dict[str, Any]:
    """IQM with its interval, and the runs' spread (min, max of the per-run mean over tasks)."""
    a = _counts(k)
    per_run = [float(Fraction(int(r.sum()), a.shape[1] * n)) for r in a]
    return {
        "iqm": round(iqm(a, n), 6),
        "ci95": None if (ci := iqm_interval(a, n)) is None else [round(v, 6) for v in ci],
        "runs": a.shape[0],
        "tasks": a.shape[1],
        "per_run": [round(v, 6) for v in per_run],
        "min": round(min(per_run), 6),
        "max": round(max(per_run), 6),
    }
