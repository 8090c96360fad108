"""Adapters for tools that want flat ``Box`` observations (SuperSuit, Stable-Baselines3).

* :class:`FlatObservation` turns the ``{"observation", "action_mask"}`` dict of every agent into
  one float32 ``Box`` (the observation, optionally followed by the 27 mask flags). SuperSuit's
  ``black_death_v3`` (needed because learning aircraft leave the episode) requires this.
* :func:`sb3_vec_env` builds the SuperSuit pipeline ``FlatObservation -> black_death_v3 ->
  pettingzoo_env_to_vec_env_v1 -> concat_vec_envs_v1`` as a Stable-Baselines3 ``VecEnv``, with the
  ``seed()`` method SuperSuit's vector env lacks (the seed applies to the next reset). Every
  learning aircraft is one slot of the vector env (parameter sharing).

SuperSuit and Stable-Baselines3 are imported lazily: they are training extras.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo.utils import BaseParallelWrapper

from cdr_bench.env import CDREnv


class FlatObservation(BaseParallelWrapper):
    """Replace each agent's observation dict by a flat float32 Box.

    ``include_mask=True`` appends the 27 action-mask flags (as 0.0 / 1.0) after the observation,
    so a policy without native masking can still see feasibility.
    """

    def __init__(self, env: CDREnv, include_mask: bool = True):
        super().__init__(env)
        self.include_mask = include_mask
        self._spaces: dict[str, spaces.Box] = {}
        for a in env.possible_agents:
            box = env.observation_spaces[a]["observation"]
            assert isinstance(box, spaces.Box)
            if include_mask:
                low = np.concatenate([box.low, np.zeros(27, np.float32)])
                high = np.concatenate([box.high, np.ones(27, np.float32)])
                box = spaces.Box(low, high, dtype=np.float32)
            self._spaces[a] = box

    def observation_space(self, agent: str) -> spaces.Box:
        return self._spaces[agent]

    def _flat(self, obs: dict[str, Any]) -> dict[str, np.ndarray]:
        if not self.include_mask:
            return {a: o["observation"] for a, o in obs.items()}
        return {
            a: np.concatenate([o["observation"], o["action_mask"].astype(np.float32)])
            for a, o in obs.items()
        }

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
        obs, infos = self.env.reset(seed=seed, options=options)
        return self._flat(obs), infos

    def step(self, actions: dict[str, Any]) -> Any:
        obs, rew, term, trunc, infos = self.env.step(actions)
        return self._flat(obs), rew, term, trunc, infos


def sb3_vec_env(
    scenario: str = "marl/low-2",
    num_envs: int = 1,
    include_mask: bool = True,
    seed: int | None = None,
    **overrides: Any,
) -> Any:
    """A Stable-Baselines3 ``VecEnv`` of ``num_envs`` copies of a (multi-agent) scenario.

    Slots: ``num_envs * len(possible_agents)``; aircraft that have left receive zero observations
    and rewards until the whole episode ends (SuperSuit's black death), then all slots reset.
    """
    import supersuit as ss
    from stable_baselines3.common.vec_env import VecEnvWrapper

    par = FlatObservation(CDREnv(scenario, **overrides), include_mask=include_mask)
    par = ss.black_death_v3(par)
    vec = ss.pettingzoo_env_to_vec_env_v1(par)
    vec = ss.concat_vec_envs_v1(vec, num_envs, num_cpus=0, base_class="stable_baselines3")

    class _Seeded(VecEnvWrapper):  # SuperSuit's vector env has no seed(); add it
        def __init__(self, venv: Any):
            super().__init__(venv)
            self._next_seed = seed

        def seed(self, seed: int | None = None) -> list[int | None]:
            self._next_seed = seed
            return [seed] * self.num_envs

        def reset(self) -> Any:
            s, self._next_seed = self._next_seed, None
            if s is None:
                return self.venv.reset()
            # SuperSuit's SB3 wrapper forwards a reset seed to a seed() that does not exist below
            # it; reset the concatenated vector env underneath it directly instead.
            inner: Any = self.venv
            obs, inner.reset_infos = inner.venv.reset(seed=s)
            return obs

        def step_wait(self) -> Any:
            return self.venv.step_wait()

    return _Seeded(vec)
