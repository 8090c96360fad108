"""Behaviour of the parallel env beyond the PettingZoo contract."""

from __future__ import annotations

import re

import numpy as np
import pytest

import cdr_bench
from cdr_bench import actions
from cdr_bench.errors import ActionError, ArgumentError
from cdr_bench.sim import REWARD_TERMS
from cdr_bench.vector_env import VectorEnv


def test_agents_and_spaces():
    env = cdr_bench.parallel_env("marl/medium-4")
    assert env.possible_agents == [
        "ownship_0",
        "intruder_0",
        "intruder_1",
        "intruder_2",
        "intruder_3",
    ]
    obs, infos = env.reset(seed=1)
    assert env.agents == env.possible_agents
    for a in env.agents:
        assert set(obs[a]) == {"observation", "action_mask"}
        assert obs[a]["observation"].dtype == np.float32
        assert obs[a]["observation"].shape == (42,)
        assert obs[a]["action_mask"].dtype == np.int8 and obs[a]["action_mask"].shape == (27,)
        assert env.observation_space(a).contains(obs[a])
    assert env.observation_space("ownship_0") is env.observation_space("ownship_0")


def test_masked_action_does_not_crash_and_is_reported():
    env = cdr_bench.parallel_env("medium")
    obs, _ = env.reset(seed=0)
    level = int(env.sim.ac_level[0, 0])
    bad = actions.encode((0, 0, 1)) if level == 2 else actions.encode((0, 0, -1))
    if level == 1:  # move to a bound first
        env.step({"ownship_0": actions.encode((0, 0, 1))})
        bad = actions.encode((0, 0, 1))
    assert obs is not None
    lv = int(env.sim.ac_level[0, 0])
    _, _, _, _, infos = env.step({"ownship_0": bad})
    assert infos["ownship_0"]["invalid_action"] is True
    assert int(env.sim.ac_level[0, 0]) == lv


@pytest.mark.parametrize("value", [27, -1, 100])
def test_out_of_range_action_raises_naming_agent_and_value(value):
    env = cdr_bench.parallel_env("low")
    env.reset(seed=0)
    with pytest.raises(ValueError, match=rf"ownship_0.*{value}"):
        env.step({"ownship_0": value})


@pytest.mark.parametrize("value", [3.5, "3", None, True])
def test_non_integer_action_raises(value):
    env = cdr_bench.parallel_env("low")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="ownship_0"):
        env.step({"ownship_0": value})


def test_numpy_integer_actions_accepted():
    env = cdr_bench.parallel_env("low")
    env.reset(seed=0)
    env.step({"ownship_0": np.int64(13)})
    env.step({"ownship_0": np.uint8(13)})
    env.step({"ownship_0": np.array(13)})


@pytest.mark.parametrize(
    ("actions", "expect"),
    [
        ({"ownship_0": np.array([13])}, "array of shape (1,)"),
        ({"ownship_0": np.array([[13]])}, "array of shape (1, 1)"),
        ({"ownship_0": [13]}, "got [13] of type list"),
        ({"ownship_0": np.float64(13.0)}, "must be an integer"),
        ({"ownship_0": 2**70}, "must be in 0..26"),
        ({"ownship_0": 13, "bogus": 5}, "unknown agent 'bogus'"),
        ({"ownship_0": 13, 0: 13}, "unknown agent 0"),
        ({"intruder_0": 13}, "unknown agent 'intruder_0'"),  # "low" has no learning intruders
        ({}, "missing action for live agent 'ownship_0'"),
        (13, "takes a dict of agent id -> action"),
        ([("ownship_0", 13)], "takes a dict"),
        (None, "takes a dict"),
    ],
)
def test_step_rejects_bad_actions_with_the_documented_error(actions, expect):
    env = cdr_bench.parallel_env("low")
    env.reset(seed=0)
    with pytest.raises(ActionError) as ei:
        env.step(actions)
    assert isinstance(ei.value, ValueError) and expect in str(ei.value)
    assert env.step({"ownship_0": 13})[4]["ownship_0"]["step"] == 1  # the bad call did nothing


def test_actions_of_finished_agents_are_ignored():
    env = cdr_bench.parallel_env("marl/low-2")
    env.reset(seed=0)
    while len(env.agents) == len(env.possible_agents):
        env.step({a: 13 for a in env.agents})
    if env.agents:
        env.step({a: 13 for a in env.possible_agents})


