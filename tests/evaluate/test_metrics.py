"""Metrics on hand-built episode logs, Wilson intervals against hand-computed values, bootstrap
determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cdr_bench.evaluate.metrics import (
    bootstrap_mean_interval,
    group_metrics,
    scenario_metrics,
    wilson_interval,
)


def rec(outcome, steps=10, los=False, goal=0.0, safety=0.0, invalid=0, id="ownship_0"):
    return {
        "id": id,
        "outcome": outcome,
        "steps": steps,
        "los": los,
        "nmac": outcome == "nmac",
        "goal_reward": goal,
        "safety_reward": safety,
        "invalid_actions": invalid,
        "min_sep_km": None,
        "severity": None,
        "los_events": int(los),
        "los_s": 30.0 * los,
        "nmac_events": int(outcome == "nmac"),
        "conflicts": 0,
        "manoeuvres": 0,
        "flight_s": 30.0 * steps,
        "path_km": 6.6 * steps,
        "direct_km": 6.6 * steps,
        "direct_s": 30.0 * steps,
    }


def test_metrics_on_a_hand_built_log():
    records = [
        rec("success", steps=40, los=False, goal=-3.0),
        rec("success", steps=50, los=True, goal=-4.0, safety=-1.0),
        rec("success", steps=60, los=False, goal=-5.0, invalid=3),
        rec("nmac", steps=20, los=True, goal=-2.0, safety=-1.5),
        rec("timeout", steps=1000, los=False, goal=-60.0, invalid=2),
    ]
    m = group_metrics(records)
    assert m["episodes"] == 5
    assert m["success_rate"]["value"] == 0.6 and m["success_rate"]["count"] == 3
    assert m["nmac_rate"]["value"] == 0.2
    assert m["timeout_rate"]["value"] == 0.2
    assert m["los_terminated_rate"]["value"] == 0.0
    assert m["boundary_rate"]["value"] == 0.0
    assert m["los_rate"]["value"] == 0.4  # any LoS, whatever the outcome
    assert m["clean_success_rate"]["value"] == 0.4
    assert m["avg_steps_success"]["value"] == 50.0
    assert m["goal_reward"]["value"] == pytest.approx(-14.8)
    assert m["safety_reward"]["value"] == pytest.approx(-0.5)
    assert m["invalid_action_rate"]["count"] == 5 and m["invalid_action_rate"]["n"] == 1170
    outcome_rates = [
        "success_rate",
        "nmac_rate",
        "los_terminated_rate",
        "boundary_rate",
        "timeout_rate",
    ]
    assert sum(m[k]["count"] for k in outcome_rates) == m["episodes"]  # a partition


def test_los_terminated_and_boundary_partition():
    records = [rec("los", los=True), rec("boundary"), rec("success"), rec("success", los=True)]
    m = group_metrics(records)
    assert m["los_terminated_rate"]["value"] == 0.25
    assert m["boundary_rate"]["value"] == 0.25
    assert m["los_rate"]["value"] == 0.5
    total = sum(
        m[k]["value"]
        for k in (
            "success_rate",
            "nmac_rate",
            "los_terminated_rate",
            "boundary_rate",
            "timeout_rate",
        )
    )
    assert total == pytest.approx(1.0)


def test_unknown_outcome_is_refused():
    with pytest.raises(ValueError, match="unknown outcome"):
        group_metrics([rec("crashed")])


def test_ownship_and_intruders_reported_apart():
    eps = [
        {
            "aircraft": [
                rec("success"),
                rec("nmac", id="intruder_0"),
                rec("success", id="intruder_1"),
            ]
        },
        {
            "aircraft": [
                rec("timeout"),
                rec("success", id="intruder_0"),
                rec("success", id="intruder_1"),
            ]
        },
    ]
    m = scenario_metrics(eps)
    assert m["ownship"]["episodes"] == 2 and m["ownship"]["success_rate"]["value"] == 0.5
    assert m["intruders"]["episodes"] == 4 and m["intruders"]["nmac_rate"]["value"] == 0.25
    assert "intruders" not in scenario_metrics([{"aircraft": [rec("success")]}])


def test_wilson_against_hand_computed_values():
    # k = 8, n = 10, z = 1.959964: centre = (0.8 + z^2/20) / (1 + z^2/10),
    # half = z sqrt(0.8*0.2/10 + z^2/400) / (1 + z^2/10)
    z = 1.959963984540054
    centre = (0.8 + z * z / 20) / (1 + z * z / 10)
    half = z * math.sqrt(0.016 + z * z / 400) / (1 + z * z / 10)
    lo, hi = wilson_interval(8, 10)
    assert lo == pytest.approx(centre - half) and hi == pytest.approx(centre + half)
    assert (round(lo, 4), round(hi, 4)) == (0.4902, 0.9433)  # published table value
    lo, hi = wilson_interval(0, 50)
    assert lo == pytest.approx(0.0, abs=1e-12) and hi == pytest.approx(0.07135, abs=1e-4)
    lo, hi = wilson_interval(50, 50)
    assert hi == 1.0 and lo == pytest.approx(1 - 0.07135, abs=1e-4)
    assert all(math.isnan(x) for x in wilson_interval(0, 0))


def test_bootstrap_is_deterministic_and_sane():
    x = [float(i % 7) for i in range(200)]
    a, b = bootstrap_mean_interval(x), bootstrap_mean_interval(x)
    assert a == b
    mean = sum(x) / len(x)
    assert a[0] < mean < a[1] and a[1] - a[0] < 1.0
    assert bootstrap_mean_interval([3.0]) == (3.0, 3.0)
    assert all(math.isnan(v) for v in bootstrap_mean_interval([]))


def test_resampled_sums_are_numpys_bit_for_bit() -> None:
    # the bootstrap adds each resample without gathering it, in numpy's own order: the same
    # bits as x[indices].sum(axis=1) (so the same intervals on any CPU: no BLAS involved)
    from cdr_bench.evaluate.metrics import (
        _resampled_row_sums,
        _resampled_sums,
        bootstrap_mean_interval,
        ratio_interval,
        resample_indices,
    )

    rng = np.random.default_rng(3)
    for n in (*range(2, 140), 537, 1000, 2001):
        idx = resample_indices(n, 64, 7)
        x = rng.normal(50.0, 20.0, n) * rng.random(n)
        assert np.array_equal(_resampled_sums(x, idx), x[idx].sum(axis=1))
        nd = np.stack([rng.integers(0, 3, n).astype(float), rng.random(n)], axis=1)
        assert np.array_equal(_resampled_row_sums(nd, idx), nd[idx].sum(axis=1))
    x, idx = rng.normal(5.0, 2.0, 537), resample_indices(537)
    lo, hi = np.percentile(x[idx].mean(axis=1), [2.5, 97.5])
    assert bootstrap_mean_interval(x) == (lo, hi)
    sums = nd[resample_indices(2001)].sum(axis=1)
    assert ratio_interval(nd) == tuple(np.percentile(sums[:, 0] / sums[:, 1], [2.5, 97.5]))
