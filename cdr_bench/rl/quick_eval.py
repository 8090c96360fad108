"""Quick batched evaluation on the simulator (for tuning; the official scorer is
``cdr-bench evaluate``). Pure numpy: the policy is any ``act_batch(obs, masks) -> actions``."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from cdr_bench.scenarios import load_scenario
from cdr_bench.sim import Simulator, observe
from cdr_bench.sim.core import LOS, NMAC, SUCCESS, TIMEOUT

ActBatch = Callable[[np.ndarray, np.ndarray], np.ndarray]


def quick_eval(
    act_batch: ActBatch, scenario: str, episodes: int = 200, seed: int = 0, batch: int = 100
) -> dict[str, Any]:
    """Success / LoS / NMAC / timeout rates of the ownship over ``episodes`` episodes with
    seeds ``seed .. seed + episodes - 1`` (LoS = at least one LoS in the episode)."""
    cfg = load_scenario(scenario)
    n_done, succ, los, nmac, tout, steps_succ = 0, 0, 0, 0, 0, []
    for start in range(0, episodes, batch):
        E = min(batch, episodes - start)
        sim = Simulator(cfg, n_episodes=E)
        sim.reset(np.arange(seed + start, seed + start + E))
        had_los = np.zeros(E, bool)
        while sim.ac_active.any():
            obs = observe(sim)[:, 0]
            masks = sim.action_masks()[:, 0]
            flying = sim.ac_active[:, 0]
            a = np.full(E, 13)
            if flying.any():
                a[flying] = act_batch(obs[flying], masks[flying])
            res = sim.step(a[:, None])
            had_los |= res.los_with[:, 0].any(-1)
        out = sim.ac_outcome[:, 0]
        n_done += E
        succ += int((out == SUCCESS).sum())
        los += int((had_los | (out == LOS)).sum())
        nmac += int((out == NMAC).sum())
        tout += int((out == TIMEOUT).sum())
        steps_succ += list(sim.steps[out == SUCCESS])
    return {
        "scenario": scenario,
        "episodes": n_done,
        "success": succ / n_done,
        "los": los / n_done,
        "nmac": nmac / n_done,
        "timeout": tout / n_done,
        "steps_success": float(np.mean(steps_succ)) if steps_succ else float("nan"),
    }
