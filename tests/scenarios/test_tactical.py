"""The tactical scenarios are real dilemmas (docs/model.md §8.3), certified by search.

Families (``tactical/head-on``, ``crossing``, ``overtaking``: a geometry drawn per episode): on
the evaluation's episodes (a) holding fails, (b) every searched episode has at least two
manoeuvre families with a successful continuation, (c) the MVP resolver solves between 30 % and
90 %. Fixed encounters (``tactical/*-fixed``): holding fails and at least three first actions
succeed, spanning two of climb / level / descend. The witnesses checked are replayed
independently through fresh single-episode rollouts.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cdr_bench.actions import decode
from cdr_bench.evaluate.search import (
    FAMILIES,
    FAMILY_ACTIONS,
    certify,
    manoeuvre_family,
    rollout,
    search_families,
    successful_first_actions,
)
from cdr_bench.evaluate.seeds import episode_seeds
from cdr_bench.scenarios import ScenarioError, from_mapping, load_scenario
from cdr_bench.scenarios.schema import range_bounds
from cdr_bench.sim import Simulator
from cdr_bench.sim.units import KM_PER_S_PER_KT

FAMILY_SCENARIOS = ("tactical/head-on", "tactical/crossing", "tactical/overtaking")
FIXED = ("tactical/head-on-fixed", "tactical/crossing-fixed", "tactical/overtaking-fixed")
MVP = Path(__file__).resolve().parents[2] / "agents" / "mvp"


@pytest.mark.slow
@pytest.mark.parametrize("name", FAMILY_SCENARIOS)
def test_tactical_family_is_certified(name: str) -> None:
    """The certification of docs/model.md §8.3: holding and MVP on the 1000 episodes of the
    evaluation, every family searched in the first 50 (the recorded run searches 200)."""
    config = load_scenario(name)
    assert config.separation.los_terminates, "a tactical LoS must end the episode as a failure"
    r = certify(config, episodes=1000, search_episodes=50, agent=str(MVP))
    assert r["hold"]["ok"] and r["hold"]["failure_rate"] >= 0.95, r["hold"]
    assert r["families"]["ok"], r["families"]["per_episode"]
    assert 0.30 <= r["agent"]["success_rate"] <= 0.90, r["agent"]
    assert r["ok"]

    # Witnesses: each replays to success in a fresh rollout and belongs to its family.
    seeds = episode_seeds(0, config.id, config.config_hash(), 0, 6)
    for found in search_families(config, seeds, enough=2):
        assert len(found.families) >= 2
        for family, witness in found.witnesses.items():
            assert manoeuvre_family(witness[0]) == family
            assert rollout(config, witness, seed=found.seed) == "success", (family, witness)


@pytest.mark.slow
@pytest.mark.parametrize("name", FIXED)
def test_fixed_tactical_scenario_is_a_dilemma(name: str) -> None:
    config = load_scenario(name)
    assert config.separation.los_terminates, "a tactical LoS must end the episode as a failure"

    assert rollout(config, []) in ("los", "nmac"), "holding must fail"

    witnesses = {a: w for a, w in successful_first_actions(config).items() if w is not None}
    assert len(witnesses) >= 3, f"only {sorted(witnesses)} succeed"
    vertical = {decode(a)[2] for a in witnesses}
    assert len(vertical) >= 2, f"successful first actions use only vertical choice {vertical}"

    for a, w in witnesses.items():
        assert w[0] == a
        assert rollout(config, w) == "success", f"witness of first action {a} does not replay"


def test_search_finds_nothing_when_every_first_action_fails() -> None:
    """A negative control: with a horizon of one step no first action can reach the goal."""
    config = load_scenario("tactical/head-on-fixed", time={"max_steps": 1})
    assert all(w is None for w in successful_first_actions(config).values())
    config = load_scenario("tactical/head-on", time={"max_steps": 1})
    (found,) = search_families(config, [5])
    assert found.witnesses == {} and found.searched == FAMILIES


def test_families_partition_the_manoeuvres() -> None:
    assert manoeuvre_family(13) is None
    every = sorted(a for f in FAMILIES for a in FAMILY_ACTIONS[f])
    assert every == [a for a in range(27) if a != 13]
    assert manoeuvre_family(2) == "climb"  # left/slower/climb: a level change comes first
    assert manoeuvre_family(3) == "descend"  # left/keep/descend
    assert manoeuvre_family(4) == "left" and manoeuvre_family(25) == "right"  # any speed
    assert FAMILY_ACTIONS["climb"][0] == 14 and FAMILY_ACTIONS["speed"] == (10, 16)


def _geometry(name: str, seeds: list[int]) -> np.ndarray:
    sim = Simulator(load_scenario(name), len(seeds))
    sim.reset(seeds)
    return np.concatenate(
        [sim.pos_km.reshape(len(seeds), -1), sim.vel_km_s.reshape(len(seeds), -1), sim.level],
        axis=1,
    )


@pytest.mark.parametrize("name", FAMILY_SCENARIOS)
def test_a_seed_gives_its_geometry(name: str) -> None:
    a = _geometry(name, [1, 2, 3])
    b = _geometry(name, [3, 2, 1])
    assert np.array_equal(a, b[::-1]), "the same seed must draw the same geometry"
    assert not np.array_equal(a[0], a[1]) and not np.array_equal(a[1], a[2])
    # The ownship is the same in every episode; the others are not.
    sim = Simulator(load_scenario(name), 40)
    sim.reset(list(range(40)))
    assert np.ptp(sim.ac_pos_km[:, 0], axis=0).max() == 0.0
    assert (np.ptp(sim.bg_pos_km, axis=0) > 1.0).all()


@pytest.mark.parametrize("name", FAMILY_SCENARIOS)
def test_a_family_never_starts_an_aircraft_within_the_start_clearance(name: str) -> None:
    """docs/model.md §8.3: the ranges keep every same-level start at least 20 km away, so no
    episode is drawn again (which would bend the documented distributions)."""
    config = load_scenario(name)
    start = config.ownship.start
    assert start is not None
    v0 = start.speed_kt * KM_PER_S_PER_KT
    for ac in config.aircraft:
        enc = ac.encounter
        assert enc is not None
        levels = enc.level if isinstance(enc.level, tuple) else (enc.level,)
        if start.level not in levels:
            continue
        axes = [
            np.linspace(*range_bounds(x), 31)
            for x in (enc.time_to_cpa_s, enc.angle_deg, enc.miss_km, enc.speed_kt)
        ]
        t, angle, miss, speed = np.meshgrid(*axes, indexing="ij")
        a, v = np.radians(angle), speed * KM_PER_S_PER_KT
        w = np.hypot(v * np.sin(a), v * np.cos(a) - v0)  # relative speed, km/s
        assert np.sqrt(miss * miss + (w * t) ** 2).min() >= config.ownship.start_clearance_km


@pytest.mark.parametrize("name", FAMILY_SCENARIOS + FIXED)
def test_a_tactical_scenario_round_trips_through_its_dict(name: str) -> None:
    config = load_scenario(name)
    assert from_mapping(config.to_dict()) == config
    assert load_scenario(config, time={"max_steps": 5}).aircraft == config.aircraft


def test_fixed_encounters_do_not_depend_on_the_seed() -> None:
    a = _geometry("tactical/crossing-fixed", [1, 2])
    assert np.array_equal(a[0], a[1])


HEAD_ON = "extends: tactical/head-on\n"


@pytest.mark.parametrize(
    ("text", "field", "expected"),
    [
        (
            "aircraft: [{encounter: {time_to_cpa_s: [200, 100], angle_deg: 180, miss_km: 0,"
            " speed_kt: 430, level: 1}}]\n",
            "aircraft[0].encounter.time_to_cpa_s",
            "lo <= hi",
        ),
        (
            "aircraft: [{encounter: {time_to_cpa_s: 100, angle_deg: [170, 400], miss_km: 0,"
            " speed_kt: 430, level: 1}}]\n",
            "aircraft[0].encounter.angle_deg[1]",
            "[-360.0, 360.0]",
        ),
        (
            "aircraft: [{encounter: {time_to_cpa_s: 100, angle_deg: 180, miss_km: [1, 2, 3],"
            " speed_kt: 430, level: 1}}]\n",
            "aircraft[0].encounter.miss_km",
            "a list of 2 numbers",
        ),
        (
            "aircraft: [{encounter: {time_to_cpa_s: 100, angle_deg: 180, miss_km: 0,"
            " speed_kt: 430, level: [0, 0]}}]\n",
            "aircraft[0].encounter.level",
            "distinct levels",
        ),
        (
            "aircraft: [{encounter: {time_to_cpa_s: 100, angle_deg: 180, miss_km: 0,"
            " speed_kt: 430, level: [0, 3]}}]\n",
            "aircraft[0].encounter.level[1]",
            "[0, 2]",
        ),
        (
            "aircraft: [{encounter: {time_to_cpa_s: 100, angle_deg: 180, miss_km: 0,"
            " speed_kt: 430, level: []}}]\n",
            "aircraft[0].encounter.level",
            "at least 1",
        ),
        (
            "aircraft: [{encounter: {time_to_cpa_s: 100, angle_deg: 180, miss_km: 0,"
            " speed_kt: 430}}]\n",
            "aircraft[0].encounter.level",
            "missing required field",
        ),
        (
            "aircraft: [{encounter: {time_to_cpa_s: 100, angle_deg: 180, miss_km: 0,"
            " speed_kt: 430, level: 1, side: left}}]\n",
            "aircraft[0].encounter.side",
            "unknown key",
        ),
        (
            "aircraft: [{encounter: {time_to_cpa_s: 100, angle_deg: 180, miss_km: 0,"
            " speed_kt: 430, level: 1}, level: 1}]\n",
            "aircraft[0].level",
            "either 'encounter' or 'level'",
        ),
        (
            "aircraft: [{position_km: [1, 2], heading_deg: 90, level: 1}]\n",
            "aircraft[0].speed_kt",
            "missing required field (a number)",
        ),
        (
            "aircraft: [{encounter: {time_to_cpa_s: 1200, angle_deg: 180, miss_km: 0,"
            " speed_kt: 430, level: 1}}]\n",
            "aircraft[0].encounter",
            "outside the sector",
        ),
        (
            "ownship: {start: null, goal_km: null}\n"
            "aircraft: [{encounter: {time_to_cpa_s: 100, angle_deg: 180, miss_km: 0,"
            " speed_kt: 430, level: 1}}]\n",
            "aircraft[0].encounter",
            "explicit ownship.start",
        ),
    ],
)
def test_encounter_schema_errors_name_the_field(
    tmp_path: Path, text: str, field: str, expected: str
) -> None:
    p = tmp_path / "bad.yaml"
    p.write_text(HEAD_ON + text)
    with pytest.raises(ScenarioError) as info:
        load_scenario(p)
    problems = dict(info.value.problems)
    assert field in problems, info.value.problems
    assert expected in problems[field], problems[field]
    assert str(p.name) in str(info.value)


def test_every_problem_of_an_encounter_is_reported_at_once(tmp_path: Path) -> None:
    p = tmp_path / "bad.yaml"
    p.write_text(
        HEAD_ON + "aircraft: [{encounter: {time_to_cpa_s: [9, 1], angle_deg: [10, 0],"
        " miss_km: 0, speed_kt: [500, 400], level: [1, 1]}}]\n"
    )
    with pytest.raises(ScenarioError) as info:
        load_scenario(p)
    fields = {f for f, _ in info.value.problems}
    assert fields == {
        f"aircraft[0].encounter.{k}" for k in ("time_to_cpa_s", "angle_deg", "speed_kt", "level")
    }
