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
from cdr_bench.evaluate.rollout import fly
from cdr_bench.sim.core import OUTCOME_NAMES
from cdr_bench.vector_env import VectorEnv, VectorStep

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
        los, flown = _fly_ownship(act_batch, env, obs, masks)
        out.append(env.outcomes[:, 0].copy())
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


def _fly_ownship(
    act_batch: ActBatch, env: VectorEnv, obs: np.ndarray, masks: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Fly the episodes just started in ``env`` to their end, the ownship by ``act_batch``, the
    other controlled aircraft holding: whether each ownship was ever in LoS, and its steps
    (decisions)."""
    los = np.zeros(env.num_envs, bool)
    flown = np.zeros(env.num_envs, np.int64)

    def on_step(_: np.ndarray, st: VectorStep) -> None:
        los[:] |= st.result.los_with[:, 0].any(-1)
        flown[:] += st.result.acting[:, 0]

    fly(
        env,
        obs,
        masks,
        lambda d: act_batch(d.obs, d.masks),
        drive="ownship",
        until="all",
        on_step=on_step,
    )
    return los, flown