def test_a_huge_value_is_quoted_short():
    env = cdr_bench.parallel_env("low")
    env.reset(seed=0)
    with pytest.raises(ActionError) as ei:
        env.step({"ownship_0": list(range(100_000))})
    assert len(str(ei.value)) < 250


@pytest.mark.parametrize(
    ("call", "expect"),
    [
        (lambda: cdr_bench.parallel_env("low").reset(seed="x"), "reset(seed=...)"),
        (lambda: cdr_bench.parallel_env("low").reset(seed=-1), "reset(seed=...)"),
        (lambda: cdr_bench.parallel_env("low").reset(options=[1]), "reset(options=...)"),
        (
            lambda: cdr_bench.parallel_env("low").reset(options={"episode_seed": 2**64}),
            "episode_seed",
        ),
        (lambda: cdr_bench.parallel_env("low", render_mode="ascii"), "render_mode"),
        (lambda: VectorEnv("low", num_envs=0), "num_envs"),
        (lambda: VectorEnv("low", num_envs="4"), "num_envs"),
        (lambda: VectorEnv("low", num_envs=True), "num_envs"),
        (lambda: VectorEnv("low", seed=1.5), "seed"),
        (lambda: VectorEnv("low", autoreset="yes"), "autoreset"),
    ],
)
def test_bad_env_arguments_raise_argument_errors(call, expect):
    with pytest.raises(ArgumentError, match=re.escape(expect)):
        call()


@pytest.mark.parametrize("bad", [[[1, 2], [3]], [13, 13, 13], [1.0, 2.0], "ab", {"a": 1}, [27, 0]])
def test_gymnasium_vector_env_rejects_bad_actions(bad):
    from cdr_bench.gym_env import OwnshipVectorEnv

    env = OwnshipVectorEnv(num_envs=2, scenario="low")
    env.reset(seed=0)
    with pytest.raises(ActionError):
        env.step(bad)


def test_infos_carry_named_terms_that_sum_to_reward_and_outcome_at_end():
    env = cdr_bench.parallel_env("high")
    obs, _ = env.reset(seed=3)
    rng = np.random.default_rng(0)
    total = 0.0
    while env.agents:
        m = obs["ownship_0"]["action_mask"]
        a = int(rng.choice(np.flatnonzero(m)))
        obs, rew, term, trunc, infos = env.step({"ownship_0": a})
        info = infos["ownship_0"]
        assert set(info["reward_terms"]) == set(REWARD_TERMS)
        assert sum(info["reward_terms"].values()) == pytest.approx(rew["ownship_0"])
        assert info["goal_reward"] + info["safety_reward"] == pytest.approx(rew["ownship_0"])
        assert ("outcome" in info) == (term["ownship_0"] or trunc["ownship_0"])
        total += rew["ownship_0"]
        for other in info["los_with"] + info["nmac_with"]:
            assert other.startswith(("bg_", "intruder_"))
    assert info["outcome"] in {"success", "nmac", "timeout", "boundary"}


def test_determinism_500_steps():
    def run():
        env = cdr_bench.parallel_env("high")
        obs, _ = env.reset(seed=123)
        rng = np.random.default_rng(7)
        out = []
        for _ in range(500):
            if not env.agents:
                obs, _ = env.reset()
            a = int(rng.choice(np.flatnonzero(obs["ownship_0"]["action_mask"])))
            obs, rew, *_ = env.step({"ownship_0": a})
            out.append((obs["ownship_0"]["observation"].copy(), rew["ownship_0"]))
        return out

    a, b = run(), run()
    for (oa, ra), (ob, rb) in zip(a, b, strict=True):
        np.testing.assert_array_equal(oa, ob)
        assert ra == rb


def test_different_seeds_differ_and_episode_seed_option_reproduces():
    env = cdr_bench.parallel_env("medium")
    o1, i1 = env.reset(seed=1)
    o2, _ = env.reset(seed=2)
    assert not np.array_equal(o1["ownship_0"]["observation"], o2["ownship_0"]["observation"])
    o3, _ = env.reset(options={"episode_seed": i1["ownship_0"]["episode_seed"]})
    np.testing.assert_array_equal(o1["ownship_0"]["observation"], o3["ownship_0"]["observation"])


def test_reset_seed_seeds_action_spaces():
    env = cdr_bench.parallel_env("marl/low-2")
    env.reset(seed=9)
    s1 = [env.action_space(a).sample() for a in env.possible_agents]
    env.reset(seed=9)
    s2 = [env.action_space(a).sample() for a in env.possible_agents]
    assert s1 == s2


