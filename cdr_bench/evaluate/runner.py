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

from cdr_bench.actions import N_ACTIONS
from cdr_bench.evaluate.loader import AgentError
from cdr_bench.evaluate.remote import (
    DEFAULT_DECISION_TIMEOUT_S,
    AgentFault,
    AgentOptions,
    AgentProcess,
    RemoteAgent,
)
from cdr_bench.evaluate.rollout import Decisions, fly
from cdr_bench.evaluate.seeds import episode_seeds
from cdr_bench.scenarios import ScenarioConfig
from cdr_bench.sim import OUTCOME_NAMES, kernels, observation_bounds
from cdr_bench.sim.units import KM_PER_S_PER_KT
from cdr_bench.vector_env import VectorEnv, VectorStep, observation_space

__all__ = ["DEFAULT_DECISION_TIMEOUT_S", "run_batch", "run_batch_task", "load_for"]

DEFAULT_BATCH_SIZE = 200


def spaces_for(config: ScenarioConfig) -> tuple[Any, Any]:
    """The per-agent observation space (Dict) and action space (Discrete(27)) of the env."""
    from gymnasium import spaces

    return observation_space(config), spaces.Discrete(N_ACTIONS)


def batch_seed(
    base_seed: int, scenario_id: str, config_hash: str, batch_index: int, agent_key: str = ""
) -> int:
    """Seed passed to ``agent.reset`` before batch ``batch_index``. With an ``agent_key`` (a
    secret drawn by the scorer, e.g. for the fresh episodes of ``leaderboard build --check``)
    the seed is independent of the episodes' seeds for anyone who does not know the key, so an
    agent cannot tell from it which episodes it is flying."""
    key = f"{int(base_seed)}/{scenario_id}/{config_hash}/batch/{int(batch_index)}"
    if agent_key:
        key = f"{agent_key}/{key}"
    return int.from_bytes(hashlib.sha256(key.encode()).digest()[:8], "big") >> 1


# ----------------------------------------------------------------------------------------------
# One batch


ACTION_CODE = "0123456789abcdefghijklmnopq"
"""How a record stores its decisions: one character per decision, action ``a`` as
``ACTION_CODE[a]`` (a base-27 digit: ``int(c, 27)`` decodes it)."""
_CODE_BYTES = np.frombuffer(ACTION_CODE.encode(), dtype=np.uint8)
_DECODE = np.full(256, -1, dtype=np.int16)
_DECODE[_CODE_BYTES] = np.arange(N_ACTIONS)


def encode_actions(actions: np.ndarray) -> str:
    """The record string of a sequence of actions in 0..26."""
    return _CODE_BYTES[np.asarray(actions, dtype=np.int64)].tobytes().decode("ascii")


def decode_actions(code: str) -> np.ndarray:
    """The actions of a record string; ``ValueError`` for a character that is not a code."""
    try:
        raw = np.frombuffer(code.encode("ascii"), dtype=np.uint8)
    except (UnicodeEncodeError, AttributeError):
        raise ValueError("actions: expected a string of characters 0-9, a-q") from None
    out = _DECODE[raw]
    if (out < 0).any():
        raise ValueError("actions: expected a string of characters 0-9, a-q")
    return out.astype(np.int64)


class ReplayMismatch(Exception):
    """A recorded episode cannot be replayed as recorded (it needs more or fewer decisions
    than its record holds)."""


