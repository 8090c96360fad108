"""Headroom: what a planner that knows the future of the traffic achieves on the same episodes.

The leaderboard ranks agents that see only their observations. How far are they, and MVP,
from what is possible? :func:`plan` answers it for the ownship of a single-aircraft scenario
(``high`` on the leaderboard): for every episode it searches the follow-on policies of
:mod:`cdr_bench.evaluate.search` (hold at the first step, then a turn, a hold, a return to the
goal, with a target speed and levels; simplest first), each flown in its own copy of the episode
with the real traffic, and keeps the first one after which the ownship reaches its goal with no
loss of separation at all (a *clean* success, the headline of the ranking). The background
traffic flies its airways whatever the ownship does, so a copy of the episode is the episode.

The planner is not an agent: it reads the episode's seed and the traffic's future, which no
submission can, so its row is shown apart and never ranked. Where it finds no clean plan in the
family it keeps the first plan that reaches the goal (else the simplest one), so its rate is a
lower bound of what is possible, not the optimum. Its result file is an ordinary result
(:func:`headroom_result`): the decisions of every episode are in the log, and ``leaderboard build
--check`` replays them like any entry's, so the row is proven by its own witnesses.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cdr_bench.actions import HOLD
from cdr_bench.errors import UserError
from cdr_bench.evaluate import results as rf
from cdr_bench.evaluate.api import result_head, scenario_entry
from cdr_bench.evaluate.rollout import Decisions, fly
from cdr_bench.evaluate.runner import encode_actions, run_batch
from cdr_bench.evaluate.search import _follow_on_actions, follow_on_family
from cdr_bench.evaluate.seeds import episode_seeds
from cdr_bench.scenarios.schema import ScenarioConfig
from cdr_bench.sim.core import SUCCESS
from cdr_bench.vector_env import VectorEnv

NAME = "headroom"
"""The planner's name in its result (``agent.name``)."""
FIRST_PASS = 64
"""Follow-ons tried for every episode; the rest of the family only where none is clean."""
MAX_ROLLOUTS = 1 << 13
"""Most copies of episodes flown at once (memory: about 1 kB each)."""


def _fly_family(
    config: ScenarioConfig, seeds: list[int], family: dict[str, NDArray[np.float64]]
) -> tuple[NDArray[np.int64], NDArray[np.bool_], NDArray[np.bool_], NDArray[np.int64]]:
    """Every follow-on of ``family`` (F rows) in a copy of every episode of ``seeds`` (S), at
    once: ``(played (S*F, T), success (S*F,), clean (S*F,), steps (S*F,))``, episode-major."""
    n_f = len(family["turn"])
    E = len(seeds) * n_f
    fam = {k: np.tile(v, len(seeds)) for k, v in family.items()}
    env = VectorEnv(config, num_envs=E)
    obs, masks = env.reset(seeds=np.repeat(np.asarray(seeds, dtype=np.uint64), n_f))
    horizon = config.time.max_steps
    played = np.full((E, horizon), HOLD, dtype=np.int64)
    los = np.zeros(E, dtype=bool)

    def decide(d: Decisions) -> NDArray[np.int64]:
        a = np.full(E, HOLD, np.int64) if d.t == 0 else _follow_on_actions(env, fam, d.t - 1)
        played[:, d.t] = a
        return a[d.episodes]

    def on_step(actions: NDArray[np.int64], step: Any) -> None:
        los[:] |= step.result.los_with[:, 0].any(axis=1)

    fly(env, obs, masks, decide, drive="ownship", max_steps=horizon, on_step=on_step)
    success = env.outcomes[:, 0] == SUCCESS
    return played, success, success & ~los, env.episode_steps.copy()


