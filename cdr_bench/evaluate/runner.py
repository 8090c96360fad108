"""Lock-step episode runner on the batched :class:`~cdr_bench.vector_env.VectorEnv`.

Episodes of a scenario are cut into batches on a fixed grid (batch ``k`` holds episodes
``k * batch_size .. (k + 1) * batch_size - 1``); a batch is stepped in lock-step until every
aircraft in it has finished, calling the agent once per step for every flying controlled aircraft
of the batch (``act_batch``). Episode ``i`` starts from
:func:`~cdr_bench.evaluate.seeds.derive_seed`
and the agent's ``reset`` gets a seed derived from the batch, so a batch's results do not depend on
which process runs it, in which order, or whether the run was resumed.

The agent runs in its own process (:mod:`.remote`); this module only sends it observations and
masks and receives actions. Every returned action is checked (an integer in 0..26; not a float,
NaN or bool); a masked action is passed on (the simulator does not execute its level change) and
counted. Agent exceptions, invalid values, decisions over the time limit and an agent process that
dies raise :class:`AgentError` naming the scenario, the episode, its seed, the step and the
aircraft.
"""

from __future__ import annotations

import atexit
import hashlib
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from cdr_bench.actions import HOLD, N_ACTIONS
from cdr_bench.evaluate.loader import AgentError
from cdr_bench.evaluate.remote import (
    DEFAULT_DECISION_TIMEOUT_S,
    AgentFault,
    AgentOptions,
    AgentProcess,
    RemoteAgent,
)
from cdr_bench.evaluate.seeds import episode_seeds
from cdr_bench.scenarios import ScenarioConfig
from cdr_bench.sim import OUTCOME_NAMES, observation_bounds
from cdr_bench.vector_env import VectorEnv, observation_space

__all__ = ["DEFAULT_DECISION_TIMEOUT_S", "run_batch", "run_batch_task", "load_for"]

DEFAULT_BATCH_SIZE = 200


def spaces_for(config: ScenarioConfig) -> tuple[Any, Any]:
    """The per-agent observation space (Dict) and action space (Discrete(27)) of the env."""
    from gymnasium import spaces

    return observation_space(config), spaces.Discrete(N_ACTIONS)


def batch_seed(base_seed: int, scenario_id: str, config_hash: str, batch_index: int) -> int:
    """Seed passed to ``agent.reset`` before batch ``batch_index``."""
    key = f"{int(base_seed)}/{scenario_id}/{config_hash}/batch/{int(batch_index)}".encode()
    return int.from_bytes(hashlib.sha256(key).digest()[:8], "big") >> 1


# ----------------------------------------------------------------------------------------------
# One batch


