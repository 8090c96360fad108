"""Learning intruders placed by an encounter (docs/model.md §2.4, §8.4): each episode draws the
geometry of a placed aircraft's encounter (§8.3) for a controlled aircraft, which then meets the
ownship's straight flight as drawn and flies to the point of its track at twice the time to
CPA. Scenarios whose learning intruders fly airways are unchanged (the same canonical form, so
the same configuration hash; the same draws, so the same episodes: the leaderboard's replay)."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

import cdr_bench
from cdr_bench.scenarios import ScenarioError, load_scenario
from cdr_bench.sim import Simulator
from cdr_bench.sim.kernels import KM_PER_S_PER_KT, closest_approach
from cdr_bench.vector_env import agent_ids

ENC = {
    "time_to_cpa_s": [150.0, 260.0],
    "angle_deg": [60.0, 120.0],
    "miss_km": [1.0, 4.0],
    "speed_kt": [400.0, 470.0],
    "level": [0, 1, 2],
    "mirror": True,
}
FIXED = {"time_to_cpa_s": 200.0, "angle_deg": 180.0, "miss_km": -1.5, "speed_kt": 450.0, "level": 1}


def _config(*encounters: dict):
    return load_scenario(
        "tactical/head-on",
        aircraft=[],
        learning_intruders=[{"encounter": e} for e in encounters],
    )


def _meeting(sim: Simulator, e: int, m: int) -> tuple[float, float]:
    """Time to CPA (s) and distance at CPA (km) of controlled aircraft ``m``'s straight flight
    with the ownship's, from the state after the reset."""
    (px, py) = sim.ac_pos_km[e, m] - sim.ac_pos_km[e, 0]
    (vx, vy) = sim.ac_vel_km_s[e, m] - sim.ac_vel_km_s[e, 0]
    d, t = closest_approach(px, py, vx, vy, 1e9)
    return t, d


def test_an_intruder_meets_the_ownship_as_drawn_and_flies_past_it_to_its_goal():
    n = 300
    sim = Simulator(_config(ENC, FIXED), n)
    sim.reset(list(range(n)))
    assert agent_ids(sim.config) == ["ownship_0", "intruder_0", "intruder_1"]
    drawn = []
    for e in range(n):
        for m, enc in ((1, ENC), (2, FIXED)):
            t, d = _meeting(sim, e, m)
            t_lo, t_hi = np.broadcast_to(enc["time_to_cpa_s"], 2)
            assert t_lo - 1e-6 <= t <= t_hi + 1e-6
            lo, hi = sorted(abs(x) for x in np.broadcast_to(enc["miss_km"], 2))
            assert lo - 1e-6 <= d <= hi + 1e-6
            v = sim.ac_vel_km_s[e, m]
            speed_kt = math.hypot(*v) / KM_PER_S_PER_KT
            s_lo, s_hi = np.broadcast_to(enc["speed_kt"], 2)
            assert s_lo - 1e-9 <= speed_kt <= s_hi + 1e-9
            assert sim.ac_speed_kt[e, m] == pytest.approx(speed_kt, abs=1e-9)
            # the goal: its straight track at twice the time to CPA
            goal = sim.ac_pos_km[e, m] + v * (2.0 * t)
            assert np.allclose(sim.ac_goal_km[e, m], goal, atol=1e-6)
        drawn.append(_meeting(sim, e, 1)[0])
    assert len(set(np.round(drawn, 6))) == n  # drawn per episode
    assert set(sim.level[:, sim.B + 1].tolist()) == {0, 1, 2}
    assert (sim.level[:, sim.B + 2] == 1).all()
    # mirrored in about half of the episodes: the intruder comes from either side
    side = np.sign(sim.ac_pos_km[:, 1, 1] - sim.ac_pos_km[:, 0, 1])
    assert 0.35 < (side > 0).mean() < 0.65
    # the same seeds give the same episodes
    again = Simulator(_config(ENC, FIXED), n)
    again.reset(list(range(n)))
    assert np.array_equal(again.ac_pos_km, sim.ac_pos_km)


def test_intruders_start_clear_of_the_ownship_and_of_each_other():
    close = {**FIXED, "time_to_cpa_s": [30.0, 200.0], "angle_deg": [150.0, 210.0]}
    n = 200
    sim = Simulator(_config(close, close), n)
    sim.reset(list(range(n)))
    own = sim.ac_pos_km[:, 0]
    for m in (1, 2):
        same = sim.level[:, sim.B + m] == sim.level[:, sim.B]
        gap = np.hypot(*(sim.ac_pos_km[:, m] - own).T)
        assert (gap[same] >= 20.0).all()
    same = sim.level[:, sim.B + 1] == sim.level[:, sim.B + 2]
    assert (np.hypot(*(sim.ac_pos_km[:, 1] - sim.ac_pos_km[:, 2]).T)[same] >= 20.0).all()


def test_pettingzoo_parallel_api_on_intruders_placed_by_encounters(tmp_path: Path):
    from pettingzoo.test import parallel_api_test

    path = tmp_path / "converge.yaml"
    path.write_text(
        "extends: tactical/head-on\n"
        "description: two learning intruders converging on the ownship\n"
        "aircraft: []\n"
        "learning_intruders:\n"
        f"  - encounter: {ENC}\n"
        f"  - encounter: {FIXED}\n".replace("'", "")
    )
    env = cdr_bench.parallel_env(str(path))
    parallel_api_test(env, num_cycles=60)
    obs, _ = env.reset(seed=3)
    assert sorted(obs) == ["intruder_0", "intruder_1", "ownship_0"]


def test_canonical_form_of_airway_intruders_is_unchanged():
    li = load_scenario("marl/medium-4").to_dict()["learning_intruders"]
    assert li == [{"airway": 0}, {"airway": 3}, {"airway": 6}, {"airway": 9}]
    assert _config(FIXED).to_dict()["learning_intruders"][0]["encounter"]["miss_km"] == -1.5


@pytest.mark.parametrize(
    ("intruder", "problem"),
    [
        ({"airway": 0, "encounter": FIXED}, "learning_intruders[0]"),
        ({}, "learning_intruders[0].airway"),
        ({"encounter": {**FIXED, "time_to_cpa_s": [300.0, 100.0]}}, "lo <= hi"),
        ({"encounter": {**FIXED, "time_to_cpa_s": 3000.0}}, "outside the sector"),
    ],
)
def test_bad_encounter_intruders_are_refused(intruder: dict, problem: str):
    with pytest.raises(ScenarioError, match=re.escape(problem)):
        load_scenario("tactical/head-on", aircraft=[], learning_intruders=[intruder])


def test_an_encounter_intruder_needs_an_explicit_ownship_start():
    with pytest.raises(ScenarioError, match="expected an explicit ownship.start"):
        load_scenario("marl/medium-4", learning_intruders=[{"encounter": FIXED}])
