"""Lock-step episode runner on the batched :class:`~cdr_bench.vector_env.VectorEnv`.

Episodes of a scenario are cut into batches on a fixed grid (batch ``k`` holds episodes
``k * batch_size .. (k + 1) * batch_size - 1``); a batch is stepped in lock-step until every
aircraft in it has finished, calling the agent once per step for every flying controlled aircraft
of the batch (``act_batch``). Episode ``i`` starts from
:func:`~cdr_bench.evaluate.seeds.derive_seed`
and the agent's ``reset`` gets a seed derived from the batch, so a batch's results do not depend on
which process runs it, in which order, or whether the run was resumed.

Every returned action is checked before the step (an integer in 0..26; not a float, NaN or bool);
a masked action is passed on (the simulator does not execute its level change) and counted. Agent
exceptions, invalid values and decisions over the time limit raise :class:`AgentError` naming the
scenario, the episode, its seed, the step and the aircraft.
"""

from __future__ import annotations

import hashlib
import math
import numbers
import signal
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cdr_bench.actions import HOLD, N_ACTIONS
from cdr_bench.evaluate.loader import AgentError, LoadedAgent, agent_error_line, load_agent
from cdr_bench.evaluate.seeds import episode_seeds
from cdr_bench.scenarios import ScenarioConfig
from cdr_bench.sim import OUTCOME_NAMES
from cdr_bench.vector_env import VectorEnv, observation_space

DEFAULT_BATCH_SIZE = 200
DEFAULT_DECISION_TIMEOUT_S = 10.0


def spaces_for(config: ScenarioConfig) -> tuple[Any, Any]:
    """The per-agent observation space (Dict) and action space (Discrete(27)) of the env."""
    from gymnasium import spaces

    return observation_space(config), spaces.Discrete(N_ACTIONS)


def batch_seed(base_seed: int, scenario_id: str, config_hash: str, batch_index: int) -> int:
    """Seed passed to ``agent.reset`` before batch ``batch_index``."""
    key = f"{int(base_seed)}/{scenario_id}/{config_hash}/batch/{int(batch_index)}".encode()
    return int.from_bytes(hashlib.sha256(key).digest()[:8], "big") >> 1


# ----------------------------------------------------------------------------------------------
# Per-decision time limit


class DecisionTimeout(BaseException):
    """Raised inside the agent when a decision exceeds the limit (a BaseException so that an
    agent's own ``except Exception`` cannot swallow it)."""


@contextmanager
def deadline(seconds: float) -> Iterator[None]:
    """Interrupt the block with :class:`DecisionTimeout` after ``seconds`` (SIGALRM on POSIX in
    the main thread; elsewhere the caller checks the elapsed time afterwards)."""
    usable = (
        seconds > 0
        and math.isfinite(seconds)
        and hasattr(signal, "setitimer")
        and threading.current_thread() is threading.main_thread()
    )
    if not usable:
        yield
        return

    def on_alarm(signum: int, frame: Any) -> None:
        raise DecisionTimeout()

    previous = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)


# ----------------------------------------------------------------------------------------------
# Validation of returned actions


def _describe(value: Any) -> str:
    return f"{value!r} ({type(value).__name__})"


def validate_actions(out: Any, n: int) -> tuple[NDArray[np.int64] | None, int, str]:
    """``(actions, -1, "")`` if ``out`` holds ``n`` integers in 0..26, else
    ``(None, row, what)`` naming the first bad row (-1: the shape is wrong) and the value."""
    if isinstance(out, np.ndarray):
        arr = out
    else:
        try:
            seq = list(out)
        except TypeError:
            return None, -1, f"expected {n} action indices, got {_describe(out)}"
        for i, v in enumerate(seq):
            if not _is_int(v):
                return None, i, f"got {_describe(v)}, expected an integer in 0..{N_ACTIONS - 1}"
        arr = np.asarray(seq, dtype=np.int64) if seq else np.zeros(0, np.int64)
    if arr.shape != (n,):
        if arr.size == n and arr.ndim == 2 and arr.shape[1] == 1:
            arr = arr.reshape(n)
        else:
            return None, -1, f"expected {n} action indices, got an array of shape {arr.shape}"
    if arr.dtype == np.bool_ or not np.issubdtype(arr.dtype, np.integer):
        bad = 0
        if np.issubdtype(arr.dtype, np.floating):
            nan = np.flatnonzero(np.isnan(arr))
            bad = int(nan[0]) if nan.size else 0
        v = arr[bad].item() if arr.dtype != object else arr[bad]
        return (
            None,
            bad,
            (f"got {v!r} (dtype {arr.dtype}), expected an integer in 0..{N_ACTIONS - 1}"),
        )
    out_of_range = np.flatnonzero((arr < 0) | (arr >= N_ACTIONS))
    if out_of_range.size:
        i = int(out_of_range[0])
        return None, i, f"got {int(arr[i])}, expected an integer in 0..{N_ACTIONS - 1}"
    return arr.astype(np.int64, copy=False), -1, ""


