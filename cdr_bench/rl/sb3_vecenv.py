"""An SB3 ``VecEnv`` over the batched training simulator (imports SB3: load it lazily).

Each of the E sub-environments is one ownship episode of :class:`cdr_bench.rl.baselines.
SplitTrainEnv` -- the same environment, observation, reward, DPSC curriculum and training cut as
Diffusion-AC -- so SB3 trains at the batched simulator's speed instead of stepping E copies of
the Gymnasium env (``cdr_bench/Ownship-v0``) one by one. Episodes auto-reset;
``infos[i]["terminal_observation"]`` and ``"TimeLimit.truncated"`` follow SB3's conventions (the
200-step training cut and curriculum promotions are truncations, bootstrapped), and
``infos[i]["episode"]`` feeds SB3's episode statistics. ``env_method("action_masks")`` returns
the feasibility masks for sb3-contrib's ``MaskablePPO``.

With ``continuous=True`` the action space is ``Box(-1, 1, (3,))`` and actions are rounded to the
discrete triple by :func:`cdr_bench.rl.baselines.continuous_to_index` (TD3).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv

from cdr_bench.rl.baselines import SplitTrainEnv, continuous_to_index
from cdr_bench.scenarios import load_scenario
from cdr_bench.sim import observation_bounds


class BatchedVecEnv(VecEnv):
    def __init__(self, env: SplitTrainEnv, continuous: bool = False):
        low, high = observation_bounds(load_scenario(env.scenario))
        obs_space = spaces.Box(low, high, dtype=np.float32)
        act_space: spaces.Space = (
            spaces.Box(-1.0, 1.0, (3,), dtype=np.float32) if continuous else spaces.Discrete(27)
        )
        super().__init__(env.E, obs_space, act_space)
        self.env, self.continuous = env, continuous
        self._actions: np.ndarray | None = None
        self.ep_return = np.zeros(env.E)
        self.ep_length = np.zeros(env.E, np.int64)
        self.finished: list[int] = []  # outcome codes since the last read by the trainer
        self.promotions: list[int] = []

    def reset(self) -> np.ndarray:
        self.ep_return[:] = 0
        self.ep_length[:] = 0
        return self.env.observe()[0]

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self) -> Any:
        assert self._actions is not None
        a = continuous_to_index(self._actions) if self.continuous else self._actions
        tr = self.env.step(np.asarray(a, np.int64).reshape(-1))
        assert len(tr["action"]) == self.num_envs  # single ownship: every episode flies
        reward = tr["reward"].astype(np.float32)
        self.ep_return += reward
        self.ep_length += 1
        ended = tr["ended"]
        infos: list[dict] = [{} for _ in range(self.num_envs)]
        for i in np.flatnonzero(ended):
            infos[i] = {
                "terminal_observation": tr["next_obs"][i],
                "TimeLimit.truncated": not bool(tr["done"][i]),
                "episode": {"r": float(self.ep_return[i]), "l": int(self.ep_length[i])},
            }
        self.ep_return[ended] = 0
        self.ep_length[ended] = 0
        self.finished += tr["finished"]
        if tr["promoted"]:
            assert self.env.curriculum is not None
            self.promotions.append(self.env.curriculum.stage)
        return self.env.observe()[0], reward, ended.copy(), infos

    def action_masks(self) -> np.ndarray:
        return self.env.observe()[1].astype(bool)

    def close(self) -> None:
        pass

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        if attr_name == "action_masks":
            return [self.action_masks] * len(self._indices(indices))
        if attr_name == "render_mode":
            return [None] * len(self._indices(indices))
        raise AttributeError(attr_name)

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        raise AttributeError(attr_name)

    def env_method(
        self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any
    ) -> list[Any]:
        if method_name != "action_masks":
            raise AttributeError(method_name)
        masks = self.action_masks()
        return [masks[i] for i in self._indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False] * len(self._indices(indices))

    def _indices(self, indices: Any) -> Sequence[int]:
        if indices is None:
            return range(self.num_envs)
        if isinstance(indices, int):
            return [indices]
        return list(indices)
