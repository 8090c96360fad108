"""Gymnasium single-agent view of the ownship, registered as ``cdr_bench/Ownship-v0``, and its
native vector form (:class:`OwnshipVectorEnv`, the id's ``vector_entry_point``).

``gymnasium.make("cdr_bench/Ownship-v0", scenario="high")``: flat ``Box`` observation (the
``observation`` part of the PettingZoo dict), ``Discrete(27)`` actions and ``action_masks()``
for sb3-contrib's ``MaskablePPO``. Learning intruders of the scenario, if any, hold course
(action 13) unless ``intruder_policy`` is given (a callable ``obs_dict -> action``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

from cdr_bench.actions import HOLD, N_ACTIONS
from cdr_bench.env import CDREnv
from cdr_bench.errors import ActionError, short_repr
from cdr_bench.scenarios import ScenarioConfig
from cdr_bench.sim import OUTCOME_NAMES, StepResult
from cdr_bench.vector_env import VectorEnv


class OwnshipEnv(gym.Env):
    """The ownship of :class:`cdr_bench.env.CDREnv` as a Gymnasium env (see its env card)."""

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 8}

    def __init__(
        self,
        scenario: str | ScenarioConfig = "medium",
        render_mode: str | None = None,
        intruder_policy: Callable[[dict[str, Any]], int] | None = None,
        **overrides: Any,
    ):
        self.par_env = CDREnv(scenario, render_mode=render_mode, **overrides)
        self.render_mode = render_mode
        self.observation_space = self.par_env.observation_spaces["ownship_0"]["observation"]
        self.action_space = self.par_env.action_space("ownship_0")
        self._intruder_policy = intruder_policy
        self._obs: dict[str, Any] = {}

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        super().reset(seed=seed)
        self._obs, infos = self.par_env.reset(seed=seed, options=options)
        self._last_mask = self._obs["ownship_0"]["action_mask"]
        return self._obs["ownship_0"]["observation"], infos["ownship_0"]

    def step(self, action: Any) -> tuple[NDArray[np.float32], float, bool, bool, dict[str, Any]]:
        acts = {"ownship_0": action}
        for a in self.par_env.agents:
            if a != "ownship_0":
                acts[a] = self._intruder_policy(self._obs[a]) if self._intruder_policy else HOLD
        obs, rew, term, trunc, info = self.par_env.step(acts)
        # Keep the newest observation of every still-flying aircraft.
        self._obs = {a: obs[a] for a in self.par_env.agents}
        o = obs["ownship_0"]
        self._last_mask = o["action_mask"]
        return (
            o["observation"],
            rew["ownship_0"],
            term["ownship_0"],
            trunc["ownship_0"],
            info["ownship_0"],
        )

    def action_masks(self) -> NDArray[np.bool_]:
        """Feasible actions of the ownship now, (27,) bool."""
        return self._last_mask.astype(bool)

    def render(self) -> NDArray[np.uint8] | None:  # type: ignore[override]  # gymnasium<1.2 stubs
        return self.par_env.render()

    def close(self) -> None:
        self.par_env.close()


_VectorStep = tuple[
    NDArray[np.float32], NDArray[np.float64], NDArray[np.bool_], NDArray[np.bool_], dict[str, Any]
]


class OwnshipVectorEnv(gym.vector.VectorEnv):
    """``num_envs`` ownship episodes as one native Gymnasium vector env (no subprocesses, no
    copies of the env): what ``gymnasium.make_vec("cdr_bench/Ownship-v0", num_envs=N,
    vectorization_mode="vector_entry_point")`` returns.

    Arrays: observations (N, F) float32, actions (N,) integers 0..26, rewards (N,), terminations
    and truncations (N,). Auto-reset in the same step (``metadata["autoreset_mode"]`` is
    ``SAME_STEP``): when the ownship's flight ends, its episode restarts at once and the
    observation it ended with is in ``infos["final_obs"]`` (and its info in
    ``infos["final_info"]``; ``infos["_final_obs"]`` flags the slots), as Gymnasium's own vector
    envs do. Feasible actions: ``infos["action_mask"]`` (N, 27) and :meth:`action_masks`.
    Learning intruders of the scenario, if any, hold; the episode ends with the ownship's
    flight. The restart is the batched env's auto-reset (:class:`VectorEnv`, ``autoreset_when``
    ending the episode with the ownship's flight), episode seeds from its stream.
    """

    metadata = {"autoreset_mode": gym.vector.AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(
        self,
        num_envs: int = 1,
        scenario: str | ScenarioConfig = "medium",
        render_mode: str | None = None,
        max_episode_steps: int | None = None,
        **overrides: Any,
    ):
        if render_mode is not None:
            raise ValueError("the vector env does not render; use gymnasium.make for one env")
        if max_episode_steps is not None:  # gymnasium.make_vec passes the id's horizon
            overrides["time"] = {**overrides.get("time", {}), "max_steps": max_episode_steps}
        self.vector = VectorEnv(
            scenario,
            num_envs=num_envs,
            autoreset=True,
            autoreset_when=self._ownship_finished,
            **overrides,
        )
        self.num_envs = num_envs
        self.single_observation_space = self.vector.single_observation_space["observation"]
        self.single_action_space = self.vector.single_action_space
        self.observation_space = gym.vector.utils.batch_space(
            self.single_observation_space, num_envs
        )
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, num_envs)
        self.render_mode = None
        self._actions = np.full((num_envs, self.vector.n_agents), HOLD, dtype=np.int64)
        self._masks = np.zeros((num_envs, N_ACTIONS), dtype=np.int8)

    def _ownship_finished(self, res: StepResult) -> NDArray[np.bool_]:
        """The batched env's auto-reset rule: an episode ends with its ownship's flight
        (learning intruders still flying get the ``timeout`` outcome)."""
        ended = res.terminated[:, 0] | res.truncated[:, 0]
        still = np.flatnonzero(ended & self.vector.flying.any(axis=1))
        if still.size:  # learning intruders still flying: the ownship's episode is over
            self.vector.end_episodes(still)
        return ended

    def reset(
        self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[NDArray[np.float32], dict[str, Any]]:
        """``seed``: one integer seeds the stream of episode seeds; a list gives each slot's
        episode seed."""
        if isinstance(seed, (list, tuple, np.ndarray)):
            obs, masks = self.vector.reset(seeds=seed)
        else:
            obs, masks = self.vector.reset(seed=seed)
        self._masks = masks[:, 0]
        return obs[:, 0], {"action_mask": self._masks, "episode_seed": self.vector.episode_seeds}

    def step(
        self, actions: Any
    ) -> tuple[
        NDArray[np.float32], NDArray[np.float64], NDArray[np.bool_], NDArray[np.bool_], dict
    ]:
        try:
            a = np.asarray(actions)
        except (ValueError, TypeError):  # ragged nested lists
            a = np.empty(0)
        if a.shape != (self.num_envs,) or not np.issubdtype(a.dtype, np.integer):
            raise ActionError(
                f"expected {self.num_envs} integer actions in 0..{N_ACTIONS - 1}, got "
                f"{short_repr(actions)}"
            )
        if a.size and (a.min() < 0 or a.max() >= N_ACTIONS):
            raise ActionError(f"actions must be in 0..{N_ACTIONS - 1}, got {short_repr(a)}")
        self._actions[:, 0] = a
        out = self.vector._step(self._actions)  # checked above; restarts the ended episodes
        res = out.result
        reward = out.reward[:, 0]
        term, trunc = out.terminated[:, 0].copy(), out.truncated[:, 0].copy()
        obs = out.obs[:, 0]
        masks = out.action_mask[:, 0]
        infos: dict[str, Any] = {}
        ended = np.flatnonzero(out.restarted)
        if ended.size:
            final_obs = np.empty(self.num_envs, dtype=object)
            final_info = np.empty(self.num_envs, dtype=object)
            for e in ended.tolist():
                final_obs[e] = out.final_obs[e, 0].copy()
                final_info[e] = {
                    "outcome": OUTCOME_NAMES[int(res.outcome[e, 0])],
                    "episode_seed": int(out.final_episode_seeds[e]),
                }
            flag = np.zeros(self.num_envs, dtype=bool)
            flag[ended] = True
            infos.update(
                final_obs=final_obs, _final_obs=flag, final_info=final_info, _final_info=flag.copy()
            )
        self._masks = masks
        infos["action_mask"] = masks
        infos["reward_terms"] = res.terms[:, 0]
        return obs, reward, term, trunc, infos

    def action_masks(self) -> NDArray[np.bool_]:
        """(N, 27) feasible actions of every ownship now."""
        return self._masks.astype(bool)
