"""RLlib ``MultiAgentEnv`` adapter of :func:`cdr_bench.parallel_env`.

| | |
|---|---|
| Agents | ``ownship_0``, ``intruder_*``, ``aircraft_*`` (all possible; some enter later) |
| Observation | ``Dict(observations=Box(obs_dim) float32, action_mask=Box(0, 1, (27,)) float32)`` |
| Action | ``Discrete(27)`` per agent |
| Episode end | an agent leaves when done; ``"__all__"`` once no agent is left |

The mask sits under ``"action_mask"`` and the observation under ``"observations"`` (plural),
the keys RLlib's action-masking module expects
(``ray.rllib.examples.rl_modules.classes.action_masking_rlm.ActionMaskingTorchRLModule``:
it takes ``log(action_mask)`` as logit offsets, hence float32). Spaces are declared for every
possible agent, so one shared module serves them all (parameter sharing:
``policy_mapping_fn=lambda agent_id, *a, **k: "shared"``); see ``docs/tutorials/rllib_ppo.py``.

Ray is imported by this module only; the env itself is the package's PettingZoo env.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from ray.rllib.env.multi_agent_env import MultiAgentEnv

from cdr_bench.env import CDREnv

DEFAULT_SCENARIO = "marl/low-2"


class CDRMultiAgentEnv(MultiAgentEnv):
    """``CDRMultiAgentEnv({"scenario": "marl/low-2", **scenario_overrides})``."""

    def __init__(self, config: dict[str, Any] | None = None):
        super().__init__()
        config = dict(config or {})
        scenario = config.pop("scenario", DEFAULT_SCENARIO)
        self.par_env = CDREnv(scenario, **config)
        names: list[str] = list(self.par_env.possible_agents)
        obs_spaces: dict[str, spaces.Space] = {}
        act_spaces: dict[str, spaces.Space] = {}
        for a in names:
            inner = self.par_env.observation_space(a)
            assert isinstance(inner, spaces.Dict)
            obs_box = inner["observation"]
            mask_box = inner["action_mask"]
            assert isinstance(obs_box, spaces.Box) and isinstance(mask_box, spaces.Box)
            obs_spaces[a] = spaces.Dict(
                {
                    "observations": obs_box,
                    "action_mask": spaces.Box(0.0, 1.0, mask_box.shape, dtype=np.float32),
                }
            )
            act_spaces[a] = self.par_env.action_space(a)
        self.possible_agents = list(names)
        self.agents: list[str] = []
        self.observation_spaces = {k: v for k, v in obs_spaces.items()}  # typed as RLlib declares
        self.action_spaces = {k: v for k, v in act_spaces.items()}
        # the old API stack reads single spaces of the whole env
        self.observation_space = spaces.Dict(obs_spaces)
        self.action_space = spaces.Dict(act_spaces)

    @staticmethod
    def _convert(obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {
            "observations": np.asarray(obs["observation"], dtype=np.float32),
            "action_mask": np.asarray(obs["action_mask"], dtype=np.float32),
        }

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        obs, infos = self.par_env.reset(seed=seed, options=options)
        self.agents = list(self.par_env.agents)
        return {a: self._convert(o) for a, o in obs.items()}, infos

    def step(self, action_dict: dict[Any, Any]):
        actions = {a: int(action_dict[a]) for a in self.par_env.agents if a in action_dict}
        obs, rewards, terms, truncs, infos = self.par_env.step(actions)
        self.agents = list(self.par_env.agents)
        done = not self.agents
        terminateds: dict[str, bool] = {a: bool(v) for a, v in terms.items()}
        truncateds: dict[str, bool] = {a: bool(v) for a, v in truncs.items()}
        every_truncated = all(truncateds.values()) and bool(truncateds)
        terminateds["__all__"] = done and not every_truncated
        truncateds["__all__"] = done and every_truncated
        out_obs = {a: self._convert(o) for a, o in obs.items()}
        return out_obs, {a: float(r) for a, r in rewards.items()}, terminateds, truncateds, infos
