"""Quick batched evaluation through :class:`~cdr_bench.vector_env.VectorEnv` (for tuning; the
official scorer is ``cdr-bench evaluate``). Pure numpy: the policy is any
``act_batch(obs, masks) -> actions`` of the ownship. Its rates are those of the metric registry
(:mod:`cdr_bench.evaluate.metrics`), over the same per-aircraft facts the evaluator records
(``outcome``, ``los``, ``steps``), so one definition (of a LoS episode, say) holds for both."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from cdr_bench.evaluate.metrics import get_metric
from cdr_bench.sim.core import OUTCOME_NAMES
from cdr_bench.vector_env import VectorEnv

ActBatch = Callable[[np.ndarray, np.ndarray], np.ndarray]

QUICK_METRICS = {
    "success": "success_rate",
    "clean_success": "clean_success_rate",
    "los": "los_rate",
    "nmac": "nmac_rate",
    "timeout": "timeout_rate",
    "steps_success": "avg_steps_success",
}
"""Key of :func:`quick_eval`'s result (and of the training logs' ``eval/<scenario>``) -> metric
of the registry."""


def quick_eval(
    act_batch: ActBatch, scenario: str, episodes: int = 200, seed: int = 0, batch: int = 100
) -> dict[str, Any]:
    """Success, clean success, LoS, NMAC and timeout rates and the steps of successful episodes
    of the ownship over ``episodes`` episodes with seeds ``seed .. seed + episodes - 1`` (the
    registry's metrics of :data:`QUICK_METRICS`, unrounded, without intervals; NaN steps
    without a success); other controlled aircraft hold."""
    out, had_los, steps = [], [], []
    for start in range(0, episodes, batch):
        env = VectorEnv(scenario, min(batch, episodes - start))
        obs, masks = env.reset(seeds=np.arange(seed + start, seed + start + env.num_envs))
        los = np.zeros(env.num_envs, bool)
        flown = np.zeros(env.num_envs, np.int64)  # the ownship's steps (decisions)
        while (flying := env.flying).any():
            actions = np.full((env.num_envs, env.n_agents), 13)
            own = flying[:, 0]
            if own.any():
                actions[own, 0] = act_batch(obs[own, 0], masks[own, 0])
            st = env.step(actions)
            obs, masks = st.obs, st.action_mask
            los |= st.result.los_with[:, 0].any(-1)
            flown += st.result.acting[:, 0]
        out.append(env.sim.ac_outcome[:, 0].copy())
        had_los.append(los)
        steps.append(flown)
    oc, hl, st_ = np.concatenate(out), np.concatenate(had_los), np.concatenate(steps)
    records = [
        {"outcome": OUTCOME_NAMES[int(o)], "los": bool(h), "steps": int(s)}
        for o, h, s in zip(oc, hl, st_, strict=True)
    ]
    return {
        "scenario": scenario,
        "episodes": len(records),
        **{k: get_metric(m).point(records) for k, m in QUICK_METRICS.items()},
    }
