"""Adapters for tools that want flat ``Box`` observations (SuperSuit, Stable-Baselines3).

Two ways to train one shared Stable-Baselines3 policy for every aircraft of a multi-agent
scenario (``marl/*``: the ownship and the learning intruders):

* :func:`sb3_vec_env` (preferred) is a Stable-Baselines3 ``VecEnv`` built natively on the
  batched :class:`~cdr_bench.vector_env.VectorEnv`: every controlled aircraft of every episode is
  one slot (parameter sharing), all episodes advance in one compiled call per step (no dict per
  agent, no loop over copies of the env, no SuperSuit), it has sb3-contrib's ``action_masks``
  (``MaskablePPO``), ``seed()`` and SB3's ``"episode"`` and ``"TimeLimit.truncated"`` infos.
  :func:`vector_env_to_sb3` is the adapter itself, which the trainers put on their training
  environment.
* The SuperSuit chain (for a pipeline already built on SuperSuit): :class:`FlatObservation`
  turns each agent's ``{"observation", "action_mask"}`` dict into one float32 ``Box`` (the
  observation, optionally followed by the 27 mask flags); :class:`BlackDeath` keeps an aircraft
  that has finished in the episode with a zero observation and zero reward until every aircraft
  has finished (``pettingzoo_env_to_vec_env_v1`` needs a fixed set of agents; it replaces
  SuperSuit's ``black_death_v3``, which in SuperSuit 3.11.0 ends the episode only when an agent
  is terminated *and* truncated, so it steps an env without live agents); and
  :func:`seedable_sb3` makes the result of ``concat_vec_envs_v1(..., base_class=
  "stable_baselines3")`` seedable (SuperSuit 3.11.0's wrapper forwards ``seed()`` to a
  Gymnasium vector env that has none, so ``PPO(..., seed=0)`` fails)::

      import supersuit as ss
      from stable_baselines3 import PPO

      import cdr_bench
      from cdr_bench.wrappers import BlackDeath, FlatObservation, seedable_sb3

      env = BlackDeath(FlatObservation(cdr_bench.parallel_env("marl/low-2")))
      venv = ss.pettingzoo_env_to_vec_env_v1(env)  # one slot per aircraft: 3 here
      venv = ss.concat_vec_envs_v1(venv, 2, base_class="stable_baselines3")  # 2 episodes
      venv = seedable_sb3(venv)
      PPO("MlpPolicy", venv, n_steps=128, batch_size=128, seed=0).learn(768)  # one rollout

  Its policy sees the mask as 27 input flags but cannot be masked (no ``action_masks``); a
  masked action is not an error (its level change is not executed, docs/model.md §3.2).

Stable-Baselines3 and SuperSuit are imported lazily: they are training extras.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo.utils import BaseParallelWrapper

from cdr_bench.actions import N_ACTIONS
from cdr_bench.env import CDREnv
from cdr_bench.sim import observation_bounds
from cdr_bench.vector_env import VectorEnv


class FlatObservation(BaseParallelWrapper):
    """Replace each agent's observation dict by a flat float32 Box.

    ``include_mask=True`` appends the 27 action-mask flags (as 0.0 / 1.0) after the observation,
    so a policy without native masking can still see feasibility. Agents that finish leave
    ``agents`` as in the wrapped env; put :class:`BlackDeath` on top for SuperSuit.
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


class BlackDeath(BaseParallelWrapper):
    """Keep every agent in the episode until all have finished ("black death").

    A finished aircraft stays in ``agents`` with a zero observation, reward 0.0, empty infos and
    both flags False (its actions are ignored) until the last controlled aircraft finishes; that
    step reports every agent with its own flags (terminated, or truncated at the horizon) and
    ``agents`` becomes empty. The agent set is then fixed for the whole episode, which
    SuperSuit's ``pettingzoo_env_to_vec_env_v1`` requires. Observations must be ``Box`` spaces
    (wrap :class:`FlatObservation` first). A drop-in for SuperSuit's ``black_death_v3``, whose
    3.11.0 release ends the episode only when an agent is both terminated and truncated.
    """

    def __init__(self, env: Any):
        super().__init__(env)
        for a in env.possible_agents:
            if not isinstance(env.observation_space(a), spaces.Box):
                raise TypeError(
                    f"BlackDeath needs Box observations (wrap FlatObservation first); "
                    f"{a}: {env.observation_space(a)}"
                )
        self.agents: list[str] = []
        self._ended: dict[str, tuple[bool, bool]] = {}

    def _zero(self, agent: str) -> np.ndarray:
        return np.zeros_like(self.observation_space(agent).low)

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
        obs, infos = self.env.reset(seed=seed, options=options)
        self.agents = list(self.env.agents)
        self._ended = {}
        return obs, infos

    def step(self, actions: dict[str, Any]) -> Any:
        if not self.agents:
            raise RuntimeError("step() called after the episode ended; call reset() first")
        live = self.env.agents
        obs, rew, term, trunc, infos = self.env.step({a: actions[a] for a in live})
        for a in live:
            if term.get(a) or trunc.get(a):
                self._ended[a] = (bool(term.get(a)), bool(trunc.get(a)))
        done = not self.env.agents
        out_obs = {a: obs[a] if a in obs else self._zero(a) for a in self.agents}
        out_rew = {a: float(rew.get(a, 0.0)) for a in self.agents}
        out_info = {a: infos.get(a, {}) for a in self.agents}
        flags = {
            a: self._ended.get(a, (False, False)) if done else (False, False) for a in self.agents
        }
        out_term = {a: f[0] for a, f in flags.items()}
        out_trunc = {a: f[1] for a, f in flags.items()}
        if done:
            self.agents = []
        return out_obs, out_rew, out_term, out_trunc, out_info


