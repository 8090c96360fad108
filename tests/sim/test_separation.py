"""Separation judged over the whole step: closest point of approach, levels, transitions."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cdr_bench import actions
from cdr_bench.sim import Simulator
from cdr_bench.sim.geometry import closest_approach
from cdr_bench.sim.units import KM_PER_S_PER_KT
from tests.conftest import make_config

STEP_KM = 30.0 * 430.0 * KM_PER_S_PER_KT  # 6.637 km


def encounter(
    own_level=1,
    other_level=1,
    other_pos=(200.0, 200.0),
    other_heading=270.0,
    own_pos=(200.0 - 0.5 * STEP_KM * 2, 200.0),
    offset_km=0.0,
    **kw,
):
    cfg = make_config(
        ownship={
            "start": {
                "position_km": list(own_pos),
                "heading_deg": 90.0,
                "speed_kt": 430.0,
                "level": own_level,
            },
            "goal_km": [390.0, 390.0],
        },
        aircraft=[
            {
                "position_km": [other_pos[0], other_pos[1] + offset_km],
                "heading_deg": other_heading,
                "speed_kt": 430.0,
                "level": other_level,
            }
        ],
        **kw,
    )
    sim = Simulator(cfg)
    sim.reset([0])
    return sim


def test_closest_approach_closed_form():
    d, t = closest_approach(10.0, 3.0, -1.0, 0.0, 30.0)
    assert d == pytest.approx(3.0) and t == pytest.approx(10.0)
    d, t = closest_approach(10.0, 3.0, -1.0, 0.0, 5.0)  # clipped
    assert d == pytest.approx(np.hypot(5.0, 3.0)) and t == 5.0
    d, t = closest_approach(10.0, 3.0, 1.0, 0.0, 30.0)  # diverging
    assert d == pytest.approx(np.hypot(10.0, 3.0)) and t == 0.0
    d, t = closest_approach(4.0, 3.0, 0.0, 0.0, 30.0)  # static
    assert d == pytest.approx(5.0) and t == 0.0


@settings(max_examples=300, deadline=None)
@given(
    p=st.tuples(*[st.floats(-500, 500)] * 2),
    v=st.tuples(*[st.floats(-0.5, 0.5)] * 2),
    horizon=st.floats(0.0, 600.0),
)
def test_closest_approach_is_the_minimum_over_the_interval(p, v, horizon):
    # The closed form against a dense sampling of the segment: never above any sample, and
    # the time returned attains the distance returned.
    d, t = closest_approach(p[0], p[1], v[0], v[1], horizon)
    ts = np.linspace(0.0, horizon, 2001)
    sampled = np.hypot(p[0] + v[0] * ts, p[1] + v[1] * ts)
    assert 0.0 <= t <= horizon
    assert d <= sampled.min() + 1e-9
    assert d == pytest.approx(np.hypot(p[0] + v[0] * t, p[1] + v[1] * t), abs=1e-9)


def test_head_on_pass_through_between_step_ends_is_nmac():
    # Head-on, 6.64 km apart: they end 6.64 km apart on the other side, so the sampled
    # distance never drops below 6 km, yet they pass through each other mid-step.
    sim = encounter(own_pos=(200.0 - STEP_KM / 2, 200.0), other_pos=(200.0 + STEP_KM / 2, 200.0))
    start_gap = np.linalg.norm(sim.ac_pos_km[0, 0] - sim.bg_pos_km[0, 0])
    r = sim.step(np.array([[actions.HOLD]]))
    end_gap = np.linalg.norm(sim.ac_pos_km[0, 0] - sim.bg_pos_km[0, 0])
    assert start_gap > 6.0 and end_gap > 6.0
    assert r.nmac_with[0, 0, 0] and r.terminated[0, 0]
    assert r.rewards["nmac"][0, 0] == -1.0 and r.rewards["los"][0, 0] == 0.0
    assert r.outcome[0, 0] == 2  # NMAC


def test_vertical_separation_prevents_los():
    sim = encounter(
        other_level=2, own_pos=(200.0 - STEP_KM / 2, 200.0), other_pos=(200.0 + STEP_KM / 2, 200.0)
    )
    r = sim.step(np.array([[actions.HOLD]]))
    assert not r.los_with.any() and not r.terminated[0, 0]
    assert r.min_sep_km[0, 0] == np.inf


@pytest.mark.parametrize(
    "own_level,action,other_level,expect",
    [
        (1, (0, 0, 1), 1, True),  # climbing from 1 to 2: still occupies 1
        (1, (0, 0, 1), 2, True),  # ... and already occupies 2
        (1, (0, 0, 1), 0, False),  # never at 0
        (1, (0, 0, -1), 0, True),
        (2, (0, 0, 1), 1, False),  # masked climb at 2 is not executed: stays at 2 only
    ],
)
def test_level_change_counts_against_both_levels(own_level, action, other_level, expect):
    sim = encounter(
        own_level=own_level,
        other_level=other_level,
        offset_km=3.0,
        own_pos=(200.0 - STEP_KM / 2, 200.0),
        other_pos=(200.0 + STEP_KM / 2, 200.0),
    )
    r = sim.step(np.array([[actions.encode(action)]]))
    assert bool(r.los_with[0, 0, 0]) is expect
    if expect:
        assert r.rewards["los"][0, 0] == -0.5 and not r.nmac_with[0, 0, 0]


def test_minimum_reached_mid_step_is_found():
    # Head-on with a 2 km lateral offset, passing mid-step: both step ends are 6.9 km apart,
    # above a 5 km LoS threshold, while the true minimum (2 km) is reached half-way.
    sim = encounter(
        offset_km=2.0,
        own_pos=(200.0 - STEP_KM / 2, 200.0),
        other_pos=(200.0 + STEP_KM / 2, 200.0),
        separation={"los_km": 5.0},
    )
    gap0 = np.linalg.norm(sim.ac_pos_km[0, 0] - sim.bg_pos_km[0, 0])
    r = sim.step(np.array([[actions.HOLD]]))
    gap1 = np.linalg.norm(sim.ac_pos_km[0, 0] - sim.bg_pos_km[0, 0])
    assert gap0 > 5.0 and gap1 > 5.0
    assert r.min_sep_km[0, 0] == pytest.approx(2.0)
    assert r.los_with[0, 0, 0] and not r.nmac_with[0, 0, 0]


def test_los_terminates_only_where_scenario_says_so():
    kw = dict(
        offset_km=5.0, own_pos=(200.0 - STEP_KM / 2, 200.0), other_pos=(200.0 + STEP_KM / 2, 200.0)
    )
    r = encounter(**kw).step(np.array([[actions.HOLD]]))
    assert r.los_with[0, 0, 0] and not r.terminated[0, 0]
    sim = encounter(separation={"los_terminates": True}, **kw)
    r = sim.step(np.array([[actions.HOLD]]))
    assert r.terminated[0, 0] and r.outcome[0, 0] == 3  # LOS


def test_learning_intruders_are_judged_against_each_other():
    cfg = make_config(
        airways=[
            {"start_km": [0.0, 200.0], "end_km": [400.0, 200.0]},
            {"start_km": [400.0, 200.0], "end_km": [0.0, 200.0]},
        ],
        learning_intruders=[{"airway": 0}, {"airway": 1}],
        ownship={
            "start": {
                "position_km": [200.0, 20.0],
                "heading_deg": 0.0,
                "speed_kt": 430.0,
                "level": 1,
            },
            "goal_km": [200.0, 380.0],
        },
    )
    sim = Simulator(cfg)
    sim.reset([3])
    sim.ac_level[0, 1:] = 0  # same level, head-on along the same line
    hold = np.full((1, 3), actions.HOLD)
    outcomes = []
    for _ in range(40):
        r = sim.step(hold)
        if r.nmac_with[0, 1, sim.B + 2]:
            outcomes.append("nmac")
            assert r.nmac_with[0, 2, sim.B + 1]  # symmetric
            break
    assert outcomes == ["nmac"]
