"""cdr_bench.resolvers: direct's pursuit and MVP on the observation vector, trig-free."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cdr_bench import resolvers
from cdr_bench.resolvers import (
    direct_actions,
    mvp_actions,
    mvp_onehot,
    steer_to_goal,
    with_mvp_input,
)

K = 3
F = 12 + 10 * K
ALL = np.ones((1, 27), np.int8)


def _index(a_psi: int, a_v: int, a_h: int) -> int:
    return 9 * (a_psi + 1) + 3 * (a_v + 1) + (a_h + 1)


def _obs(heading_deg=0.0, speed_kt=430.0, goal_rel_deg=0.0, neighbours=()):
    """One observation row: own state, goal bearing relative to the nose, and neighbours
    given as (dx_km, dy_km, dvx_kt, dvy_kt, dlevel)."""
    o = np.zeros(F, np.float32)
    h = math.radians(heading_deg)
    o[2], o[3] = math.sin(h), math.cos(h)
    o[4] = (speed_kt - 430.0) / 100.0
    g = math.radians(goal_rel_deg)
    o[9], o[10] = math.sin(g), math.cos(g)
    for k, (dx, dy, dvx, dvy, dlev) in enumerate(neighbours):
        b = 12 + 10 * k
        o[b] = 1.0
        o[b + 1], o[b + 2] = dx / 100.0, dy / 100.0
        o[b + 3], o[b + 4] = dvx / 1000.0, dvy / 1000.0
        o[b + 5] = dlev / 2.0
        o[b + 6] = math.hypot(dx, dy) / 100.0
    return o[None]


def test_step_constants_are_the_sines_and_cosines_they_name():
    assert resolvers.SIN_STEP == pytest.approx(math.sin(math.radians(5.0)), abs=1e-17)
    assert resolvers.COS_STEP == pytest.approx(math.cos(math.radians(5.0)), abs=1e-17)
    assert resolvers.SIN_HALF_STEP == pytest.approx(math.sin(math.radians(2.5)), abs=1e-17)
    assert resolvers.COS_HALF_STEP == pytest.approx(math.cos(math.radians(2.5)), abs=1e-17)


def test_steer_to_goal_is_the_angle_rule_away_from_its_boundaries():
    rel = np.random.default_rng(0).uniform(-180.0, 180.0, 20_000)
    rel = rel[np.abs(np.abs(rel) - 2.5) > 1e-6]
    obs = np.zeros((len(rel), F), np.float32)
    obs[:, 9], obs[:, 10] = np.sin(np.radians(rel)), np.cos(np.radians(rel))
    want = np.where(rel > 2.5, 1, np.where(rel < -2.5, -1, 0))
    np.testing.assert_array_equal(steer_to_goal(obs), want)
    assert steer_to_goal(_obs(goal_rel_deg=180.0))[0] == 1  # directly behind: turn right


def test_no_conflict_flies_like_direct_and_drifts_back_to_nominal_speed():
    o = _obs(goal_rel_deg=40.0, speed_kt=500.0, neighbours=[(50.0, 0.0, 0.0, 0.0, 0)])
    assert direct_actions(o)[0] == _index(1, 0, 0)
    assert mvp_actions(o, ALL)[0] == _index(1, -1, 0)


def test_head_on_conflict_climbs_to_a_free_level_else_turns_left():
    head_on = (0.0, 40.0, 0.0, -860.0, 0)  # 40 km ahead, closing at 860 kt, same level
    o = _obs(neighbours=[head_on, (0.0, 30.0, 0.0, 0.0, -1)])  # the level below is busy
    assert mvp_actions(o, ALL)[0] == _index(0, 0, 1)
    no_level_change = ALL.copy()
    no_level_change[0, [_index(0, 0, 1), _index(0, 0, -1)]] = 0
    a = int(mvp_actions(o, no_level_change)[0])
    # an exact head-on (d_cpa = 0) is pushed to the left of the closing velocity (see the module)
    assert a // 9 - 1 == -1 and a % 3 - 1 == 0


def test_no_cpu_dispatched_function_is_called(monkeypatch):
    def forbidden(*a, **k):
        raise AssertionError("a libm/SIMD-dispatched function was called")

    for name in ("sin", "cos", "arctan2", "degrees", "radians", "hypot", "exp"):
        monkeypatch.setattr(np, name, forbidden)
    for name in ("sin", "cos", "atan2"):
        monkeypatch.setattr(math, name, forbidden)
    monkeypatch.setattr(np.linalg, "norm", forbidden)
    rng = np.random.default_rng(1)
    obs = rng.uniform(-1, 1, (500, F)).astype(np.float32)
    obs[:, 12::10] = rng.random((500, K)) < 0.7
    mvp_actions(obs, rng.random((500, 27)) < 0.9)


def test_golden_actions_on_random_observations():
    """A change of arithmetic that flips any decision (e.g. a libm call sneaking back) shows."""
    rng = np.random.default_rng(2)
    obs = rng.uniform(-1, 1, (4000, F)).astype(np.float32)
    obs[:, 12::10] = rng.random((4000, K)) < 0.7
    obs[:, 17::10] = rng.integers(-1, 2, (4000, K)) / 2.0
    masks = (rng.random((4000, 27)) < 0.8).astype(np.int8)
    a = mvp_actions(obs, masks)
    assert a.dtype == np.int64 and ((a >= 0) & (a < 27)).all()
    assert np.bincount(a, minlength=27).tolist()[:9] == GOLDEN_FIRST_NINE
    assert int((a * np.arange(len(a))).sum()) == GOLDEN_WEIGHTED_SUM


GOLDEN_FIRST_NINE = [86, 478, 133, 60, 301, 95, 93, 530, 113]
GOLDEN_WEIGHTED_SUM = 104328525


def test_one_hot_input_is_appended_after_the_observation():
    o = _obs(goal_rel_deg=-30.0)
    x = with_mvp_input(o, ALL)
    assert x.shape == (1, F + 27) and x.dtype == np.float32
    np.testing.assert_array_equal(x[:, :F], o)
    assert x[0, F:].sum() == 1.0 and x[0, F + _index(-1, 0, 0)] == 1.0
    np.testing.assert_array_equal(mvp_onehot(o, ALL), x[:, F:])


def test_reciprocal_mvp_shares_the_vertical_escape_by_direction():
    """Two aircraft in a head-on conflict, both levels free: plain MVP climbs both (to the same
    level); reciprocal MVP climbs the eastbound one and descends the westbound one."""
    east = _obs(heading_deg=90.0, neighbours=[(40.0, 0.0, -860.0, 0.0, 0)])
    west = _obs(heading_deg=270.0, neighbours=[(-40.0, 0.0, 860.0, 0.0, 0)])
    assert mvp_actions(east, ALL)[0] == mvp_actions(west, ALL)[0] == _index(0, 0, 1)
    assert mvp_actions(east, ALL, reciprocal=True)[0] == _index(0, 0, 1)
    assert mvp_actions(west, ALL, reciprocal=True)[0] == _index(0, 0, -1)
    # no descent for the westbound one (lowest level): it resolves horizontally, never climbs
    low = ALL.copy()
    low[0, [_index(p, v, -1) for p in (-1, 0, 1) for v in (-1, 0, 1)]] = 0
    a = int(mvp_actions(west, low, reciprocal=True)[0])
    assert a % 3 - 1 == 0 and a // 9 - 1 != 0


def test_reciprocal_mvp_asks_for_half_the_velocity_change():
    """A crossing conflict with no level change allowed: the reciprocal variant's wanted
    velocity change is half of MVP's, so it picks a gentler (or the same) discrete change and
    never one MVP would not turn toward."""
    rng = np.random.default_rng(5)
    level = ALL.copy()
    level[0, [_index(p, v, h) for p in (-1, 0, 1) for v in (-1, 0, 1) for h in (-1, 1)]] = 0
    differ = 0
    for _ in range(300):
        dx, dy = rng.uniform(-40, 40, 2)
        dvx, dvy = rng.uniform(-800, 800, 2)
        o = _obs(heading_deg=float(rng.uniform(0, 360)), neighbours=[(dx, dy, dvx, dvy, 0)])
        a, b = int(mvp_actions(o, level)[0]), int(mvp_actions(o, level, reciprocal=True)[0])
        psi_a, psi_b = a // 9 - 1, b // 9 - 1
        assert psi_b in (psi_a, 0) or psi_a == 0
        differ += a != b
    assert differ > 0


def _priority_agent():
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "agents" / "mvp_priority" / "agent.py"
    spec = importlib.util.spec_from_file_location("mvp_priority_agent", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_right_of_way_goes_to_the_lower_index_of_two_aircraft_that_see_each_other():
    """Two controlled aircraft head-on at one level, each the other's only neighbour (the
    same vector reversed), and a third in another episode: the lower index keeps its course,
    the other resolves alone with MVP's full manoeuvre; without the pairing both would."""
    agent = _priority_agent()
    north = _obs(heading_deg=0.0, neighbours=[(0.0, 40.0, 0.0, -860.0, 0)])
    south = _obs(heading_deg=180.0, neighbours=[(0.0, -40.0, 0.0, 860.0, 0)])
    obs = np.concatenate([north, south, north])
    episodes, aircraft = np.array([0, 0, 1]), np.array([0, 1, 0])
    row = agent.right_of_way(obs, episodes, aircraft)
    assert row.tolist() == [[True, False, False], [False] * 3, [False] * 3]
    masks = np.ones((3, 27), np.int8)
    masks[:, [_index(0, 0, 1), _index(0, 0, -1)]] = 0  # no level change: turn or speed
    a = agent.Agent(None, None).act_joint(obs, masks, episodes, aircraft)
    mvp = mvp_actions(obs, masks)
    assert a[0] == direct_actions(obs)[0] != mvp[0]  # keeps its course
    assert a[1] == mvp[1] != direct_actions(obs)[1]  # resolves
    assert a[2] == mvp[2]  # alone in its episode: plain MVP
    # the same aircraft, their indices swapped: the right of way follows the index
    swapped = agent.right_of_way(obs, episodes, np.array([1, 0, 0]))
    assert swapped.tolist() == [[False] * 3, [True, False, False], [False] * 3]