def _is_int(v: Any) -> bool:
    if isinstance(v, np.ndarray) and v.ndim == 0:
        v = v[()]
    return isinstance(v, numbers.Integral) and not isinstance(v, (bool, np.bool_))


# ----------------------------------------------------------------------------------------------
# One batch


def run_batch(
    agent: LoadedAgent,
    config: ScenarioConfig,
    base_seed: int,
    batch_index: int,
    batch_size: int,
    n_episodes: int,
    decision_timeout_s: float = DEFAULT_DECISION_TIMEOUT_S,
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
    agent.reset(batch_seed(base_seed, config.id, chash, batch_index))
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
            with deadline(decision_timeout_s):
                out = agent.act_batch(obs, masks)
        except DecisionTimeout:
            raise AgentError(
                f"agent {agent.name}: a decision exceeded the time limit of "
                f"{decision_timeout_s:g} s ({where(0)}{' and others' if n > 1 else ''}; "
                "--decision-timeout sets the limit)"
            ) from None
        except Exception as exc:
            row, err = _localise(agent, obs, masks, decision_timeout_s)
            line = agent_error_line(err or exc, agent.path)
            at = where(row) if row >= 0 else f"{where(0)} (one of {n} aircraft of the batch)"
            raise AgentError(f"agent {agent.name} raised in {at}: {line}") from None
        elapsed = time.perf_counter() - t0
        if elapsed > decision_timeout_s > 0:  # no SIGALRM available (not the main thread)
            raise AgentError(
                f"agent {agent.name}: a decision exceeded the time limit of "
                f"{decision_timeout_s:g} s ({where(0)}; took {elapsed:.1f} s)"
            )
        actions, row, what = validate_actions(out, n)
        if actions is None:
            at = where(max(row, 0)) if row >= 0 else where(0) + f" (batch of {n} aircraft)"
            how = "act_batch" if agent.has_act_batch else "act"
            raise AgentError(f"agent {agent.name}: invalid action from {how} in {at}: {what}")
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


def _localise(
    agent: LoadedAgent,
    obs: NDArray[np.float32],
    masks: NDArray[np.int8],
    timeout_s: float,
) -> tuple[int, BaseException | None]:
    """After ``act_batch`` raised on a batch: the first row that raises on its own and its error
    (``(-1, None)`` if none does)."""
    if obs.shape[0] <= 1:
        return (0 if obs.shape[0] == 1 else -1), None
    for i in range(obs.shape[0]):
        try:
            with deadline(timeout_s):
                agent.act_batch(obs[i : i + 1], masks[i : i + 1])
        except DecisionTimeout:
            return -1, None
        except Exception as e:  # noqa: BLE001 - the agent's own error, reported verbatim
            return i, e
    return -1, None


# ----------------------------------------------------------------------------------------------
# Worker processes (spawn-safe: everything is passed by value, the agent is loaded by path)

_WORKER_AGENTS: dict[tuple[str, str], LoadedAgent] = {}


def load_for(agent_path: str | Path, config: ScenarioConfig) -> LoadedAgent:
    """The agent constructed with the spaces of ``config`` (cached per process)."""
    key = (str(agent_path), config.config_hash())
    if key not in _WORKER_AGENTS:
        obs_space, act_space = spaces_for(config)
        _WORKER_AGENTS[key] = load_agent(agent_path, obs_space, act_space)
    return _WORKER_AGENTS[key]


def run_batch_task(
    agent_path: str,
    config: ScenarioConfig,
    base_seed: int,
    batch_index: int,
    batch_size: int,
    n_episodes: int,
    decision_timeout_s: float,
) -> dict[str, Any]:
    """:func:`run_batch` with the agent loaded in this process (the worker entry point)."""
    agent = load_for(agent_path, config)
    return run_batch(
        agent, config, base_seed, batch_index, batch_size, n_episodes, decision_timeout_s
    )