def test_masked_sample_draws_what_gymnasium_draws():
    """The action spaces' short path of ``sample(mask)`` gives gymnasium's samples and leaves
    the stream where gymnasium leaves it, for the env's three masks and for other masks."""
    from gymnasium import spaces

    env = cdr_bench.parallel_env("marl/low-2")
    ours = env.action_space("ownship_0")
    assert isinstance(ours, spaces.Discrete) and ours == spaces.Discrete(27)
    theirs = spaces.Discrete(27)
    level_masks = [actions.action_mask(np.array(lv), 3) for lv in range(3)]
    odd = np.zeros(27, dtype=np.int8)
    odd[[4, 13, 20]] = 1
    masks = [*level_masks, odd, np.zeros(27, dtype=np.int8)]
    for seed in range(20):
        ours.seed(seed)
        theirs.seed(seed)
        for i in range(300):
            mask = masks[(seed + i) % len(masks)]
            a, b = ours.sample(mask), theirs.sample(mask)
            assert a == b and type(a) is type(b)
        assert ours.sample() == theirs.sample()
    assert ours.np_random.bit_generator.state == theirs.np_random.bit_generator.state
    with pytest.raises(AssertionError):
        ours.sample(np.full(27, 2, dtype=np.int8))


def test_observation_neighbour_features_match_geometry():
    env = cdr_bench.parallel_env("high")
    obs, _ = env.reset(seed=11)
    o = obs["ownship_0"]["observation"].astype(float)
    sim = env.sim
    others = sim.bg_pos_km[0][sim.bg_active[0]]
    d = np.sort(np.linalg.norm(others - sim.ac_pos_km[0, 0], axis=1))[:3]
    np.testing.assert_allclose(
        [o[12 + 6], o[22 + 6], o[32 + 6]], np.minimum(d / 100.0, 10), rtol=1e-5
    )
    assert o[12] == o[22] == o[32] == 1.0


def test_goal_relative_bearing_sign():
    env = cdr_bench.parallel_env(
        "low",
        ownship={
            "start": {
                "position_km": [200.0, 200.0],
                "heading_deg": 0.0,
                "speed_kt": 430.0,
                "level": 1,
            },
            "goal_km": [300.0, 200.0],
        },
    )
    obs, _ = env.reset(seed=0)
    o = obs["ownship_0"]["observation"]
    assert o[9] == pytest.approx(1.0, abs=1e-6)  # goal due east, heading north: to the right
    assert o[10] == pytest.approx(0.0, abs=1e-6)


def test_rgb_array_render_and_bad_render_mode():
    env = cdr_bench.parallel_env("medium", render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    assert frame.std() > 0
    with pytest.raises(ValueError, match="render_mode"):
        cdr_bench.parallel_env("medium", render_mode="ascii")


def test_overrides_are_validated():
    env = cdr_bench.parallel_env("medium", separation={"los_km": 8.0})
    assert env.config.separation.los_km == 8.0
    with pytest.raises(cdr_bench.ScenarioError, match="separation.los_kn"):
        cdr_bench.parallel_env("medium", separation={"los_kn": 8.0})


@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
def test_a_copied_env_continues_exactly_like_the_original(how):
    """Copies must not share or lose the simulator's internal views (positions as complex
    numbers, goals): a copy taken mid-episode steps on exactly like the original."""
    import copy
    import pickle

    env = cdr_bench.parallel_env("marl/low-2")
    env.reset(seed=5)
    hold = {a: actions.HOLD for a in env.possible_agents}
    for _ in range(10):
        env.step({a: hold[a] for a in env.agents})
    twin = copy.deepcopy(env) if how == "deepcopy" else pickle.loads(pickle.dumps(env))
    # read-only as in the original: the kernels compiled for it serve the copy too
    assert not twin.sim.params.flags.writeable and not twin.sim.all_episodes.flags.writeable
    rng = np.random.default_rng(0)
    for _ in range(200):
        if not env.agents:
            break
        act = {a: int(rng.integers(27)) for a in env.agents}
        o1, r1, t1, u1, _ = env.step(act)
        o2, r2, t2, u2, _ = twin.step(act)
        assert r1 == r2 and t1 == t2 and u1 == u2
        for a in o1:
            assert o1[a]["observation"].tobytes() == o2[a]["observation"].tobytes()
    assert env.agents == twin.agents
    np.testing.assert_array_equal(env.sim.pos_km, twin.sim.pos_km)
    assert not np.shares_memory(env.sim.pos_km, twin.sim.pos_km)
