"""The single-episode fast path (Simulator.step_one, observe_one) against the batched reference.

The PettingZoo env runs ``step_one`` / ``observe_one``; ``cdr-bench evaluate`` and training run
the batched ``step`` / ``observe``. They must give the same episodes bit for bit: every state
array, every field of the step result and every observation byte are compared, step by step, on
every shipped scenario and on variants that make each kind of event frequent.
"""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from cdr_bench.actions import HOLD
from cdr_bench.scenarios import list_scenarios, load_scenario
from cdr_bench.sim import REWARD_TERMS, Simulator, observe, observe_one
from cdr_bench.sim.core import BOUNDARY, LOS, NMAC, SUCCESS, TIMEOUT

STATE = (
    "pos_km",
    "vel_km_s",
    "level",
    "active",
    "bg_arc_km",
    "route_last_arc_km",
    "route_spawn_count",
    "route_waiting",
    "ac_heading_deg",
    "ac_speed_kt",
    "ac_goal_km",
    "ac_outcome",
    "steps",
)
FLAGS = ("acting", "invalid_action", "outside", "reached_goal", "terminated", "truncated")

VARIANTS = {
    "timeouts": ("high", {"time": {"max_steps": 25}}),
    "boundary": ("medium", {"sector": {"boundary_terminates": True}}),
    "nmac": ("high", {"separation": {"los_km": 10.0, "nmac_km": 4.0}}),
    "marl-los-ends": ("marl/medium-4", {"separation": {"los_terminates": True}}),
    "more-neighbours-than-aircraft": ("tactical/crossing", {"observation": {"neighbours": 16}}),
    "no-traffic": ("low", {"traffic": {"routes": 0}}),
}


def _same_bytes(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def run_both(cfg, steps: int, seed: int, events: Counter) -> None:
    ref, fast = Simulator(cfg), Simulator(cfg)
    rng = np.random.default_rng(seed)

    def reset() -> None:
        s = int(rng.integers(2**62))
        ref.reset([s])
        fast.reset([s])

    reset()
    for i in range(steps):
        where = f"{cfg.id} seed {seed} step {i}"
        o_ref, o_fast = observe(ref)[0], observe_one(fast)
        assert _same_bytes(o_ref, o_fast), f"{where}: observation differs"
        # Mostly hold (the start heading points at the goal, so episodes succeed), otherwise
        # any of the 27 actions, masked level changes included.
        act = np.where(rng.random(ref.M) < 0.6, HOLD, rng.integers(0, 27, ref.M))
        r_ref = ref.step(act[None])
        r_fast = fast.step_one(act.tolist())
        for f in FLAGS + ("outcome", "min_sep_km"):
            assert getattr(r_ref, f)[0].tolist() == getattr(r_fast, f), f"{where}: {f}"
        for m in range(ref.M):
            for k in REWARD_TERMS:
                a, b = r_ref.rewards[k].item(0, m), r_fast.rewards[m][k]
                assert _same_bytes(np.float64(a), np.float64(b)), f"{where}: reward {k}"
        assert np.array_equal(r_ref.los_with, r_fast.los_with), f"{where}: los_with"
        assert np.array_equal(r_ref.nmac_with, r_fast.nmac_with), f"{where}: nmac_with"
        for name in STATE:
            assert _same_bytes(getattr(ref, name), getattr(fast, name)), f"{where}: {name}"
        events.update(
            {
                "los": int(r_ref.los_with.any()),
                "nmac": int(r_ref.nmac_with.any()),
                "success": int((r_ref.outcome == SUCCESS).any()),
                "boundary": int((r_ref.outcome == BOUNDARY).any()),
                "los_end": int((r_ref.outcome == LOS).any()),
                "nmac_end": int((r_ref.outcome == NMAC).any()),
                "timeout": int((r_ref.outcome == TIMEOUT).any()),
                "invalid": int(r_ref.invalid_action.any()),
                "spawn_waits": int(ref.route_waiting.any()),
                "some_left": int(r_ref.acting.any() and not r_ref.acting.all()),
            }
        )
        if not ref.ac_active.any():
            reset()


@pytest.mark.parametrize("name", list_scenarios())
def test_fast_path_is_the_reference_on_every_scenario(name):
    events: Counter = Counter()
    for seed in range(2):
        run_both(load_scenario(name), 150, seed, events)


def test_fast_path_is_the_reference_for_every_kind_of_event():
    events: Counter = Counter()
    for base, overrides in VARIANTS.values():
        for seed in range(2):
            run_both(load_scenario(base, **overrides), 300, seed, events)
    for name in ("tactical/head-on", "marl/low-2", "curriculum/stage-12"):
        run_both(load_scenario(name), 400, 7, events)
    missing = [
        e
        for e in (
            "los",
            "nmac",
            "success",
            "boundary",
            "los_end",
            "nmac_end",
            "timeout",
            "invalid",
            "spawn_waits",
            "some_left",
        )
        if not events[e]
    ]
    assert not missing, f"the comparison never exercised: {missing} ({dict(events)})"


def test_a_step_with_nothing_flying_matches_too():
    cfg = load_scenario("high")
    ref, fast = Simulator(cfg), Simulator(cfg)
    ref.reset([3])
    fast.reset([3])
    ref.ac_active[:] = False
    fast.ac_active[:] = False
    r_ref, r_fast = ref.step(np.array([[HOLD]])), fast.step_one([HOLD])
    assert r_fast.acting == [False] and r_fast.outcome == r_ref.outcome[0].tolist()
    for name in STATE:
        assert _same_bytes(getattr(ref, name), getattr(fast, name)), name


def test_fast_path_refuses_a_batch():
    sim = Simulator(load_scenario("low"), n_episodes=2)
    sim.reset([0, 1])
    with pytest.raises(ValueError, match="single-episode"):
        sim.step_one([HOLD])
    with pytest.raises(ValueError, match="single-episode"):
        observe_one(sim)
