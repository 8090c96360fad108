"""The field metrics of docs/model.md §10.1 (LoS events and time, intrusion severity,
conflicts, extra path and delay, manoeuvres, NMAC per flight hour): per-episode records from the
runner checked against what they mean, the conflict kernel against a brute-force reference,
and the aggregates against hand-computed values."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cdr_bench.evaluate.api import record_traces
from cdr_bench.evaluate.loader import load_agent
from cdr_bench.evaluate.metrics import Z95, group_metrics, poisson_rate
from cdr_bench.evaluate.runner import run_batch, spaces_for
from cdr_bench.scenarios import load_scenario
from cdr_bench.vector_env import VectorEnv, random_feasible_actions

AGENTS = Path(__file__).resolve().parents[2] / "agents"


def agent(name, config):
    return load_agent(AGENTS / name / "agent.py", *spaces_for(config))


@pytest.fixture(scope="module")
def high_direct():
    cfg = load_scenario("high")
    return cfg, run_batch(agent("direct", cfg), cfg, 0, 0, 40, 40)


def test_a_straight_flight_has_no_extra_path_delay_or_manoeuvre(high_direct):
    cfg, batch = high_direct
    ok = [a for e in batch["episodes"] for a in e["aircraft"] if a["outcome"] == "success"]
    assert len(ok) > 30
    for a in ok:
        assert a["manoeuvres"] == 0
        # cut at the goal circle: the path is the direct distance, not a whole last step more
        assert a["path_km"] == pytest.approx(a["direct_km"], abs=1e-3)
        assert a["flight_s"] == pytest.approx(a["direct_s"], abs=1e-3)
        assert a["flight_s"] < a["steps"] * cfg.time.dt_s  # the last step is cut
    m = group_metrics(ok)
    assert m["extra_path_km"]["value"] == pytest.approx(0.0, abs=1e-3)
    assert m["delay_s"]["value"] == pytest.approx(0.0, abs=1e-3)


def test_los_records_are_consistent(high_direct):
    cfg, batch = high_direct
    recs = [a for e in batch["episodes"] for a in e["aircraft"]]
    assert any(r["los"] for r in recs) and not all(r["los"] for r in recs)
    for r in recs:
        assert (r["los_events"] > 0) == r["los"]
        assert (r["los_s"] > 0) == r["los"]
        assert r["los_s"] <= r["steps"] * cfg.time.dt_s
        assert (r["nmac_events"] > 0) == r["nmac"]
        assert r["los_events"] >= r["nmac_events"]
        if r["los"]:  # below the threshold: severity in (0, 1]
            assert 0.0 < r["severity"] <= 1.0
            assert r["severity"] == pytest.approx(1 - r["min_sep_km"] / cfg.separation.los_km, 1e-3)
        elif r["severity"] is not None:
            assert r["severity"] == 0.0
        # a LoS of a straight flight is predicted at the previous decision: it was a conflict
        if r["los"]:
            assert r["conflicts"] >= 1


def test_mvp_manoeuvres_and_pays_for_it_in_path():
    cfg = load_scenario("high")
    mvp = run_batch(agent("mvp", cfg), cfg, 0, 0, 40, 40)
    recs = [a for e in mvp["episodes"] for a in e["aircraft"]]
    assert sum(r["manoeuvres"] for r in recs) > 0
    ok = [r for r in recs if r["outcome"] == "success"]
    assert all(r["path_km"] >= r["direct_km"] - 1e-6 for r in ok)  # never shorter than straight
    assert group_metrics(recs)["manoeuvres"]["value"] > 0


def _conflicts_reference(env: VectorEnv) -> np.ndarray:
    """Brute force, in numpy: same level, both in the sky, closest approach over the look-ahead
    below the LoS threshold."""
    sim = env.sim
    cfg = env.config
    look, los = cfg.observation.lookahead_s, cfg.separation.los_km
    out = np.zeros((sim.E, sim.M, sim.N), dtype=bool)
    for e in range(sim.E):
        for m in range(sim.M):
            i = sim.B + m
            if not sim.active[e, i]:
                continue
            for n in range(sim.N):
                if n == i or not sim.active[e, n] or sim.level[e, n] != sim.level[e, i]:
                    continue
                p = sim.pos_km[e, n] - sim.pos_km[e, i]
                v = sim.vel_km_s[e, n] - sim.vel_km_s[e, i]
                vv = float(v @ v)
                t = 0.0 if vv == 0 else min(max(-float(p @ v) / vv, 0.0), look)
                out[e, m, n] = math.hypot(*(p + v * t)) < los
    return out


@pytest.mark.parametrize("scenario", ["high", "marl/medium-4"])
def test_conflict_kernel_matches_brute_force(scenario):
    env = VectorEnv(scenario, num_envs=6, seed=1, autoreset=True)
    env.reset()
    rng = np.random.default_rng(0)
    seen = 0
    for _ in range(25):
        ref = _conflicts_reference(env)
        got = env.conflicts()
        assert np.array_equal(got, ref)
        seen += int(got.sum())
        masks = env.sim.action_masks()
        env.step(random_feasible_actions(masks, rng))
    assert seen > 0  # the comparison saw conflicts, not only empty arrays


def test_poisson_rate_interval():
    r = poisson_rate(0, 10.0)
    assert r["value"] == 0.0 and r["ci95"][0] == 0.0
    assert r["ci95"][1] == pytest.approx(Z95 * Z95 / 10.0, rel=1e-5)  # (z²/2 + z·z/2) / T
    r = poisson_rate(4, 2.0)
    half = Z95 * math.sqrt(4 + Z95 * Z95 / 4)
    assert r["value"] == 2.0
    assert r["ci95"] == [
        pytest.approx((4 + Z95**2 / 2 - half) / 2, abs=1e-6),
        pytest.approx((4 + Z95**2 / 2 + half) / 2, abs=1e-6),
    ]
    assert r["count"] == 4 and r["exposure_h"] == 2.0
    assert poisson_rate(3, 0.0)["value"] is None


def test_aggregates_by_hand():
    def rec(outcome, los, severity, path, direct, flight, dsec, nmac_ev=0, conflicts=0, man=0):
        return {
            "id": "ownship_0", "outcome": outcome, "steps": 10, "los": los, "nmac": nmac_ev > 0,
            "goal_reward": 0.0, "safety_reward": 0.0, "invalid_actions": 0, "min_sep_km": None,
            "severity": severity, "los_events": int(los), "los_s": 30.0 * los,
            "nmac_events": nmac_ev, "conflicts": conflicts, "manoeuvres": man,
            "flight_s": flight, "path_km": path, "direct_km": direct, "direct_s": dsec,
        }  # fmt: skip

    m = group_metrics(
        [
            rec("success", False, 0.0, 110.0, 100.0, 500.0, 450.0, conflicts=2, man=4),
            rec("success", True, 0.5, 104.0, 100.0, 470.0, 450.0, conflicts=1),
            rec("nmac", True, 0.9, 10.0, 100.0, 1800.0, 450.0, nmac_ev=1, man=2),
        ]
    )
    assert m["extra_path_km"]["value"] == pytest.approx(7.0)  # successes only: (10 + 4) / 2
    assert m["delay_s"]["value"] == pytest.approx(35.0)  # (50 + 20) / 2
    assert m["intrusion_severity"]["value"] == pytest.approx(0.7)  # LoS flights only
    assert m["intrusion_severity"]["n"] == 2
    assert m["conflicts"]["value"] == pytest.approx(1.0)
    assert m["manoeuvres"]["value"] == pytest.approx(2.0)
    assert m["los_time_s"]["value"] == pytest.approx(20.0)
    nm = m["nmac_per_flight_hour"]
    assert nm["count"] == 1 and nm["exposure_h"] == pytest.approx(2770.0 / 3600, abs=1e-6)
    assert nm["value"] == pytest.approx(3600 / 2770.0, abs=1e-6)


def test_traces_are_the_evaluated_episodes():
    cfg = load_scenario("tactical/head-on")
    traces = record_traces(AGENTS / "mvp" / "agent.py", cfg, 2, batch_size=8, n_episodes=8)
    batch = run_batch(agent("mvp", cfg), cfg, 0, 0, 8, 8)
    assert [t["episode"] for t in traces] == [0, 1]
    for t, ep in zip(traces, batch["episodes"], strict=False):
        assert t["seed"] == ep["seed"]
        assert t["outcomes"] == [a["outcome"] for a in ep["aircraft"]]
        assert len(t["frames"]) == ep["steps"] + 1  # the start and every step
        assert len(t["frames"][0]["c"]) == len(t["ids"]) == 1
        assert t["frames"][0]["los"] == [0]
        x0, y0 = t["frames"][0]["c"][0][:2]
        x1, y1 = t["frames"][1]["c"][0][:2]
        assert 0 < math.hypot(x1 - x0, y1 - y0) <= 10.0  # one step of ~7 km
        assert t["dt_s"] == cfg.time.dt_s and t["los_km"] == cfg.separation.los_km


def test_compare_of_chosen_metrics_equals_the_full_comparison(tmp_path):
    from cdr_bench.errors import UserError
    from cdr_bench.evaluate.api import evaluate, resolve_jobs
    from cdr_bench.evaluate.compare import compare

    jobs, _ = resolve_jobs(["high"], None, 8)
    a, b = tmp_path / "mvp.json", tmp_path / "direct.json"
    for name, out in (("mvp", a), ("direct", b)):
        evaluate(AGENTS / name, jobs, out, batch_size=8, progress=False)
    full = compare(a, b, ["high"])["rows"]
    some = compare(a, b, ["high"], ["clean_success_rate", "extra_path_km"])["rows"]
    assert [r["metric"] for r in some] == ["clean_success_rate", "extra_path_km"]
    assert some == [r for r in full if r["metric"] in ("clean_success_rate", "extra_path_km")]
    with pytest.raises(UserError, match="unknown metric"):
        compare(a, b, ["high"], ["clean_sucess_rate"])
