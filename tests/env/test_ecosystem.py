"""Gymnasium, SuperSuit, Stable-Baselines3 and sb3-contrib paths."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest

import cdr_bench  # noqa: F401 - registers cdr_bench/Ownship-v0


def test_gymnasium_make_and_check_env():
    from gymnasium.utils.env_checker import check_env

    env = gym.make("cdr_bench/Ownship-v0", scenario="high")
    assert isinstance(env.observation_space, gym.spaces.Box)
    assert env.observation_space.shape == (42,)
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    mask = env.unwrapped.action_masks()
    assert mask.shape == (27,) and mask.dtype == bool
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        check_env(env.unwrapped, skip_render_check=False)


def test_maskable_ppo_short_run():
    sb3_contrib = pytest.importorskip("sb3_contrib")
    env = gym.make("cdr_bench/Ownship-v0", scenario="low")
    model = sb3_contrib.MaskablePPO(
        "MlpPolicy", env, n_steps=64, batch_size=32, n_epochs=1, seed=0, verbose=0
    )
    model.learn(128)
    obs, _ = env.reset(seed=1)
    action, _ = model.predict(obs, action_masks=env.unwrapped.action_masks())
    assert 0 <= int(action) < 27


def test_sb3_vec_env_ppo_with_learning_intruders():
    sb3 = pytest.importorskip("stable_baselines3")
    from cdr_bench.wrappers import sb3_vec_env

    venv = sb3_vec_env("marl/low-2", num_envs=2, seed=0)
    assert isinstance(venv, sb3.common.vec_env.VecEnv)
    assert venv.num_envs == 2 * 3  # two episodes x (ownship + 2 learning intruders)
    assert venv.observation_space.shape == (42 + 27,)
    model = sb3.PPO("MlpPolicy", venv, n_steps=32, batch_size=64, n_epochs=1, seed=0, verbose=0)
    model.learn(2 * 3 * 32 * 2)
    assert model.num_timesteps >= 2 * 3 * 32 * 2
    obs = venv.reset()
    assert obs.shape == (6, 69) and np.isfinite(obs).all()
    assert venv.observation_space.contains(obs[0])


def _supersuit_venv(ss, n: int, scenario: str = "marl/low-2"):
    from cdr_bench.wrappers import BlackDeath, FlatObservation, seedable_sb3

    par = BlackDeath(FlatObservation(cdr_bench.parallel_env(scenario), include_mask=True))
    vec = ss.pettingzoo_env_to_vec_env_v1(par)
    return seedable_sb3(ss.concat_vec_envs_v1(vec, n, num_cpus=0, base_class="stable_baselines3"))


def test_supersuit_pipeline_trains_sb3_past_episode_ends():
    """SuperSuit's chain (FlatObservation, BlackDeath, Markov vector env, SB3 concat) trains a
    seeded PPO through whole episodes of a multi-agent scenario: every aircraft's slot is done
    together when its episode ends, and the same seed gives the same observations."""
    sb3 = pytest.importorskip("stable_baselines3")
    ss = pytest.importorskip("supersuit")

    venv = _supersuit_venv(ss, 2)
    assert venv.num_envs == 6 and venv.observation_space.shape == (69,)
    model = sb3.PPO("MlpPolicy", venv, n_steps=96, batch_size=96, n_epochs=1, seed=0, verbose=0)
    model.learn(6 * 96)  # random-policy episodes of marl/low-2 last ~70-80 steps
    assert model.num_timesteps >= 6 * 96

    venv.seed(5)
    first = venv.reset()
    again = _supersuit_venv(ss, 2)
    again.seed(5)
    assert np.array_equal(first, again.reset())
    rng = np.random.default_rng(0)
    ends = 0
    for _ in range(150):
        obs, rewards, dones, infos = venv.step(rng.integers(0, 27, 6))
        assert obs.shape == (6, 69) and np.isfinite(obs).all()
        for e in range(2):  # an episode's three slots end together
            assert len(set(dones[3 * e : 3 * e + 3].tolist())) == 1
        for i in np.flatnonzero(dones):
            assert infos[i]["terminal_observation"].shape == (69,)
        ends += int(dones.sum()) // 3
    assert ends >= 2


def test_black_death_keeps_finished_aircraft_until_the_episode_ends():
    from cdr_bench.wrappers import BlackDeath, FlatObservation

    env = BlackDeath(FlatObservation(cdr_bench.parallel_env("marl/low-2"), include_mask=False))
    obs, _ = env.reset(seed=0)
    agents = list(env.possible_agents)
    assert env.agents == agents and set(obs) == set(agents)
    finished: set[str] = set()
    while env.agents:
        live = set(env.unwrapped.agents)
        obs, rew, term, trunc, infos = env.step({a: 13 for a in agents})
        assert set(obs) == set(rew) == set(term) == set(agents)
        for a in finished:  # a finished aircraft: zero observation, no reward, no flag yet
            assert not obs[a].any() and rew[a] == 0.0 and infos[a] == {}
        finished |= live - set(env.unwrapped.agents)
        if env.agents:
            assert not any(term.values()) and not any(trunc.values())
    assert finished == set(agents)
    assert all(term[a] or trunc[a] for a in agents)  # the last step: each its own flags
    with pytest.raises(RuntimeError, match="episode ended"):
        env.step({a: 13 for a in agents})
    with pytest.raises(TypeError, match="FlatObservation"):
        BlackDeath(cdr_bench.parallel_env("marl/low-2"))


def test_vec_env_seed_makes_resets_reproducible():
    pytest.importorskip("stable_baselines3")
    from cdr_bench.wrappers import sb3_vec_env

    a = sb3_vec_env("marl/low-2", num_envs=2)
    b = sb3_vec_env("marl/low-2", num_envs=2)
    assert a.seed(5) == [5] * 6
    b.seed(5)
    first = a.reset()
    np.testing.assert_array_equal(first, b.reset())
    assert not np.array_equal(first, a.reset())  # the stream goes on
    c, d = (
        sb3_vec_env("marl/low-2", num_envs=2, seed=7),
        sb3_vec_env("marl/low-2", num_envs=2, seed=7),
    )
    np.testing.assert_array_equal(c.reset(), d.reset())


def test_black_death_slots_and_episode_ends():
    """An aircraft that has left gets zero observations, zero reward and only "hold" until its
    episode ends; then all the episode's slots are done together, with terminal observations."""
    pytest.importorskip("stable_baselines3")
    from cdr_bench.wrappers import sb3_vec_env

    venv = sb3_vec_env("marl/low-2", num_envs=3, seed=1, time={"max_steps": 80})
    venv.reset()
    hold = np.zeros(27, bool)
    hold[13] = True
    rng = np.random.default_rng(0)
    saw_dead = saw_done = saw_truncated = False
    alive = np.ones(9, bool)
    for _ in range(400):
        obs, reward, done, infos = venv.step(rng.integers(0, 27, 9))
        masks = np.stack(venv.env_method("action_masks"))
        assert venv.has_attr("action_masks") and masks.shape == (9, 27) and masks.dtype == bool
        flying = venv.unwrapped.source.flying.reshape(-1)
        dead = ~flying & ~done
        assert (obs[dead] == 0).all() and (masks[dead] == hold).all()
        assert (obs[flying][:, 42:] == masks[flying]).all()  # the appended mask flags
        assert (reward[~alive & ~done] == 0).all()  # left before this step: no reward
        saw_dead |= bool(dead.any())
        for e in range(3):
            assert done[3 * e : 3 * e + 3].all() or not done[3 * e : 3 * e + 3].any()
        for i in np.flatnonzero(done):
            saw_done = True
            info = infos[i]
            assert info["terminal_observation"].shape == (69,) and "episode" in info
            if not alive[i]:
                assert (info["terminal_observation"] == 0).all()
                assert not info["TimeLimit.truncated"]
            saw_truncated |= info["TimeLimit.truncated"]
            assert (obs[i] != 0).any()  # the first observation of the next episode
        alive = flying | done
    assert saw_dead and saw_done and saw_truncated  # the 80-step horizon cuts flights


