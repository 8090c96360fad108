"""Aircraft placed by an encounter (docs/model.md §8.3): each episode draws the time to the
closest point of approach, the angle, the signed miss distance, the speed, the level and the
mirror from its seed, and the aircraft then meets the ownship's straight flight as drawn."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cdr_bench.scenarios import ScenarioError, load_scenario
from cdr_bench.sim import Simulator
from cdr_bench.sim.kernels import KM_PER_S_PER_KT, closest_approach, sin_cos_deg

ENC = {
    "time_to_cpa_s": [60.0, 300.0],
    "angle_deg": [20.0, 160.0],
    "miss_km": [2.0, 9.0],
    "speed_kt": [250.0, 500.0],
    "level": [0, 2],
}


def _sim(n: int, **enc) -> Simulator:
    cfg = load_scenario("tactical/head-on", aircraft=[{"encounter": {**ENC, **enc}}])
    sim = Simulator(cfg, n)
    sim.reset(list(range(n)))
    return sim


def _relative(sim: Simulator):
    """Per episode: time to CPA (s), signed miss (km, + right), track angle (deg), speed (kt)."""
    out = []
    for e in range(sim.E):
        own, ov = sim.ac_pos_km[e, 0], sim.ac_vel_km_s[e, 0]
        p, v = sim.bg_pos_km[e, 0], sim.bg_vel_km_s[e, 0]
        (px, py), (vx, vy) = p - own, v - ov
        d, t = closest_approach(px, py, vx, vy, 1e9)
        rel = p - own + (v - ov) * t
        right = np.array([ov[1], -ov[0]]) / np.hypot(*ov)
        side = math.copysign(d, float(rel @ right))
        angle = math.degrees(math.atan2(*v)) - math.degrees(math.atan2(*ov))
        angle = (angle + 180.0) % 360.0 - 180.0
        out.append((t, side, angle, float(np.hypot(*v)) / KM_PER_S_PER_KT))
    return np.array(out)


def test_an_encounter_meets_the_ownship_as_drawn():
    sim = _sim(400)
    t, miss, angle, speed = _relative(sim).T
    assert 60.0 - 1e-6 <= t.min() and t.max() <= 300.0 + 1e-6
    assert 2.0 - 1e-9 <= miss.min() and miss.max() <= 9.0 + 1e-9  # on the right
    assert 20.0 - 1e-9 <= angle.min() and angle.max() <= 160.0 + 1e-9
    assert 250.0 - 1e-9 <= speed.min() and speed.max() <= 500.0 + 1e-9
    assert set(sim.bg_level[:, 0].tolist()) == {0, 2}
    assert len(set(t.round(6))) == 400  # drawn per episode


def test_mirror_flips_the_side_in_about_half_of_the_episodes():
    sim = _sim(400, mirror=True)
    t, miss, angle, _ = _relative(sim).T
    left = miss < 0
    assert 150 < left.sum() < 250
    assert (angle[left] < 0).all() and (angle[~left] > 0).all()
    assert (np.abs(miss) >= 2.0 - 1e-9).all() and (np.abs(miss) <= 9.0 + 1e-9).all()


def test_fixed_values_draw_nothing_but_keep_the_order_of_the_draws():
    """A fixed value is a range of width 0: the same draws are consumed, so fixing one field
    leaves the others' values as they were."""
    a = _relative(_sim(50))
    b = _relative(_sim(50, miss_km=5.0))
    assert np.allclose(b[:, 1], 5.0)
    assert np.allclose(a[:, [0, 2, 3]], b[:, [0, 2, 3]], rtol=0, atol=1e-6)


def test_an_encounter_starting_within_the_start_clearance_is_drawn_again():
    # Mostly too close at the ownship's level: redrawn until clear.
    sim = _sim(50, time_to_cpa_s=[0.0, 100.0], level=1, angle_deg=[100.0, 120.0])
    d = np.hypot(*(sim.bg_pos_km[:, 0] - sim.ac_pos_km[:, 0]).T)
    assert (d >= 20.0).all()
    with pytest.raises(ScenarioError, match="start_clearance_km"):
        _sim(1, time_to_cpa_s=0.0, level=1)


def test_a_stationary_relative_motion_passes_to_the_right():
    sim = _sim(5, angle_deg=0.0, speed_kt=430.0, miss_km=30.0, level=1)
    rel = sim.bg_pos_km[:, 0] - sim.ac_pos_km[:, 0]
    assert np.allclose(rel, [0.0, -30.0])  # the ownship heads east: its right is south
    assert np.allclose(sim.bg_vel_km_s[:, 0], sim.ac_vel_km_s[:, 0])


@settings(max_examples=300, deadline=None)
@given(st.floats(-720.0, 720.0))
def test_sin_cos_deg_is_within_two_ulp(angle):
    mpmath = pytest.importorskip("mpmath")
    s, c = sin_cos_deg(angle)
    with mpmath.workdps(50):
        x = mpmath.mpf(angle) / 180
        exact = (float(mpmath.sinpi(x)), float(mpmath.cospi(x)))
    for got, want in zip((s, c), exact, strict=True):
        assert abs(got - want) <= 2 * math.ulp(max(abs(want), 1e-300)) or abs(got - want) < 1e-300


def test_sin_cos_deg_at_the_cardinal_points():
    assert sin_cos_deg(0.0) == (0.0, 1.0)
    assert sin_cos_deg(90.0) == (1.0, -0.0)
    assert sin_cos_deg(-90.0) == (-1.0, 0.0)
    assert sin_cos_deg(180.0) == (-0.0, -1.0)
