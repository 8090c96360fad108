"""Controlled airway aircraft (``traffic.controlled``) and airways without spawns
(``traffic.spawn: false``): docs/model.md §2.4, §8.4."""

from __future__ import annotations

import dataclasses
import json
import warnings

import numpy as np
import pytest

import cdr_bench
from cdr_bench.errors import ScenarioError
from cdr_bench.scenarios import list_scenarios, load_scenario
from cdr_bench.scenarios.schema import from_mapping
from cdr_bench.sim import Simulator
from cdr_bench.vector_env import VectorEnv, agent_ids

HOLD = 13


def test_the_new_fields_leave_every_other_scenario_and_its_hash_as_it_was():
    for name in list_scenarios():
        d = load_scenario(name).to_dict()
        if name.startswith("marl/") and not d["learning_intruders"]:  # learning intruders only
            assert d["traffic"]["controlled"] > 0
        else:  # left out at their default: the canonical form, hence the hash, is unchanged
            assert "controlled" not in d["traffic"] and "spawn" not in d["traffic"]
        if not name.endswith("-stream"):
            assert "controlled_spawns" not in d["traffic"]
    cfg = load_scenario("marl/high-all")
    assert cfg.to_dict()["traffic"] == {**load_scenario("high").to_dict()["traffic"]} | {
        "controlled": 48,
        "spawn": False,
    }
    back = from_mapping(json.loads(json.dumps(cfg.to_dict())))  # round trip
    assert back.config_hash() == cfg.config_hash()


def test_more_controlled_aircraft_than_airway_aircraft_is_refused():
    d = load_scenario("low").to_dict()
    d["traffic"]["controlled"] = 25
    with pytest.raises(ScenarioError, match=r"traffic.controlled.*routes x per_route = 24"):
        from_mapping(d)


@pytest.mark.parametrize("name,controlled", [("marl/high-8", 8), ("marl/medium-all", 36)])
def test_controlled_aircraft_take_over_airway_aircraft_heading_for_the_airway_exit(
    name, controlled
):
    cfg = load_scenario(name)
    assert agent_ids(cfg) == ["ownship_0"] + [f"aircraft_{i}" for i in range(controlled)]
    plain = Simulator(
        dataclasses.replace(cfg, traffic=dataclasses.replace(cfg.traffic, controlled=0)), 3
    )
    sim = Simulator(cfg, 3)
    seeds = [5, 6, 7]
    plain.reset(seeds)
    sim.reset(seeds)
    assert sim.M == 1 + controlled
    n_airway = cfg.traffic.routes * cfg.traffic.per_route
    assert (sim.bg_active.sum(axis=1) == n_airway - controlled).all()
    ends = np.array([w.end_km for w in cfg.airways[: cfg.traffic.routes]])
    for e in range(3):
        # The same steady state: every airway aircraft is now either background or controlled.
        taken = plain.bg_active[e] & ~sim.bg_active[e]
        assert taken.sum() == controlled
        want = sorted(map(tuple, np.round(plain.bg_pos_km[e][taken], 9)))
        got = sorted(map(tuple, np.round(sim.ac_pos_km[e, 1:], 9)))
        assert want == got
        for m in range(1, sim.M):
            slot = int(
                np.flatnonzero(
                    taken & (np.abs(plain.bg_pos_km[e] - sim.ac_pos_km[e, m]).sum(axis=1) < 1e-9)
                )[0]
            )
            route = slot // sim.C
            assert sim.ac_level[e, m] == plain.bg_level[e, slot]
            assert np.allclose(sim.ac_dir[e, m], sim.route_unit[route])
            assert np.allclose(sim.ac_goal_km[e, m], ends[route])
            assert sim.ac_speed_kt[e, m] == cfg.ownship.speed_kt


def test_without_spawns_the_sky_empties_and_every_flight_ends():
    env = VectorEnv("marl/low-all", num_envs=2)
    env.reset(seeds=[1, 2])
    assert env.sim.bg_active.sum() == 0
    steps = 0
    while env.flying.any():
        env.step(np.full((2, env.n_agents), HOLD))
        assert env.sim.bg_active.sum() == 0  # no spawn ever
        steps += 1
    assert steps < 100 and (env.outcomes > 0).all()


def test_with_spawns_the_airways_keep_their_density():
    cfg = load_scenario("marl/high-8")
    sim = Simulator(cfg, 2)
    sim.reset([3, 4])
    for _ in range(80):  # every aircraft of the start has left by now
        sim.step(np.full((2, sim.M), HOLD))
    assert (sim.bg_active.sum(axis=1) >= 46).all()


def test_the_agent_list_shrinks_as_aircraft_finish_and_finished_agents_get_nothing():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env = cdr_bench.parallel_env("marl/low-all")
    obs, infos = env.reset(seed=3)
    assert env.agents == env.possible_agents and len(env.possible_agents) == 25
    assert set(obs) == set(infos) == set(env.agents)
    gone: set[str] = set()
    while env.agents:
        live = list(env.agents)
        actions = {a: HOLD for a in live} | {a: 0 for a in gone}  # ignored for finished ones
        obs, rew, term, trunc, infos = env.step(actions)
        assert set(obs) == set(rew) == set(term) == set(trunc) == set(infos) == set(live)
        ended = {a for a in live if term[a] or trunc[a]}
        assert all("outcome" in infos[a] for a in ended)
        assert set(env.agents) == set(live) - ended
        gone |= ended
        assert env.possible_agents[0] == "ownship_0" and len(env.possible_agents) == 25
    assert gone == set(env.possible_agents)
