"""Quick batched evaluation through :class:`~cdr_bench.vector_env.VectorEnv` (for tuning; the
official scorer is ``cdr-bench evaluate``). Pure numpy: the policy is any
``act_batch(obs, masks) -> actions`` of the ownship."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from cdr_bench.sim.core import LOS, NMAC, SUCCESS, TIMEOUT
from cdr_bench.vector_env import VectorEnv

ActBatch = Callable[[np.ndarray, np.ndarray], np.ndarray]


def quick_eval(
    act_batch: ActBatch, scenario: str, episodes: int = 200, seed: int = 0, batch: int = 100
) -> dict[str, Any]:
    """Success / LoS / NMAC / timeout rates of the ownship over ``episodes`` episodes with
    seeds ``seed .. seed + episodes - 1`` (LoS = at least one LoS in the episode); other
    controlled aircraft hold."""
    out, had_los, steps = [], [], []
    for start in range(0, episodes, batch):
        env = VectorEnv(scenario, min(batch, episodes - start))
        obs, masks = env.reset(seeds=np.arange(seed + start, seed + start + env.num_envs))
        los = np.zeros(env.num_envs, bool)
        while (flying := env.flying).any():
            actions = np.full((env.num_envs, env.n_agents), 13)
            own = flying[:, 0]
            if own.any():
                actions[own, 0] = act_batch(obs[own, 0], masks[own, 0])
            st = env.step(actions)
            obs, masks = st.obs, st.action_mask
            los |= st.result.los_with[:, 0].any(-1)
        out.append(env.sim.ac_outcome[:, 0].copy())
        had_los.append(los)
        steps.append(env.sim.steps.copy())
    oc, hl, st_ = np.concatenate(out), np.concatenate(had_los), np.concatenate(steps)
    return {
        "scenario": scenario,
        "episodes": len(oc),
        "success": float(np.mean(oc == SUCCESS)),
        "clean_success": float(np.mean((oc == SUCCESS) & ~hl)),
        "los": float(np.mean(hl | (oc == LOS))),
        "nmac": float(np.mean(oc == NMAC)),
        "timeout": float(np.mean(oc == TIMEOUT)),
        "steps_success": float(np.mean(st_[oc == SUCCESS])) if (oc == SUCCESS).any() else np.nan,
    }