def seedable_sb3(venv: Any) -> Any:
    """SuperSuit's Stable-Baselines3 vector env (``concat_vec_envs_v1(..., base_class=
    "stable_baselines3")``, or its ``base_class="gymnasium"`` form) with a working ``seed(s)``:
    the next ``reset()`` resets copy i with seed s + i (SuperSuit 3.11.0's wrapper forwards
    ``seed`` to a vector env that has no such method, so ``PPO(..., seed=0)`` fails)."""
    return _seedable_class()(getattr(venv, "venv", venv))


@functools.cache
def _seedable_class() -> type:
    from supersuit.vector.sb3_vector_wrapper import SB3VecEnvWrapper

    class SeedableSB3VecEnv(SB3VecEnvWrapper):
        __doc__ = seedable_sb3.__doc__
        _next_seed: int | None = None

        def seed(self, seed: int | None = None) -> Sequence[int | None]:
            self._next_seed = seed
            return [None if seed is None else seed + i for i in range(self.num_envs)]

        def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
            if seed is None:
                seed, self._next_seed = self._next_seed, None
            observations, self.reset_infos = self.venv.reset(seed=seed, options=options)
            return observations

    return SeedableSB3VecEnv


def sb3_vec_env(
    scenario: str = "marl/low-2",
    num_envs: int = 1,
    include_mask: bool = True,
    seed: int | None = None,
    **overrides: Any,
) -> Any:
    """A Stable-Baselines3 ``VecEnv`` of ``num_envs`` episodes of a (multi-agent) scenario
    (``overrides``: nested scenario fields).

    Slots: ``num_envs * (1 + learning intruders)``, episode-major. ``seed`` seeds the stream of
    episode seeds (``venv.seed(s)`` re-seeds it at the next reset). See
    :func:`vector_env_to_sb3` for what a slot sees.
    """
    venv = VectorEnv(scenario, num_envs, autoreset=True, seed=seed, **overrides)
    return vector_env_to_sb3(venv, include_mask)


def vector_env_to_sb3(
    source: Any,
    include_mask: bool = True,
    continuous_actions: Callable[[np.ndarray], np.ndarray] | None = None,
    extra_features: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
) -> Any:
    """The Stable-Baselines3 ``VecEnv`` of a :class:`~cdr_bench.vector_env.VectorEnv`, or of a
    source with the same face (the trainers' :class:`cdr_bench.rl.curriculum.CurriculumEnv`).

    Episodes restart through the source's auto-reset: the adapter switches on that of a
    VectorEnv built without it (``source.autoreset = True``: restarted episodes take the next
    seeds of its stream).

    * Each controlled aircraft of each episode is one slot (slot ``e * M + m``). An aircraft
      that has left gets a zero observation and zero reward ("black death") until its episode
      ends; then every slot of the episode is ``done`` at once (``infos[i]["terminal_observation"]``
      its last observation, ``"TimeLimit.truncated"`` when its flight was cut rather than
      terminated, ``"episode"`` its return and length) and the next observation is the first of
      the new episode.
    * ``include_mask`` appends the 27 feasibility flags (0.0 / 1.0) to the observation.
      ``env_method("action_masks")`` returns them as booleans for sb3-contrib's
      ``MaskablePPO`` (only "hold" for an aircraft that has left: its action is ignored).
    * ``seed(s)`` re-seeds the episode-seed stream at the next ``reset()``.
    * ``continuous_actions``: the action space is ``Box(-1, 1, (3,))`` and this maps (N, 3)
      actions to action indices (TD3).
    * ``extra_features``: maps (N, F) observations and (N, 27) masks to (N, X) features in
      [0, 1], appended to each observation (after the mask flags); e.g.
      :func:`cdr_bench.resolvers.mvp_onehot` for a learned residual on top of ``mvp``.
    """
    return _adapter_class()(source, include_mask, continuous_actions, extra_features)


_HOLD_ONLY = np.arange(N_ACTIONS) == 13


