"""Closed-form kinematics of the controlled aircraft and the action table."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cdr_bench import actions
from cdr_bench.sim import Simulator
from cdr_bench.sim.units import KM_PER_S_PER_KT
from tests.conftest import make_config


def lone_ownship(
    heading=90.0, speed=430.0, level=1, pos=(100.0, 200.0), goal=(390.0, 390.0), ownship=None, **kw
):
    own = {
        "start": {
            "position_km": list(pos),
            "heading_deg": heading,
            "speed_kt": speed,
            "level": level,
        },
        "goal_km": list(goal),
        **(ownship or {}),
    }
    cfg = make_config(ownship=own, **kw)
    sim = Simulator(cfg)
    sim.reset([0])
    return sim


def test_action_table_round_trip():
    assert actions.HOLD == 13
    assert actions.decode(0) == (-1, -1, -1)
    assert actions.decode(26) == (1, 1, 1)
    for i in range(27):
        assert actions.encode(actions.decode(i)) == i
    with pytest.raises(ValueError):
        actions.decode(27)
    with pytest.raises(ValueError):
        actions.encode((2, 0, 0))
    assert actions.describe(actions.encode((-1, 0, 1))) == "left/climb"


def test_mask_only_level_bounds():
    m = actions.action_mask(np.array([0, 1, 2]))
    assert m.shape == (3, 27) and m.dtype == np.int8
    assert m[1].all()
    assert m[0].sum() == 18 and not m[0][actions.DESCEND].any()
    assert m[2].sum() == 18 and not m[2][actions.CLIMB].any()


def test_straight_flight_closed_form():
    sim = lone_ownship(heading=90.0, speed=430.0)
    for _ in range(10):
        sim.step(np.array([[actions.HOLD]]))
    expected_x = 100.0 + 10 * 30.0 * 430.0 * KM_PER_S_PER_KT  # 1 kt = 1.852 km/h
    assert sim.ac_pos_km[0, 0, 0] == pytest.approx(expected_x, abs=1e-9)
    assert sim.ac_pos_km[0, 0, 1] == pytest.approx(200.0, abs=1e-9)
    assert expected_x - 100.0 == pytest.approx(10 * 6.63633, abs=1e-3)  # 430 kt over 30 s


def test_heading_north_moves_north_and_turn_is_clockwise():
    sim = lone_ownship(heading=0.0, pos=(200.0, 100.0))
    turn_right = actions.encode((1, 0, 0))
    sim.step(np.array([[turn_right]]))
    assert sim.ac_heading_deg[0, 0] == pytest.approx(5.0)
    step_km = 30.0 * 430.0 * KM_PER_S_PER_KT
    np.testing.assert_allclose(
        sim.ac_pos_km[0, 0],
        [200.0 + step_km * math.sin(math.radians(5)), 100.0 + step_km * math.cos(math.radians(5))],
    )
    left = actions.encode((-1, 0, 0))
    for _ in range(3):
        sim.step(np.array([[left]]))
    assert sim.ac_heading_deg[0, 0] == pytest.approx(350.0)


def test_speed_is_clipped_not_masked():
    sim = lone_ownship(speed=430.0)
    faster = actions.encode((0, 1, 0))
    for _ in range(5):
        sim.step(np.array([[faster]]))
    assert sim.ac_speed_kt[0, 0] == 530.0
    slower = actions.encode((0, -1, 0))
    for _ in range(6):
        sim.step(np.array([[slower]]))
    assert sim.ac_speed_kt[0, 0] == 330.0


def test_level_change_and_infeasible_level_not_executed():
    sim = lone_ownship(level=1)
    climb = actions.encode((0, 0, 1))
    r = sim.step(np.array([[climb]]))
    assert sim.ac_level[0, 0] == 2 and not r.invalid_action[0, 0]
    r = sim.step(np.array([[actions.encode((1, 0, 1))]]))  # climb at the top: masked
    assert sim.ac_level[0, 0] == 2 and r.invalid_action[0, 0]
    assert sim.ac_heading_deg[0, 0] == pytest.approx(95.0)  # the heading part still applies


def test_goal_reached_by_swept_test_between_step_ends():
    # Goal 3.3 km after the first end-of-step point: passed mid-step, never sampled within 5 km
    # at a step end if the goal radius were tested only at the ends with a 2 km radius.
    step_km = 30.0 * 430.0 * KM_PER_S_PER_KT
    sim = lone_ownship(
        pos=(100.0, 200.0), goal=(100.0 + 1.5 * step_km, 200.0), ownship={"goal_radius_km": 2.0}
    )
    r = sim.step(np.array([[actions.HOLD]]))
    assert not r.reached_goal[0, 0]  # 1.5 steps away: the first segment ends 3.3 km short
    r = sim.step(np.array([[actions.HOLD]]))
    assert r.reached_goal[0, 0] and r.terminated[0, 0]
    assert r.rewards["goal"][0, 0] == 1.0


def test_boundary_penalty_and_timeout():
    sim = lone_ownship(heading=270.0, pos=(3.0, 200.0), time={"max_steps": 3})
    r = sim.step(np.array([[actions.HOLD]]))
    assert r.outside[0, 0] and r.rewards["boundary"][0, 0] == -0.5
    assert not r.terminated[0, 0]
    sim.step(np.array([[actions.HOLD]]))
    r = sim.step(np.array([[actions.HOLD]]))
    assert r.truncated[0, 0] and r.rewards["timeout"][0, 0] == -0.5
    assert not sim.ac_active[0, 0]


def test_path_penalty_closed_form():
    sim = lone_ownship(pos=(0.0, 0.0), goal=(300.0, 0.0), heading=0.0)
    r = sim.step(np.array([[actions.HOLD]]))
    p = sim.ac_pos_km[0, 0]
    d = math.dist(p, (300.0, 0.0))
    assert r.rewards["path"][0, 0] == pytest.approx(-((d / 400.0) ** 2))
    assert r.rewards["step"][0, 0] == -0.01