def run_batch(
    agent: RemoteAgent | None,
    config: ScenarioConfig,
    base_seed: int,
    batch_index: int,
    batch_size: int,
    n_episodes: int,
    trace: int = 0,
    replay: list[dict[str, str]] | None = None,
    agent_key: str = "",
) -> dict[str, Any]:
    """Run batch ``batch_index`` of a scenario (episodes on the fixed grid, at most
    ``n_episodes`` in all). Returns ``{"batch", "episodes": [record, ...], "timing": {...}}``,
    plus ``"traces"`` (:func:`_frame`) of the batch's first ``trace`` episodes if ``trace``.

    With ``replay`` (per episode of the batch, the recorded ``actions`` string of each flight
    by its aircraft id; a flight not recorded never entered the sky), the recorded decisions
    are flown instead of the agent's: the records
    come out identical to the recorded ones when the recording is honest (raises
    :class:`ReplayMismatch` when an aircraft needs more decisions than recorded, or fewer). An
    ``agent`` given with ``replay`` is asked at every step as usual (same observations, same
    reset seed), and its choices are counted against the record in ``"agreement"``
    (``decisions``, ``agree``, ``disagreements``: the first few as ``[episode, aircraft id,
    decision index, recorded, re-run]``) without changing the flight; ``agent=None`` replays
    only. ``agent_key``: see :func:`batch_seed`.
    """
    chash = config.config_hash()
    start = batch_index * batch_size
    stop = min(start + batch_size, n_episodes)
    seeds = episode_seeds(base_seed, config.id, chash, start, stop)
    E = stop - start
    env = VectorEnv(config, num_envs=E)
    obs_all, masks_all = env.reset(seeds=seeds)
    if agent is not None:
        try:
            agent.reset(batch_seed(base_seed, config.id, chash, batch_index, agent_key))
        except AgentFault as f:
            at = f"reset(seed) before episodes {start}..{stop - 1} of scenario {config.id!r}"
            raise AgentError(fault_message(f, agent, at)) from None
    ids = env.agent_ids
    M = env.n_agents
    cap = config.time.max_steps + 1
    decisions = np.zeros((E, M, cap), dtype=np.int8)
    n_dec = np.zeros((E, M), dtype=np.int64)
    recorded_n = None
    if replay is not None:
        index = {a: m for m, a in enumerate(ids)}
        if len(replay) != E or any(not set(r) <= index.keys() for r in replay):
            raise ReplayMismatch(f"the record of batch {batch_index} has another shape")
        recorded_n = np.zeros((E, M), dtype=np.int64)
        for e in range(E):
            for name, code in replay[e].items():
                m = index[name]
                a = decode_actions(code)[:cap]
                decisions[e, m, : a.size] = a
                recorded_n[e, m] = len(code)
    agree = 0
    asked = 0
    disagreements: list[list[Any]] = []

    N = env.n_aircraft
    dt_s = config.time.dt_s
    los_km = config.separation.los_km
    steps = np.zeros((E, M), dtype=np.int64)
    los = np.zeros((E, M), dtype=bool)
    nmac = np.zeros((E, M), dtype=bool)
    goal_r = np.zeros((E, M))
    safety_r = np.zeros((E, M))
    invalid = np.zeros((E, M), dtype=np.int64)
    min_sep = np.full((E, M), np.inf)
    outcome = np.zeros((E, M), dtype=np.int8)
    # Field metrics (docs/model.md §10.1): events are pairs entering a state, counted by
    # kernels.pair_events in one pass a step. The *_ac counts are the same with other
    # controlled aircraft only (recorded where there are several): a pair of controlled
    # aircraft is in both of its records, and the system metrics count it once.
    counts = np.zeros((8, E, M), dtype=np.int64)
    (los_events, nmac_events, los_events_ac, nmac_events_ac) = counts[:4]
    (los_steps, conflict_events, los_now, nmac_now) = counts[4:]
    B = env.n_background
    manoeuvres = np.zeros((E, M), dtype=np.int64)
    path_km = np.zeros((E, M))
    prev_los = np.zeros((E, M, N), dtype=bool)
    prev_nmac = np.zeros((E, M, N), dtype=bool)
    in_conflict = env.conflicts()
    conflict_events += in_conflict.sum(axis=2)
    conflict_now = np.zeros_like(in_conflict)
    start_km = env.positions_km.copy()
    goal_km = env.goals_km.copy()
    gap = goal_km - start_km
    goal_radius = config.ownship.goal_radius_km
    direct_km = np.maximum(_norm(gap) - goal_radius, 0.0)
    flight_s = np.zeros((E, M))
    start_speed_km_s = env.speeds_kt * KM_PER_S_PER_KT
    # The step at which each flight entered the sky: 0 for those flying at the start, -1 for
    # those still to enter (traffic.controlled_spawns; their start, goal and direct route are
    # taken when they enter), and for any that never does (no record).
    entered = np.where(env.flying, 0, -1)
    first_spawn = M - config.traffic.controlled_spawns
    traces = [_trace_head(config, env, start + e, seeds[e], ids, e) for e in range(min(trace, E))]
    for t in traces:
        t["frames"].append(_frame(env, t.pop("_row"), None))
    per_decision_ms: list[float] = []
    per_call_ms: list[float] = []
    episode_steps = env.episode_steps  # a live view
    before_km = start_km.copy()

    def decide(d: Decisions) -> np.ndarray:
        """The actions of the flying aircraft ``d`` (the agent's, or the record's when
        replaying), counted and recorded."""
        nonlocal asked, agree
        rows_e, rows_m, obs, masks = d.episodes, d.aircraft, d.obs, d.masks

        def where(row: int) -> str:
            e, m = int(rows_e[row]), int(rows_m[row])
            return (
                f"scenario {config.id!r}, episode {start + e} (seed {seeds[e]}), "
                f"step {int(episode_steps[e])}, {ids[m]}"
            )

        n = rows_e.size
        k = n_dec[rows_e, rows_m]
        if recorded_n is not None:
            short = k >= recorded_n[rows_e, rows_m]
            if short.any():
                raise ReplayMismatch(f"{where(int(np.argmax(short)))}: the record ends here")
        if agent is not None:
            t0 = time.perf_counter()
            try:
                if agent.joint:
                    actions = agent.act_joint(obs, masks, rows_e, rows_m)
                else:
                    actions = agent.act_batch(obs, masks)
            except AgentFault as f:
                if f.kind == "raised" and f.row < 0 and n > 1 and not agent.joint:
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
        if recorded_n is not None:
            played = decisions[rows_e, rows_m, k].astype(np.int64)
            if agent is not None:
                same = np.asarray(actions) == played
                asked += n
                agree += int(same.sum())
                for r in np.flatnonzero(~same)[: max(0, 20 - len(disagreements))]:
                    disagreements.append(
                        [
                            start + int(rows_e[r]),
                            ids[int(rows_m[r])],
                            int(k[r]),
                            int(played[r]),
                            int(actions[r]),
                        ]
                    )
            actions = played
        else:
            decisions[rows_e, rows_m, k] = actions
        n_dec[rows_e, rows_m] += 1
        return actions

    def on_step(actions: np.ndarray, step: VectorStep) -> None:
        """The step's part of every metric (and of the traces)."""
        nonlocal prev_los, prev_nmac, in_conflict, conflict_now
        res = step.result
        after_km = env.positions_km
        if first_spawn < M:
            new = env.flying & (entered < 0)
            if new.any():
                enter_flights(new, after_km)
        los_with, nmac_with = res.los_with, res.nmac_with
        env.conflicts(conflict_now)
        kernels.pair_events(
            los_with, nmac_with, prev_los, prev_nmac, conflict_now, in_conflict, B, counts
        )
        prev_los, prev_nmac = los_with, nmac_with
        in_conflict, conflict_now = conflict_now, in_conflict
        kernels.accumulate_step(
            actions, res.terms, res.flags, res.outcome, res.min_sep_km, before_km, after_km,
            goal_km, goal_radius, dt_s, counts, manoeuvres, steps, path_km, flight_s, goal_r,
            safety_r, invalid, min_sep, outcome, los, nmac,
        )  # fmt: skip
        before_km[:] = after_km
        for i, t in enumerate(traces):
            if res.acting[i].any():
                t["frames"].append(_frame(env, i, los_now[i].astype(bool)))

    def enter_flights(new: np.ndarray, at_km: np.ndarray) -> None:
        """Flights that entered the sky during the step: their start, goal and direct route."""
        entered[new] = episode_steps[np.nonzero(new)[0]]
        start_km[new] = at_km[new]
        goal_km[new] = env.goals_km[new]
        direct_km[new] = np.maximum(_norm(goal_km[new] - at_km[new]) - goal_radius, 0.0)
        start_speed_km_s[new] = env.speeds_kt[new] * KM_PER_S_PER_KT

    fly(env, obs_all, masks_all, decide, on_step=on_step)

    episodes = []
    for e in range(E):
        aircraft = []
        for m in range(M):
            if entered[e, m] < 0:  # never entered the sky: not a flight
                continue
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
                    "severity": round(max(0.0, 1.0 - sep / los_km), 6)
                    if math.isfinite(sep)
                    else None,
                    "los_events": int(los_events[e, m]),
                    "los_s": round(float(los_steps[e, m]) * dt_s, 6),
                    "nmac_events": int(nmac_events[e, m]),
                    "conflicts": int(conflict_events[e, m]),
                    "manoeuvres": int(manoeuvres[e, m]),
                    "flight_s": round(float(flight_s[e, m]), 4),
                    "path_km": round(float(path_km[e, m]), 4),
                    "direct_km": round(float(direct_km[e, m]), 4),
                    "direct_s": round(float(direct_km[e, m] / start_speed_km_s[e, m]), 4)
                    if start_speed_km_s[e, m] > 0
                    else None,
                    "actions": encode_actions(decisions[e, m, : n_dec[e, m]]),
                }
            )
            if M > 1:
                aircraft[-1]["los_events_ac"] = int(los_events_ac[e, m])
                aircraft[-1]["nmac_events_ac"] = int(nmac_events_ac[e, m])
            if m >= first_spawn:
                aircraft[-1]["entered_s"] = round(float(entered[e, m]) * dt_s, 4)
        episodes.append(
            {
                "episode": start + e,
                "seed": seeds[e],
                "steps": int(episode_steps[e]),
                "aircraft": aircraft,
            }
        )
    if recorded_n is not None:
        extra = np.argwhere(n_dec != recorded_n)
        if extra.size:
            e, m = (int(x) for x in extra[0])
            raise ReplayMismatch(
                f"scenario {config.id!r}, episode {start + e}, {ids[m]}: the record holds "
                f"{int(recorded_n[e, m])} decisions, the flight took {int(n_dec[e, m])}"
            )
    for i, t in enumerate(traces):
        t["outcomes"] = [OUTCOME_NAMES[int(o)] for o in outcome[i]]
    out: dict[str, Any] = {
        "scenario": config.id,
        "batch": batch_index,
        "episodes": episodes,
        "timing": {
            "per_decision_ms": [round(x, 5) for x in per_decision_ms],
            "per_call_ms": [round(x, 5) for x in per_call_ms],
        },
    }
    if trace:
        out["traces"] = traces
    if agent is not None and recorded_n is not None:
        out["agreement"] = {"decisions": asked, "agree": agree, "disagreements": disagreements}
    return out


