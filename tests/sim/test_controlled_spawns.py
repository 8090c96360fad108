"""Controlled aircraft entering during the episode (``traffic.controlled_spawns``, the
``marl/*-stream`` scenarios): the agent list grows as airways spawn them (docs/model.md §8.4)."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import numpy as np
import pytest

import cdr_bench
from cdr_bench.errors import ScenarioError
from cdr_bench.evaluate.runner import ReplayMismatch, close_all, load_for, run_batch
from cdr_bench.scenarios import load_scenario
from cdr_bench.scenarios.schema import from_mapping
from cdr_bench.vector_env import VectorEnv, agent_ids

HOLD = 13
ROOT = Path(__file__).resolve().parents[2]


def _held(name: str, seeds: list[int], **traffic: object) -> tuple[VectorEnv, list[np.ndarray]]:
    """Every aircraft holding to the end; the flying mask after each step."""
    cfg = load_scenario(name)
    if traffic:
        cfg = dataclasses.replace(cfg, traffic=dataclasses.replace(cfg.traffic, **traffic))
    env = VectorEnv(cfg, num_envs=len(seeds))
    env.reset(seeds=seeds)
    seen = [env.flying]
    while env.flying.any():
        env.step(np.full((len(seeds), env.n_agents), HOLD))
        seen.append(env.flying)
    return env, seen


def test_the_stream_scenarios_declare_their_agents():
    for density, n in (("low", 24), ("medium", 36), ("high", 48)):
        cfg = load_scenario(f"marl/{density}-stream")
        assert (cfg.traffic.controlled, cfg.traffic.controlled_spawns) == (n, n)
        assert not cfg.traffic.spawn
        assert agent_ids(cfg) == ["ownship_0"] + [f"aircraft_{i}" for i in range(2 * n)]


def test_spawned_aircraft_enter_in_order_on_their_airway_and_every_one_flies():
    cfg = load_scenario("marl/high-stream")
    env = VectorEnv(cfg, num_envs=3)
    env.reset(seeds=[11, 12, 13])
    first = 1 + cfg.traffic.controlled
    assert env.flying[:, :first].all() and not env.flying[:, first:].any()
    entered = np.full((3, env.n_agents), -1)
    entered[:, :first] = 0
    routes = np.array([[w.start_km, w.end_km] for w in cfg.airways[: cfg.traffic.routes]])
    while env.flying.any():
        before = env.flying
        env.step(np.full((3, env.n_agents), HOLD))
        new = env.flying & ~before & (entered < 0)
        for e, m in zip(*np.nonzero(new), strict=True):
            entered[e, m] = env.episode_steps[e]
            goal = env.goals_km[e, m]
            r = int(np.argmin(np.abs(routes[:, 1] - goal).sum(axis=1)))
            assert np.allclose(goal, routes[r, 1])  # its goal: its airway's end
            start = routes[r, 0]
            along = (routes[r, 1] - start) / np.linalg.norm(routes[r, 1] - start)
            off = env.positions_km[e, m] - start
            assert 0.0 <= off @ along < 7.0  # near the airway's start, on it
            assert abs(off[0] * along[1] - off[1] * along[0]) < 1e-9
            assert np.allclose(env.heading_vectors[e, m], along)
            assert env.speeds_kt[e, m] == cfg.ownship.speed_kt
        # no background aircraft ever (spawn: false): every aircraft in the sky is an agent
        assert not env.aircraft_in_sky[:, : env.n_background].any()
    assert (entered >= 0).all()  # every one of the 48 spawns entered
    spawned = entered[:, first:]
    assert (np.diff(spawned, axis=1) >= 0).all()  # in agent order
    assert (spawned > 0).all()
    assert (env.outcomes > 0).all()


def test_later_spawns_are_background_when_the_airways_keep_spawning():
    env, seen = _held("marl/high-8", [3, 4], controlled_spawns=10)
    assert env.n_agents == 1 + 8 + 10
    assert (env.outcomes > 0).all()  # the ten entered and finished
    assert max(int(f[:, 9:].sum()) for f in seen) > 0
    # the airways went on spawning background traffic after them (not with spawn: false)
    off, _ = _held("marl/high-8", [3, 4], controlled_spawns=10, spawn=False)
    kept = env.aircraft_in_sky[:, : env.n_background].sum(axis=1)
    emptied = off.aircraft_in_sky[:, : off.n_background].sum(axis=1)
    assert (kept >= 40).all() and (emptied < kept).all()


def test_the_parallel_api_with_agents_entering():
    from pettingzoo.test import parallel_api_test

    env = cdr_bench.parallel_env("marl/low-stream")
    with warnings.catch_warnings():  # "agent was given ... dead last turn" etc. are errors here
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", message=".*probably should be.*")
        warnings.filterwarnings("ignore", message="Observation is not a NumPy array")
        parallel_api_test(env, num_cycles=400)
    obs, infos = env.reset(seed=5)
    assert env.agents == [
        a for a in env.possible_agents if int(a.split("_")[1]) < 24 or a[0] == "o"
    ]
    assert set(obs) == set(env.agents)
    joined = []
    while env.agents:
        before = list(env.agents)
        obs, rew, term, trunc, infos = env.step({a: HOLD for a in env.agents})
        new = [a for a in env.agents if a not in before]
        for a in new:  # a new agent: its first observation, no reward, not done
            assert obs[a]["action_mask"].sum() > 0
            assert rew[a] == 0.0 and term[a] is False and trunc[a] is False
            assert infos[a]["entered"] is True and infos[a]["step"] == infos[before[0]]["step"]
        joined += new
    assert joined == [f"aircraft_{i}" for i in range(24, 48)]


def test_flat_infos_give_every_possible_agent_an_observation_at_reset():
    """TorchRL's wrapper reads an observation and an info of every agent at reset."""
    env = cdr_bench.parallel_env("marl/low-stream", flat_infos=True)
    obs, infos = env.reset(seed=1)
    assert set(obs) == set(infos) == set(env.possible_agents)
    assert len(env.agents) == 25


def test_records_of_spawned_flights_start_where_they_entered_and_replay():
    cfg = load_scenario("marl/low-stream")
    agent = load_for(str(ROOT / "agents" / "direct" / "agent.py"), cfg)
    try:
        got = run_batch(agent, cfg, 7, 0, 3, 3)
    finally:
        close_all()
    for ep in got["episodes"]:
        ids = [a["id"] for a in ep["aircraft"]]
        assert ids == agent_ids(cfg)[: len(ids)] and len(ids) == 49
        for a in ep["aircraft"][25:]:
            assert a["entered_s"] > 0 and a["steps"] > 0
            if a["outcome"] == "success" and not a["manoeuvres"]:
                # held on its airway: it flew its direct route, from where it entered
                assert abs(a["path_km"] - a["direct_km"]) < 7.0
        assert all("entered_s" not in a for a in ep["aircraft"][:25])
    replay = [{a["id"]: a["actions"] for a in ep["aircraft"]} for ep in got["episodes"]]
    again = run_batch(None, cfg, 7, 0, 3, 3, replay=replay)
    assert again["episodes"] == got["episodes"]
    # a flight left out of the record cannot be replayed
    del replay[0]["aircraft_30"]
    with pytest.raises(ReplayMismatch):
        run_batch(None, cfg, 7, 0, 3, 3, replay=replay)


def test_controlled_spawns_without_airway_traffic_are_refused():
    d = load_scenario("tactical/head-on").to_dict()
    d["traffic"]["controlled_spawns"] = 2
    with pytest.raises(ScenarioError, match=r"traffic.controlled_spawns.*traffic.routes: 0"):
        from_mapping(d)
