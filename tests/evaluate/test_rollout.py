"""The one rollout loop (cdr_bench.evaluate.rollout.fly): who decides, when it stops, what the
callbacks see, and that it flies exactly the loop it replaces."""

from __future__ import annotations

import numpy as np
import pytest

from cdr_bench.actions import HOLD
from cdr_bench.errors import ArgumentError
from cdr_bench.evaluate.rollout import Decisions, fly
from cdr_bench.vector_env import VectorEnv, random_feasible_actions


def _env(scenario: str = "marl/medium-4", n: int = 4) -> tuple[VectorEnv, np.ndarray, np.ndarray]:
    env = VectorEnv(scenario, num_envs=n)
    obs, masks = env.reset(seeds=np.arange(n) + 20)
    return env, obs, masks


def test_every_flying_aircraft_decides_and_it_is_the_hand_written_loop():
    env, obs, masks = _env()
    twin, tobs, tmasks = _env()
    rng, twin_rng = np.random.default_rng(0), np.random.default_rng(0)
    seen: list[Decisions] = []
    flown: list[np.ndarray] = []

    def decide(d: Decisions) -> np.ndarray:
        seen.append(d)
        return random_feasible_actions(d.masks, rng)

    steps = fly(env, obs, masks, decide, on_step=lambda a, st: flown.append(a.copy()))
    # the loop every caller used to write
    t = 0
    while (flying := twin.flying).any():
        rows_e, rows_m = np.nonzero(flying)
        act = np.full((4, twin.n_agents), HOLD)
        act[rows_e, rows_m] = random_feasible_actions(tmasks[rows_e, rows_m], twin_rng)
        assert np.array_equal(act, flown[t])
        d = seen[t]
        assert d.t == t and d.n == rows_e.size
        assert np.array_equal(d.episodes, rows_e) and np.array_equal(d.aircraft, rows_m)
        assert np.array_equal(d.obs, tobs[rows_e, rows_m])
        st = twin.step(act)
        tobs, tmasks = st.obs, st.action_mask
        t += 1
    assert steps == t == len(seen) and not env.flying.any()
    np.testing.assert_array_equal(env.outcomes, twin.outcomes)
    np.testing.assert_array_equal(env.episode_steps, twin.episode_steps)


def test_ownship_only_until_the_ownships_or_everyone_finished():
    env, obs, masks = _env()
    rows: list[Decisions] = []
    steps = fly(env, obs, masks, lambda d: rows.append(d) or HOLD, drive="ownship")
    assert all((d.aircraft == 0).all() for d in rows) and len(rows) == steps
    assert not env.flying[:, 0].any()
    # until everyone: the intruders fly on after the last ownship; no call without a row
    env2, obs2, masks2 = _env()
    calls: list[int] = []
    steps2 = fly(
        env2, obs2, masks2, lambda d: calls.append(d.n) or HOLD, drive="ownship", until="all"
    )
    assert not env2.flying.any() and steps2 >= steps and len(calls) <= steps2 and min(calls) > 0


def test_max_steps_cuts_the_rollout():
    env, obs, masks = _env("high", 3)
    assert fly(env, obs, masks, lambda d: HOLD, max_steps=5) == 5
    assert (env.episode_steps == 5).all() and env.flying.any()


def test_bad_modes_are_argument_errors():
    env, obs, masks = _env("high", 1)
    with pytest.raises(ArgumentError, match="drive"):
        fly(env, obs, masks, lambda d: HOLD, drive="intruders")  # type: ignore[arg-type]
    with pytest.raises(ArgumentError, match="until"):
        fly(env, obs, masks, lambda d: HOLD, until="never")  # type: ignore[arg-type]
