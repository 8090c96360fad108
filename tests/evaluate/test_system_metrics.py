"""System metrics (docs/model.md §10.1.3): every controlled aircraft of an episode together,
the episode the unit; and one agent flying every controlled aircraft of a scenario."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cdr_bench.evaluate.loader import load_agent
from cdr_bench.evaluate.metrics import (
    METRICS,
    SYSTEM_METRICS,
    Metric,
    get_metric,
    ratio_interval,
    resample_indices,
    scenario_metrics,
    system_metrics,
    wilson_interval,
)
from cdr_bench.evaluate.report import report_markdown, summary_text
from cdr_bench.evaluate.runner import run_batch, spaces_for
from cdr_bench.scenarios import load_scenario

AGENTS = Path(__file__).resolve().parents[2] / "agents"


def rec(i, outcome="success", los=False, los_ev=0, los_ac=0, nmac_ev=0, nmac_ac=0, delay=0.0,
        extra=0.0, man=0, flight=600.0, aid=None):  # fmt: skip
    return {
        "id": aid or ("ownship_0" if i == 0 else f"aircraft_{i - 1}"),
        "outcome": outcome, "steps": 20, "los": los, "nmac": nmac_ev > 0, "goal_reward": 0.0,
        "safety_reward": 0.0, "invalid_actions": 0, "min_sep_km": None, "severity": None,
        "los_events": los_ev, "los_s": 0.0, "nmac_events": nmac_ev, "conflicts": 0,
        "manoeuvres": man, "flight_s": flight, "path_km": 100.0 + extra, "direct_km": 100.0,
        "direct_s": flight - delay, "los_events_ac": los_ac, "nmac_events_ac": nmac_ac,
    }  # fmt: skip


def test_system_metrics_by_hand():
    # Episode 1: aircraft 0 and 1 lose separation with each other (one pair, in both records)
    # and aircraft 1 also with a background aircraft; aircraft 2 is clean, delayed 60 s.
    ep1 = [
        rec(0, los=True, los_ev=1, los_ac=1, delay=30.0, extra=2.0, man=2),
        rec(1, los=True, los_ev=2, los_ac=1, delay=0.0, man=1),
        rec(2, delay=60.0, extra=4.0, man=3),
    ]
    # Episode 2: an NMAC between two controlled aircraft ends both; the third is clean.
    ep2 = [
        rec(0, "nmac", los=True, los_ev=1, los_ac=1, nmac_ev=1, nmac_ac=1, flight=300.0),
        rec(1, "nmac", los=True, los_ev=1, los_ac=1, nmac_ev=1, nmac_ac=1, flight=300.0),
        rec(2, delay=-10.0),
    ]
    m = system_metrics([{"aircraft": ep1}, {"aircraft": ep2}])
    assert m is not None and m["episodes"] == 2 and m["flights"] == 6
    hours = (3 * 600 + 2 * 300 + 600) / 3600
    assert m["system_los_per_flight_hour"]["count"] == 2 + 1  # pairs: (0,1), (1,bg); (0,1)
    assert m["system_los_per_flight_hour"]["value"] == pytest.approx(3 / hours, abs=1e-6)
    assert m["system_los_per_flight_hour"]["exposure_h"] == pytest.approx(hours, abs=1e-6)
    assert m["system_nmac_per_flight_hour"]["count"] == 1
    assert m["system_success_rate"]["value"] == pytest.approx(4 / 6, abs=1e-6)
    assert m["system_clean_rate"]["count"] == 2 and m["system_clean_rate"]["n"] == 6
    assert m["system_clean_episode_rate"]["value"] == 0.0
    assert m["system_delay_s"]["value"] == pytest.approx((30 + 0 + 60 - 10) / 4, abs=1e-6)
    assert m["system_extra_path_km"]["value"] == pytest.approx(6 / 4, abs=1e-6)
    assert m["system_manoeuvres"]["value"] == pytest.approx(6 / 6, abs=1e-6)
    # Spread: std of (30, 0, 60) in episode 1; episode 2 has one successful flight only.
    assert m["system_delay_spread_s"]["value"] == pytest.approx(np.std([30, 0, 60]), abs=1e-6)
    assert m["system_delay_spread_s"]["episodes"] == 1
    for key in (k.key for k in SYSTEM_METRICS):
        lo, hi = m[key]["ci95"]
        assert lo <= m[key]["value"] <= hi


def test_no_system_metrics_with_one_controlled_aircraft():
    assert system_metrics([{"aircraft": [rec(0)]}, {"aircraft": [rec(0)]}]) is None
    assert system_metrics([]) is None


def test_the_interval_resamples_episodes_not_flights():
    # 40 episodes of 10 flights each, all clean in half the episodes and none in the others:
    # the flights of an episode are one unit, so the interval is that of 40 trials, not 400.
    eps = [{"aircraft": [rec(i, los=e % 2 == 1) for i in range(10)]} for e in range(40)]
    m = system_metrics(eps)
    assert m is not None
    clean = m["system_clean_rate"]
    assert clean["value"] == 0.5 and clean["n"] == 400
    lo, hi = clean["ci95"]
    flights_lo, flights_hi = wilson_interval(200, 400)
    episodes_lo, episodes_hi = wilson_interval(20, 40)
    assert hi - lo > 1.5 * (flights_hi - flights_lo)
    assert hi - lo == pytest.approx(episodes_hi - episodes_lo, rel=0.25)
    # The same by hand: the shared resampled indices, a ratio of sums per resample.
    nd = np.array([[0.0 if e % 2 else 10.0, 10.0] for e in range(40)])
    sums = nd[resample_indices(40)].sum(axis=1)
    want = np.percentile(sums[:, 0] / sums[:, 1], [2.5, 97.5])
    assert (lo, hi) == (round(want[0], 6), round(want[1], 6))
    assert ratio_interval(nd) == pytest.approx(tuple(want))


def test_system_metrics_are_registered_apart_from_the_per_role_ones():
    keys = [m.key for m in SYSTEM_METRICS]
    assert keys and all(k.startswith("system_") for k in keys)
    assert not set(keys) & {m.key for m in METRICS}  # not columns of the role tables
    assert get_metric("system_clean_rate").scope == "system"
    with pytest.raises(ValueError, match="denominator"):
        Metric("x", "x", "rate", True, lambda ep: 0, scope="system")
    with pytest.raises(ValueError, match="scope"):
        Metric("x", "x", "rate", True, lambda ep: 0, lambda ep: 1, scope="episode")
    # The paired form (per episode: numerator, denominator) of a system metric.
    ep = [rec(0, los=True, los_ev=1, los_ac=1), rec(1, los=True, los_ev=1, los_ac=1)]
    assert get_metric("system_los_per_flight_hour").paired(ep) == (1.0, 1200.0 / 3600.0)


def _agent(name, config):
    return load_agent(AGENTS / name / "agent.py", *spaces_for(config))


@pytest.fixture(scope="module")
def low_all():
    cfg = load_scenario("marl/low-all")
    runs = {a: run_batch(_agent(a, cfg), cfg, 0, 0, 30, 30) for a in ("direct", "mvp")}
    return cfg, runs


def test_one_agent_flies_every_controlled_aircraft(low_all):
    cfg, runs = low_all
    for name, run in runs.items():
        for ep in run["episodes"]:
            acs = ep["aircraft"]
            assert [a["id"] for a in acs] == ["ownship_0"] + [f"aircraft_{i}" for i in range(24)]
            assert all(len(a["actions"]) == a["steps"] > 0 for a in acs)  # every one decided
            # A pair of controlled aircraft is in both records: the sums are even.
            assert sum(a["los_events_ac"] for a in acs) % 2 == 0
            assert sum(a["nmac_events_ac"] for a in acs) % 2 == 0
            assert all(a["los_events_ac"] <= a["los_events"] for a in acs)
        traffic = [a for ep in run["episodes"] for a in ep["aircraft"][1:]]
        moved = sum(a["manoeuvres"] for a in traffic)
        assert (moved > 0) == (name == "mvp")  # mvp resolves for the airway aircraft too
    direct, mvp = (system_metrics(runs[a]["episodes"]) for a in ("direct", "mvp"))
    assert direct is not None and mvp is not None
    assert direct["system_los_per_flight_hour"]["count"] > 0  # uncontrolled airways conflict
    assert mvp["system_clean_rate"]["value"] > direct["system_clean_rate"]["value"]
    roles = scenario_metrics(runs["mvp"]["episodes"])
    assert set(roles) == {"ownship", "traffic"} and roles["traffic"]["episodes"] == 30 * 24


def test_single_aircraft_records_carry_no_pair_fields_and_tables_show_the_system(low_all):
    cfg = load_scenario("low")
    run = run_batch(_agent("direct", cfg), cfg, 0, 0, 2, 2)
    assert "los_events_ac" not in run["episodes"][0]["aircraft"][0]  # records as before
    _, runs = low_all
    eps = runs["mvp"]["episodes"]
    result = {
        "agent": {"name": "mvp", "path": "agents/mvp", "sha256": "0" * 64},
        "base_seed": 0,
        "versions": {},
        "scenarios": [
            {
                "id": "marl/low-all",
                "episodes": len(eps),
                "metrics": scenario_metrics(eps),
                "system_metrics": system_metrics(eps),
            }
        ],
    }
    text = summary_text(result)
    assert "system (every controlled aircraft" in text and "LoS/h" in text
    md = report_markdown([("r.json", result)])
    assert "System metrics" in md and "delay spread s" in md


def test_compare_pairs_the_system_metrics_over_whole_episodes(low_all, monkeypatch):
    """``cdr-bench compare`` of two multi-agent results has a ``system`` row for every system
    metric: the values are the results' own system metrics, the interval pairs whole episodes;
    a metric filter keeps only the named ones, and a one-aircraft scenario has no such row."""
    from cdr_bench.evaluate import compare as cmp_mod

    _, runs = low_all

    def result(name: str, episodes: list) -> tuple[dict, list]:
        sc = {"id": "marl/low-all", "config_hash": "c", "episodes": 30, "seeds_sha256": "s"}
        eps = [{**e, "scenario": "marl/low-all"} for e in episodes]
        return {"agent": {"name": name}, "scenarios": [sc]}, eps

    loaded = {p: result(p, runs[p]["episodes"]) for p in ("direct", "mvp")}
    monkeypatch.setattr(cmp_mod, "_load", lambda p: loaded[str(p)])
    got = cmp_mod.compare("direct", "mvp")
    rows = {r["metric"]: r for r in got["rows"] if r["aircraft"] == "system"}
    assert set(rows) == {m.key for m in SYSTEM_METRICS}
    a, b = (system_metrics(runs[n]["episodes"]) for n in ("direct", "mvp"))
    clean = rows["system_clean_rate"]
    assert clean["a"] == pytest.approx(a["system_clean_rate"]["value"], abs=1e-6)
    assert clean["b"] == pytest.approx(b["system_clean_rate"]["value"], abs=1e-6)
    lo, hi = clean["ci95"]
    assert lo <= clean["diff"] <= hi and clean["diff"] > 0 and clean["significant"]
    assert "system" in cmp_mod.comparison_table(got)
    only = cmp_mod.compare("direct", "mvp", metrics=["system_los_per_flight_hour", "success_rate"])
    assert {(r["aircraft"], r["metric"]) for r in only["rows"]} == {
        ("system", "system_los_per_flight_hour"),
        ("ownship", "success_rate"),
        ("traffic", "success_rate"),
    }
    single = {
        p: (r, [{**e, "aircraft": e["aircraft"][:1]} for e in eps])
        for p, (r, eps) in loaded.items()
    }
    monkeypatch.setattr(cmp_mod, "_load", lambda p: single[str(p)])
    assert all(r["aircraft"] != "system" for r in cmp_mod.compare("direct", "mvp")["rows"])