def run_batch(
    agent: RemoteAgent,
    config: ScenarioConfig,
    base_seed: int,
    batch_index: int,
    batch_size: int,
    n_episodes: int,
) -> dict[str, Any]:
    """Run batch ``batch_index`` of a scenario (episodes on the fixed grid, at most
    ``n_episodes`` in all). Returns ``{"batch", "episodes": [record, ...], "timing": {...}}``."""
    chash = config.config_hash()
    start = batch_index * batch_size
    stop = min(start + batch_size, n_episodes)
    seeds = episode_seeds(base_seed, config.id, chash, start, stop)
    E = stop - start
    env = VectorEnv(config, num_envs=E)
    obs_all, masks_all = env.reset(seeds=seeds)
    try:
        agent.reset(batch_seed(base_seed, config.id, chash, batch_index))
    except AgentFault as f:
        at = f"reset(seed) before episodes {start}..{stop - 1} of scenario {config.id!r}"
        raise AgentError(fault_message(f, agent, at)) from None
    ids = env.agent_ids
    M = env.n_agents

    steps = np.zeros((E, M), dtype=np.int64)
    los = np.zeros((E, M), dtype=bool)
    nmac = np.zeros((E, M), dtype=bool)
    goal_r = np.zeros((E, M))
    safety_r = np.zeros((E, M))
    invalid = np.zeros((E, M), dtype=np.int64)
    min_sep = np.full((E, M), np.inf)
    outcome = np.zeros((E, M), dtype=np.int8)
    per_decision_ms: list[float] = []
    per_call_ms: list[float] = []
    full = np.full((E, M), HOLD, dtype=np.int64)
    flying = env.flying
    episode_steps = env.sim.steps

    def where(row: int) -> str:
        e, m = int(rows_e[row]), int(rows_m[row])
        return (
            f"scenario {config.id!r}, episode {start + e} (seed {seeds[e]}), "
            f"step {int(episode_steps[e])}, {ids[m]}"
        )

    while flying.any():
        rows_e, rows_m = np.nonzero(flying)
        obs = obs_all[rows_e, rows_m]
        masks = masks_all[rows_e, rows_m]
        n = rows_e.size
        t0 = time.perf_counter()
        try:
            actions = agent.act_batch(obs, masks)
        except AgentFault as f:
            if f.kind == "raised" and f.row < 0 and n > 1:
                f = agent.localise(obs, masks) or f
            at = (
                where(f.row)
                if 0 <= f.row < n
                else where(0) + (f" (one of {n} aircraft of the batch)" if n > 1 else "")
            )
            raise AgentError(fault_message(f, agent, at)) from None
        elapsed = time.perf_counter() - t0
        per_call_ms.append(elapsed * 1e3)
        per_decision_ms.append(elapsed * 1e3 / n)

        full[:] = HOLD
        full[rows_e, rows_m] = actions
        step = env.step(full)
        res = step.result
        obs_all, masks_all = step.obs, step.action_mask
        steps += res.acting
        los |= res.los_with.any(axis=2)
        nmac |= res.nmac_with.any(axis=2)
        goal_r += res.goal_reward
        safety_r += res.safety_reward
        invalid += res.invalid_action
        np.minimum(min_sep, res.min_sep_km, out=min_sep)
        done = res.outcome != 0
        outcome[done] = res.outcome[done]
        flying = env.flying

    episodes = []
    for e in range(E):
        aircraft = []
        for m in range(M):
            sep = float(min_sep[e, m])
            aircraft.append(
                {
                    "id": ids[m],
                    "outcome": OUTCOME_NAMES[int(outcome[e, m])],
                    "steps": int(steps[e, m]),
                    "los": bool(los[e, m]),
                    "nmac": bool(nmac[e, m]),
                    "goal_reward": round(float(goal_r[e, m]), 6),
                    "safety_reward": round(float(safety_r[e, m]), 6),
                    "invalid_actions": int(invalid[e, m]),
                    "min_sep_km": round(sep, 4) if math.isfinite(sep) else None,
                }
            )
        episodes.append(
            {
                "episode": start + e,
                "seed": seeds[e],
                "steps": int(episode_steps[e]),
                "aircraft": aircraft,
            }
        )
    return {
        "scenario": config.id,
        "batch": batch_index,
        "episodes": episodes,
        "timing": {
            "per_decision_ms": [round(x, 5) for x in per_decision_ms],
            "per_call_ms": [round(x, 5) for x in per_call_ms],
        },
    }


def fault_message(f: AgentFault, agent: RemoteAgent, at: str) -> str:
    """One line (plus the confined agent's last output) for a fault of ``agent`` at ``at``."""
    name = agent.name
    if f.kind == "raised":
        return f"agent {name} raised in {at}: {f.message}"
    if f.kind == "invalid":
        head, _, what = f.message.partition(": ")
        return f"agent {name}: {head} in {at}: {what}"
    if f.kind == "timeout":
        limit = agent.process.options.decision_timeout_s
        return (
            f"agent {name}: a decision exceeded the time limit of {limit:g} s ({at}; killed; "
            "--decision-timeout sets the limit)"
        )
    return (
        f"agent {name}: {f.message.rstrip()} ({at})"
        if "\n" not in f.message
        else (f"agent {name}: in {at}: {f.message}")
    )


# ----------------------------------------------------------------------------------------------
# The agent process of this process (spawn-safe: everything is passed by value)

_PROCESSES: dict[tuple[str, AgentOptions], AgentProcess] = {}


def load_for(
    agent_path: str | Path, config: ScenarioConfig, options: AgentOptions | None = None
) -> RemoteAgent:
    """The agent, constructed with the spaces of ``config``, in this process's agent process
    (started on first use, one per agent and options; closed at exit or by :func:`close_all`)."""
    options = options or AgentOptions()
    key = (str(agent_path), options)
    proc = _PROCESSES.get(key)
    if proc is None or proc.proc.poll() is not None:
        proc = _PROCESSES[key] = AgentProcess(agent_path, options)
    low, high = observation_bounds(config)
    return proc.instance(low, high)


def close_all() -> None:
    """Stop every agent process this process started."""
    while _PROCESSES:
        _, proc = _PROCESSES.popitem()
        proc.close()


atexit.register(close_all)


def run_batch_task(
    agent_path: str,
    config: ScenarioConfig,
    base_seed: int,
    batch_index: int,
    batch_size: int,
    n_episodes: int,
    options: AgentOptions,
) -> dict[str, Any]:
    """:func:`run_batch` with the agent of this process (the worker entry point)."""
    agent = load_for(agent_path, config, options)
    return run_batch(agent, config, base_seed, batch_index, batch_size, n_episodes)
