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


# --- exact paired tests and the two-level bootstrap ------------------------------------------


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 400), st.integers(0, 400))
def test_mcnemar_exact_is_scipy_binomtest(b, c):
    from scipy.stats import binomtest

    from cdr_bench.evaluate.compare import mcnemar_exact

    want = 1.0 if b + c == 0 else binomtest(b, b + c, 0.5).pvalue
    assert mcnemar_exact(b, c) == pytest.approx(want, rel=1e-9, abs=1e-300)
    assert mcnemar_exact(b, c) == mcnemar_exact(c, b)


def test_mcnemar_exact_known_values_and_measurability():
    from cdr_bench.evaluate.compare import mcnemar_exact, measurable

    assert mcnemar_exact(12, 4) == pytest.approx(0.076812744140625)  # 2 * 2517 / 2**16
    assert mcnemar_exact(5, 0) == 0.0625 and mcnemar_exact(6, 0) == 0.03125
    assert mcnemar_exact(0, 0) == 1.0 and mcnemar_exact(3, 3) == 1.0
    assert mcnemar_exact(600, 400) < 1e-9  # exact integers: no overflow at 1000 episodes
    # 5 discordant episodes cannot reject at 5 % even all on one side; 6 can, 8 after Holm x 4
    assert not measurable(5, 0) and measurable(3, 3)
    assert not measurable(7, 0, tests=4) and measurable(8, 0, tests=4)


def test_holm_by_hand():
    from cdr_bench.evaluate.compare import holm

    # sorted 0.01, 0.02, 0.03, 0.04 -> x4, x3, x2, x1 = 0.04, 0.06, 0.06, 0.04 -> monotone
    assert holm([0.03, 0.01, 0.04, 0.02]) == pytest.approx([0.06, 0.04, 0.06, 0.06])
    assert holm([0.5, 0.9]) == pytest.approx([1.0, 1.0])
    assert holm([]) == []


def test_seed_score_mean_up_to_four_units_iqm_beyond():
    assert agg.seed_score([[900], [910], [920]], 1000) == pytest.approx(0.91)
    assert agg.aggregate_name(3) == "mean" and agg.aggregate_name(1) == "one run"
    # five units: IQM cuts one from each end
    assert agg.seed_score([[0], [900], [910], [920], [1000]], 1000) == pytest.approx(0.91)
    assert agg.aggregate_name(5) == "IQM"
    # seeds of one parent are one unit: their mean
    assert agg.seed_score([[900, 920]], 1000) == pytest.approx(0.91)


def test_two_level_interval_holds_the_seed_spread_and_is_wider_than_seeds_only():
    units = [[900], [910], [920]]
    lo, hi = agg.seed_score_interval(units, 1000, reps=20_000)
    seeds_only = agg.iqm_interval([[900], [910], [920]], 1000, reps=20_000)
    assert seeds_only is not None
    assert lo < 0.90 and hi > 0.92  # contains every seed, not the range of three values
    assert hi - lo > seeds_only[1] - seeds_only[0]
    # one run: the episode interval (about a binomial's), never zero-width
    lo1, hi1 = agg.seed_score_interval([[900]], 1000, reps=20_000)
    assert lo1 < 0.9 < hi1 and 0.03 < hi1 - lo1 < 0.045
    assert agg.seed_score_interval(units, 1000) == agg.seed_score_interval(units, 1000)


def test_probability_of_improvement_against_one_run_has_episode_noise():
    value, ci = agg.probability_of_improvement_two_level([[[905]]], [[[900]]], 1000)
    assert value == 1.0 and ci[0] < ci[1]  # never 0.83 [0.83, 0.83]
    value, ci = agg.probability_of_improvement_two_level(
        [[[990], [992], [995]]], [[[900], [910], [880]]], 1000
    )
    assert value == 1.0 and ci == [1.0, 1.0]  # separated far beyond the episode noise


def test_paired_seed_difference_with_one_run_each_is_the_episode_bootstrap():
    rng = np.random.default_rng(3)
    a = (rng.random(200) < 0.8).astype(np.int64)
    b = (rng.random(200) < 0.9).astype(np.int64)
    idx = np.random.default_rng(7).integers(0, 200, (2000, 200))
    d = agg.paired_seed_difference([[a]], [[b]], idx)
    boot = b[idx].sum(axis=1) / 200 - a[idx].sum(axis=1) / 200
    assert d["diff"] == pytest.approx((int(b.sum()) - int(a.sum())) / 200)
    assert d["ci95"] == [float(np.percentile(boot, 2.5)), float(np.percentile(boot, 97.5))]
    # several seeds: the seed spread widens the interval of the mean difference
    a2 = [
        [a],
        [(rng.random(200) < 0.6).astype(np.int64)],
        [(rng.random(200) < 0.95).astype(np.int64)],
    ]
    d2 = agg.paired_seed_difference(a2, [[b]], idx)
    assert d2["ci95"][1] - d2["ci95"][0] > d["ci95"][1] - d["ci95"][0]