@pytest.mark.parametrize("masked", [False, True])
def test_maskable_ppo_through_the_batched_adapter(masked):
    """A few hundred steps of MaskablePPO through the adapter never request a masked level
    change; unmasked PPO on the same env does."""
    sb3 = pytest.importorskip("stable_baselines3")
    sb3_contrib = pytest.importorskip("sb3_contrib")
    from cdr_bench.vector_env import VectorEnv
    from cdr_bench.wrappers import vector_env_to_sb3

    class Counting(VectorEnv):
        invalid = 0

        def step(self, actions):
            st = super().step(actions)
            Counting.invalid += int(st.result.invalid_action.sum())
            return st

    Counting.invalid = 0
    venv = vector_env_to_sb3(Counting("low", 8, seed=0), include_mask=False)
    cls = sb3_contrib.MaskablePPO if masked else sb3.PPO
    model = cls("MlpPolicy", venv, n_steps=32, batch_size=64, n_epochs=1, seed=0, verbose=0)
    model.learn(8 * 32 * 2)
    assert model.num_timesteps >= 512
    assert (Counting.invalid == 0) if masked else (Counting.invalid > 0)
    if masked:
        obs = venv.reset()
        masks = np.stack(venv.env_method("action_masks"))
        action, _ = model.predict(obs, action_masks=masks)
        assert masks[np.arange(8), action].all()