def plan(
    config: ScenarioConfig, seeds: list[int], first_pass: int = FIRST_PASS
) -> list[NDArray[np.int64]]:
    """The ownship's decisions in each episode of ``seeds``: the first clean plan of the
    follow-on family (:func:`~cdr_bench.evaluate.search.follow_on_family`, simplest first), else
    the first that reaches the goal, else the simplest."""
    if config.n_controlled != 1:
        raise UserError(
            f"headroom: scenario {config.id} has {config.n_controlled} controlled aircraft; the "
            "planner flies the ownship of a single-aircraft scenario"
        )
    family = follow_on_family()
    n_family = len(family["turn"])
    best: dict[int, tuple[int, NDArray[np.int64]]] = {}  # episode -> (rank, plan)
    todo = list(range(len(seeds)))
    for lo, hi in ((0, min(first_pass, n_family)), (min(first_pass, n_family), n_family)):
        rows = {k: v[lo:hi] for k, v in family.items()}
        n_rows = hi - lo
        per = max(1, MAX_ROLLOUTS // max(n_rows, 1))
        for i in range(0, len(todo) if n_rows else 0, per):
            group = todo[i : i + per]
            played, success, clean, steps = _fly_family(config, [seeds[g] for g in group], rows)
            for j, g in enumerate(group):
                sl = slice(j * n_rows, (j + 1) * n_rows)
                for rank, ok in ((0, clean[sl]), (1, success[sl]), (2, np.ones(n_rows, bool))):
                    if ok.any() and (g not in best or rank < best[g][0]):
                        e = j * n_rows + int(np.argmax(ok))
                        best[g] = (rank, played[e, : steps[e]].copy())
                        break
        todo = [g for g in todo if best[g][0] > 0]
    return [best[g][1] for g in range(len(seeds))]


def planner_identity() -> dict[str, Any]:
    """The planner's identity in its result: the files of its code, hashed like an agent's."""
    here = Path(__file__).parent
    files = {
        name: hashlib.sha256((here / name).read_bytes()).hexdigest()
        for name in ("headroom.py", "search.py")
    }
    lines = "\n".join(f"{k} {v}" for k, v in sorted(files.items()))
    return {
        "name": NAME,
        "path": "cdr_bench/evaluate/headroom.py",
        "entry": "headroom.py",
        "files": files,
        "sha256": hashlib.sha256(lines.encode()).hexdigest(),
        "planner": "clairvoyant follow-on search (not an agent: it knows the traffic's future)",
    }


def headroom_result(
    config: ScenarioConfig,
    base_seed: int,
    n_episodes: int,
    out: str | Path,
    batch_size: int = 200,
    progress: bool = False,
) -> dict[str, Any]:
    """Plan every episode of ``config`` (the grid of ``base_seed``), fly the plans through the
    evaluator's runner (the records any entry gets) and write the result ``out`` and its log."""
    out = rf.check_output_path(out)
    if n_episodes < 1 or batch_size < 1:
        raise UserError("headroom: episodes and batch size must be >= 1")
    chash = config.config_hash()
    records: list[dict[str, Any]] = []
    for k in range(-(-n_episodes // batch_size)):
        start, stop = k * batch_size, min((k + 1) * batch_size, n_episodes)
        seeds = [int(s) for s in episode_seeds(base_seed, config.id, chash, start, stop)]
        plans = plan(config, seeds)
        replay = [{"ownship_0": encode_actions(p)} for p in plans]
        got = run_batch(None, config, base_seed, k, batch_size, n_episodes, replay=replay)
        records += got["episodes"]
        if progress:
            print(
                f"cdr-bench headroom: {config.id} {stop}/{n_episodes} episodes planned", flush=True
            )
    result = {
        **result_head(planner_identity(), [(config, n_episodes)], base_seed, batch_size),
        "episodes_file": rf.episodes_path(out).name,
        "scenarios": [scenario_entry(config, base_seed, n_episodes, records)],
        "timing": {
            "note": "not reproducible: excluded from result identity",
            "decision_latency": {config.id: None},
        },
    }
    rf.write_results(out, result, [{"scenario": config.id, **e} for e in records])
    return result