def _norm(v: np.ndarray) -> np.ndarray:
    """Length of (..., 2) vectors."""
    return np.sqrt(v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1])


def _trace_head(
    config: ScenarioConfig, env: VectorEnv, episode: int, seed: int, ids: list[str], row: int
) -> dict[str, Any]:
    """The fixed part of an episode's trace (``frames`` filled by :func:`_frame`)."""
    return {
        "episode": episode,
        "seed": seed,
        "scenario": config.id,
        "dt_s": config.time.dt_s,
        "size_km": config.sector.size_km,
        "los_km": config.separation.los_km,
        "ids": list(ids),
        "goals_km": [[round(float(v), 2) for v in g] for g in env.goals_km[row]],
        "frames": [],
        "_row": row,
    }


def _frame(env: VectorEnv, e: int, los_any: Any) -> dict[str, Any]:
    """One frame of episode ``e``'s trace: controlled aircraft ``c`` as ``[x_km, y_km, level,
    flying]``, background aircraft in the sky ``b`` as ``[x_km, y_km, level]`` and ``los``, per
    controlled aircraft, 1 if it was in LoS during the step that led here (0 at the start)."""
    B, N = env.n_background, env.n_aircraft
    pos, level = env.aircraft_positions_km[e], env.aircraft_levels[e]
    active = env.aircraft_in_sky[e]
    return {
        "c": [
            [round(float(pos[n, 0]), 2), round(float(pos[n, 1]), 2), int(level[n]), int(active[n])]
            for n in range(B, N)
        ],
        "b": [
            [round(float(pos[n, 0]), 2), round(float(pos[n, 1]), 2), int(level[n])]
            for n in range(B)
            if active[n]
        ],
        "los": [0] * (N - B) if los_any is None else [int(x) for x in los_any],
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
    agent_key: str = "",
) -> dict[str, Any]:
    """:func:`run_batch` with the agent of this process (the worker entry point)."""
    agent = load_for(agent_path, config, options)
    return run_batch(
        agent, config, base_seed, batch_index, batch_size, n_episodes, agent_key=agent_key
    )
