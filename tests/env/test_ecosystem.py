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


def test_supersuit_sb3_ppo_with_learning_intruders():
    sb3 = pytest.importorskip("stable_baselines3")
    pytest.importorskip("supersuit")
    from cdr_bench.wrappers import sb3_vec_env

    venv = sb3_vec_env("marl/low-2", num_envs=2, seed=0)
    assert venv.num_envs == 2 * 3  # two copies x (ownship + 2 learning intruders)
    assert venv.observation_space.shape == (42 + 27,)
    model = sb3.PPO("MlpPolicy", venv, n_steps=32, batch_size=64, n_epochs=1, seed=0, verbose=0)
    model.learn(2 * 3 * 32 * 2)
    assert model.num_timesteps >= 2 * 3 * 32 * 2
    obs = venv.reset()
    assert obs.shape == (6, 69) and np.isfinite(obs).all()


def test_vec_env_seed_makes_resets_reproducible():
    pytest.importorskip("supersuit")
    from cdr_bench.wrappers import sb3_vec_env

    a = sb3_vec_env("marl/low-2", num_envs=1)
    b = sb3_vec_env("marl/low-2", num_envs=1)
    a.seed(5)
    b.seed(5)
    np.testing.assert_array_equal(a.reset(), b.reset())
