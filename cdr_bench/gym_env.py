"""Gymnasium single-agent view of the ownship, registered as ``cdr_bench/Ownship-v0``.

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

from cdr_bench.actions import HOLD
from cdr_bench.env import CDREnv
from cdr_bench.scenarios import ScenarioConfig


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
        return self.par_env.sim.action_masks()[0, 0].astype(bool)

    def render(self) -> NDArray[np.uint8] | None:  # type: ignore[override]  # gymnasium<1.2 stubs
        return self.par_env.render()

    def close(self) -> None:
        self.par_env.close()
