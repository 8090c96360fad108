"""The episodes every auto-resetting face steps through, pinned: a few hundred steps of each
adapter (the Gymnasium vector env, the training env with its curriculum, cut and penalties, the
Stable-Baselines3 adapter, and a plain ``VectorEnv(autoreset=True)``) from fixed seeds, hashed
(observations, masks, rewards, flags, infos). The digests were recorded when each adapter
restarted its episodes itself; the restart now happens in one place, ``VectorEnv``'s auto-reset,
and must give the same episodes and the same arrays."""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np
import pytest

from cdr_bench.gym_env import OwnshipVectorEnv
from cdr_bench.rl.curriculum import Curriculum, CurriculumEnv
from cdr_bench.vector_env import VectorEnv

STEPS = 300


class Digest:
    def __init__(self) -> None:
        self.h = hashlib.sha256()

    def add(self, value: Any) -> None:
        if isinstance(value, dict):
            for key in sorted(value):
                self.h.update(str(key).encode())
                self.add(value[key])
        elif isinstance(value, (list, tuple)):
            self.h.update(f"[{len(value)}".encode())
            for v in value:
                self.add(v)
        elif isinstance(value, np.ndarray) and value.dtype == object:
            self.add(value.tolist())
        elif isinstance(value, np.ndarray):
            a = np.ascontiguousarray(value)
            self.h.update(f"{a.dtype.str}{a.shape}".encode())
            self.h.update(a.tobytes())
        elif value is None or isinstance(value, (bool, int, float, str, np.generic)):
            self.h.update(repr(value.item() if isinstance(value, np.generic) else value).encode())
        else:
            raise TypeError(type(value))

    def hexdigest(self) -> str:
        return self.h.hexdigest()[:16]


def _gym_digest(scenario: str, **overrides: Any) -> str:
    d = Digest()
    envs = OwnshipVectorEnv(6, scenario, **overrides)
    rng = np.random.default_rng(7)
    d.add(envs.reset(seed=11))
    for _ in range(STEPS):
        d.add(envs.step(rng.integers(0, 27, 6)))
        d.add(envs.action_masks())
    return d.hexdigest()


def _curriculum_digest(env: CurriculumEnv) -> str:
    d = Digest()
    rng = np.random.default_rng(3)
    d.add(env.observe())
    for _ in range(STEPS):
        st = env.step(rng.integers(0, 27, (env.num_envs, env.n_agents)))
        d.add(
            [
                st.obs,
                st.action_mask,
                st.reward,
                st.safety_reward,
                st.goal_reward,
                st.terminated,
                st.truncated,
                st.flight_ended,
                st.episode_done,
                st.promoted,
                st.final_obs,
                st.final_action_mask,
                st.result.outcome,
                env.take_outcomes(),
                env.take_promotions(),
                env.stage,
                env.flying,
            ]
        )
    return d.hexdigest()


def _sb3_digest(venv: Any) -> str:
    d = Digest()
    rng = np.random.default_rng(5)
    venv.seed(13)
    d.add(venv.reset())
    for _ in range(STEPS):
        d.add(venv.action_masks())
        d.add(venv.step(rng.integers(0, 27, venv.num_envs)))
    return d.hexdigest()


def test_gymnasium_vector_env_steps_the_same_episodes():
    assert _gym_digest("low") == "0e0aefb9df619a92"
    # learning intruders still flying when the ownship's flight ends; a short horizon truncates
    assert _gym_digest("marl/low-2", time={"max_steps": 40}) == "05e3ac532f02c4ff"


def test_training_env_steps_the_same_episodes():
    curriculum = CurriculumEnv(
        6,
        seed=4,
        curriculum=Curriculum(window=3, threshold=0.0),
        failure_penalty=2.0,
        max_episode_steps=25,
    )
    assert _curriculum_digest(curriculum) == "5453717b28ab9129"
    assert curriculum.stage is not None and curriculum.stage > 3  # promotions were stepped
    fixed = CurriculumEnv(
        5, seed=9, scenario="marl/low-2", failure_penalty=1.0, max_episode_steps=35, los_penalty=0.5
    )
    assert _curriculum_digest(fixed) == "6a24064a8d7a8315"


def test_sb3_adapter_steps_the_same_episodes():
    pytest.importorskip("stable_baselines3")
    from cdr_bench.wrappers import sb3_vec_env, vector_env_to_sb3

    native = sb3_vec_env("marl/low-2", 4, seed=0, time={"max_steps": 40})
    assert _sb3_digest(native) == "c921936cca3e71bd"
    # a VectorEnv built without auto-reset, handed to the adapter
    plain = vector_env_to_sb3(VectorEnv("low", 5, seed=1), include_mask=False)
    assert _sb3_digest(plain) == "5923f80b1991adda"
    training = CurriculumEnv(4, seed=2, scenario="high", failure_penalty=1.0, max_episode_steps=30)
    assert _sb3_digest(vector_env_to_sb3(training)) == "e309e9da7a9558db"


def test_vector_env_autoreset_steps_the_same_episodes():
    d = Digest()
    env = VectorEnv("marl/low-2", 6, autoreset=True, seed=21, time={"max_steps": 50})
    rng = np.random.default_rng(1)
    d.add(env.reset())
    for _ in range(STEPS):
        out = env.step(rng.integers(0, 27, (6, env.n_agents)))
        d.add([out.obs, out.action_mask, out.reward, out.terminated, out.truncated])
        d.add([out.episode_done, out.final_obs, out.final_episode_seeds, env.episode_seeds])
        d.add([out.result.outcome, out.result.terms, env.outcomes])
    assert d.hexdigest() == "7a8e6c023f4cc46f"