@functools.cache
def _adapter_class() -> type:
    from stable_baselines3.common.vec_env import VecEnv

    class VectorEnvSB3(VecEnv):
        __doc__ = vector_env_to_sb3.__doc__

        def __init__(
            self,
            source: Any,
            include_mask: bool,
            continuous_actions: Callable[[np.ndarray], np.ndarray] | None,
            extra_features: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
        ):
            if not source.autoreset:  # a VectorEnv: its auto-reset restarts the episodes
                source.autoreset = True
            self.source, self.include_mask = source, include_mask
            self.to_index, self.extra = continuous_actions, extra_features
            self._shape = (source.num_envs, source.n_agents)
            low, high = observation_bounds(source.config)
            if include_mask:
                low = np.concatenate([low, np.zeros(N_ACTIONS, np.float32)])
                high = np.concatenate([high, np.ones(N_ACTIONS, np.float32)])
            if extra_features is not None:
                f = source.observe()[0].shape[-1]
                x = extra_features(np.zeros((1, f), np.float32), np.ones((1, N_ACTIONS))).shape[1]
                low = np.concatenate([low, np.zeros(x, np.float32)])
                high = np.concatenate([high, np.ones(x, np.float32)])
            act_space: spaces.Space = (
                spaces.Box(-1.0, 1.0, (3,), dtype=np.float32)
                if continuous_actions is not None
                else spaces.Discrete(N_ACTIONS)
            )
            n = source.num_envs * source.n_agents
            super().__init__(n, spaces.Box(low, high, dtype=np.float32), act_space)
            self.ep_return = np.zeros(n)
            self.ep_length = np.zeros(n, np.int64)
            self._seed: int | None = None
            self._actions = np.full(n, 13)
            self._observe(*source.observe())

        def _slots(self, obs: np.ndarray, masks: np.ndarray, flying: np.ndarray) -> np.ndarray:
            """(E, M, .) arrays -> (slots, .) observations, zero where not ``flying``."""
            live = flying.reshape(-1, 1)
            out = np.where(live, obs.reshape(live.shape[0], -1), np.float32(0))
            if self.include_mask:
                flags = np.where(live, masks.reshape(live.shape[0], -1), 0).astype(np.float32)
                out = np.concatenate([out, flags], axis=1)
            if self.extra is not None:
                rows = obs.reshape(live.shape[0], -1)
                extra = self.extra(rows, masks.reshape(live.shape[0], -1))
                out = np.concatenate([out, np.where(live, extra, 0).astype(np.float32)], axis=1)
            return out

        def _observe(self, obs: np.ndarray, masks: np.ndarray) -> np.ndarray:
            self._flying = self.source.flying.reshape(-1)
            feasible = masks.reshape(-1, N_ACTIONS) != 0
            self._masks = np.where(self._flying[:, None], feasible, _HOLD_ONLY)
            return self._slots(obs, masks, self._flying)

        def reset(self) -> np.ndarray:
            seed, self._seed = self._seed, None
            self.ep_return[:] = 0
            self.ep_length[:] = 0
            return self._observe(*self.source.reset(seed=seed))

        def step_async(self, actions: np.ndarray) -> None:
            self._actions = np.asarray(actions)

        def step_wait(self) -> Any:
            a = self._actions if self.to_index is None else self.to_index(self._actions)
            st = self.source.step(np.asarray(a, np.int64).reshape(self._shape))
            reward = st.reward.reshape(-1).astype(np.float32)
            acting = st.result.acting.reshape(-1)
            self.ep_return += reward
            self.ep_length += acting
            done = np.repeat(st.restarted, self._shape[1])
            infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
            if done.any():
                final = self._slots(st.final_obs, st.final_action_mask, acting)
                cut = acting & ~st.terminated.reshape(-1)
                for i in np.flatnonzero(done):
                    infos[i] = {
                        "terminal_observation": final[i],
                        "TimeLimit.truncated": bool(cut[i]),
                        "episode": {"r": float(self.ep_return[i]), "l": int(self.ep_length[i])},
                    }
                self.ep_return[done] = 0
                self.ep_length[done] = 0
            return self._observe(st.obs, st.action_mask), reward, done, infos

        def action_masks(self) -> np.ndarray:
            """(slots, 27) feasible actions (booleans) of the current observations."""
            return self._masks.copy()

        def seed(self, seed: int | None = None) -> Sequence[int | None]:
            self._seed = seed
            return [seed] * self.num_envs

        def state_dict(self) -> dict[str, Any]:
            return {"ep_return": self.ep_return.copy(), "ep_length": self.ep_length.copy()}

        def load_state_dict(self, state: dict[str, Any]) -> None:
            """Continue on ``source`` (already restored) with these episode statistics."""
            self.ep_return[:], self.ep_length[:] = state["ep_return"], state["ep_length"]
            self._observe(*self.source.observe())

        def close(self) -> None:
            pass

        def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
            if attr_name == "render_mode":
                value = None
            elif attr_name == "action_masks":
                value = self.action_masks
            else:
                value = getattr(self.source, attr_name)
            return [value] * len(self._indices(indices))

        def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
            raise AttributeError(f"cannot set {attr_name!r} per slot")

        def env_method(
            self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any
        ) -> list[Any]:
            if method_name != "action_masks":
                raise AttributeError(method_name)
            return [self._masks[i] for i in self._indices(indices)]

        def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
            return [False] * len(self._indices(indices))

        def _indices(self, indices: Any) -> Sequence[int]:
            if indices is None:
                return range(self.num_envs)
            if isinstance(indices, int):
                return [indices]
            return list(indices)

    return VectorEnvSB3
