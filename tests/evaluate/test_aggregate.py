"""Seed aggregates (cdr_bench/evaluate/aggregate.py) against scipy and brute force."""

from __future__ import annotations

import itertools
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import mannwhitneyu, trim_mean

from cdr_bench.evaluate import aggregate as agg

counts = st.integers(1, 7).flatmap(
    lambda runs: st.integers(1, 4).flatmap(
        lambda tasks: st.lists(
            st.lists(st.integers(0, 20), min_size=tasks, max_size=tasks),
            min_size=runs,
            max_size=runs,
        )
    )
)


@settings(max_examples=200, deadline=None)
@given(counts)
def test_iqm_is_scipy_trim_mean(k):
    a = np.array(k)
    assert agg.iqm(a, 20) == pytest.approx(trim_mean(a / 20, 0.25, axis=None), abs=1e-12)


@settings(max_examples=200, deadline=None)
@given(counts, st.lists(st.integers(0, 20), min_size=1, max_size=6))
def test_probability_of_improvement_is_rliable_formula(kx, y_col):
    x = np.array(kx)
    y = np.array([[v] * x.shape[1] for v in y_col])
    per_task = []
    for t in range(x.shape[1]):
        if np.array_equal(x[:, t], y[:, t]):
            per_task.append(0.5)
        else:
            u = mannwhitneyu(x[:, t], y[:, t], alternative="greater").statistic
            per_task.append(u / (x.shape[0] * y.shape[0]))
    assert agg.probability_of_improvement(x, y) == pytest.approx(np.mean(per_task), abs=1e-12)


def test_exact_values_and_identical_replicas():
    k = np.array([[10], [12], [14], [16], [30]])  # 5 runs: the IQM keeps the middle 3
    assert agg.iqm(k, 20) == float(Fraction(10 + 12 + 14 + 16 + 30 - 10 - 30, 3 * 20))
    assert agg.probability_of_improvement(k, np.array([[14]])) == float(Fraction(2 * 2 + 1, 10))
    assert agg.iqm_interval(np.array([[7, 3]]), 20) is None  # one run: no interval over seeds
    assert agg.probability_of_improvement_interval([[1]], [[2]]) is None
    s = agg.summary(k, 20)
    assert s["runs"] == 5 and s["min"] == 0.5 and s["max"] == 1.5 and s["ci95"] is not None


def test_stratified_bootstrap_resamples_within_tasks():
    # task 0 always 0, task 1 always 20 across runs: any stratified resample keeps one of each
    # per run pair, so every resampled IQM over 2 runs x 2 tasks (no cut) is exactly 0.5
    k = np.array([[0, 20], [0, 20]])
    assert agg.iqm_interval(k, 20, reps=500) == [0.5, 0.5]
    # brute force: with 3 runs of one task (nothing cut) a resampled IQM is the mean of one of
    # the 27 ordered draws; the 95 % interval lies within them
    k1 = np.array([[2], [9], [15]])
    vals = sorted(float(Fraction(sum(d), 3 * 20)) for d in itertools.product([2, 9, 15], repeat=3))
    lo, hi = agg.iqm_interval(k1, 20, reps=4000)
    assert vals[0] <= lo <= hi <= vals[-1] and lo < agg.iqm(k1, 20) < hi


def test_deterministic_and_rejects_bad_shapes():
    k = np.array([[3, 4], [5, 9], [1, 2]])
    assert agg.iqm_interval(k, 10) == agg.iqm_interval(k, 10)
    with pytest.raises(ValueError, match="shape"):
        agg.iqm(np.array([1, 2]), 10)
    with pytest.raises(ValueError, match="integer"):
        agg.iqm(np.array([[0.5]]), 10)
    with pytest.raises(ValueError, match="task counts"):
        agg.probability_of_improvement([[1, 2]], [[1]])
