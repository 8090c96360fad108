"""The sector boundary: where a flight that leaves it ends (``sector.boundary_margin_km``), and
the bound on every return that follows (docs/model.md §5, §6)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cdr_bench.actions import HOLD
from cdr_bench.sim import OUTCOME_NAMES, Simulator
from cdr_bench.vector_env import VectorEnv, random_feasible_actions
from tests.conftest import make_config


def fly_west(margin: float | None, steps: int = 40) -> tuple[str, list[float]]:
    """A lone ownship on the west edge heading west (270 deg) at 430 kt (7.4 km per step):
    its outcome and the x positions it reached."""
    own = {
        "start": {"position_km": [2.0, 200.0], "heading_deg": 270.0, "speed_kt": 430.0, "level": 1},
        "goal_km": [390.0, 200.0],
    }
    cfg = make_config(
        ownship=own, traffic={"routes": 0}, sector={"size_km": 400.0, "boundary_margin_km": margin}
    )
    sim = Simulator(cfg)
    sim.reset([0])
    xs = []
    for _ in range(steps):
        res = sim.step(np.full((1, 1), HOLD))
        xs.append(float(sim.pos_km[0, -1, 0]))
        if res.outcome[0, 0] != 0:
            return OUTCOME_NAMES[int(res.outcome[0, 0])], xs
    return "running", xs


@pytest.mark.parametrize("margin", [0.0, 20.0, 50.0])
def test_a_flight_ends_exactly_beyond_the_margin(margin: float) -> None:
    outcome, xs = fly_west(margin)
    assert outcome == "boundary"
    assert xs[-1] < -margin and all(x >= -margin for x in xs[:-1])


def test_without_a_margin_the_flight_never_ends_at_the_boundary() -> None:
    outcome, xs = fly_west(None, steps=40)
    assert outcome == "running" and xs[-1] < -250.0


def test_random_agent_returns_are_bounded_by_the_documented_bound() -> None:
    env = VectorEnv("high", num_envs=64)
    _, masks = env.reset(seeds=np.arange(64))
    rng = np.random.default_rng(0)
    per_step_min = np.inf
    total = np.zeros(64)
    size, margin = 400.0, 50.0
    while env.flying.any():
        st = env.step(random_feasible_actions(masks, rng))
        masks = st.action_mask
        g = st.result.goal_reward[:, 0][st.result.acting[:, 0]]
        per_step_min = min(per_step_min, float(g.min(initial=0.0)))
        total += st.result.goal_reward[:, 0]
    bound = -((math.sqrt(2) * (size + margin) / size) ** 2 + 0.5 + 0.01 + 0.5)
    assert per_step_min >= bound
    assert total.min() > -1000.0  # was about -45,000 on average with the soft boundary
    outcomes = {OUTCOME_NAMES[int(o)] for o in env.sim.ac_outcome[:, 0]}
    assert "boundary" in outcomes
