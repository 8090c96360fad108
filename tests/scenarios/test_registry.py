"""Scenario YAML: loading, inheritance, and every kind of bad input."""

from __future__ import annotations

import textwrap

import pytest

from cdr_bench.scenarios import ScenarioConfig, ScenarioError, list_scenarios, load_scenario
from cdr_bench.scenarios.schema import field_docs


def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


def test_every_shipped_scenario_loads_and_is_frozen():
    for name in list_scenarios():
        cfg = load_scenario(name)
        assert isinstance(cfg, ScenarioConfig) and cfg.id == name
        with pytest.raises(AttributeError):
            cfg.version = 2  # type: ignore[misc]
    assert not any(n.startswith("_") for n in list_scenarios())


def test_densities():
    for name, n in [("low", 24), ("medium", 36), ("high", 48)]:
        assert load_scenario(name).n_route_intruders == n


def test_extends_by_name_and_path_with_override(tmp_path):
    p = write(
        tmp_path,
        "mine.yaml",
        """
        extends: medium
        description: mine
        separation: {los_km: 8.0}
    """,
    )
    cfg = load_scenario(p)
    assert cfg.separation.los_km == 8.0
    assert cfg.separation.nmac_km == 0.2  # inherited within the same mapping
    assert cfg.traffic.per_route == 3
    assert cfg.id == "mine"
    q = write(tmp_path, "child.yaml", "extends: mine.yaml\ntraffic: {per_route: 1}\n")
    cfg2 = load_scenario(str(q))
    assert cfg2.separation.los_km == 8.0 and cfg2.traffic.per_route == 1


def test_config_hash_tracks_content():
    a, b = load_scenario("medium"), load_scenario("medium")
    assert a.config_hash() == b.config_hash()
    assert a.config_hash() != load_scenario("medium", separation={"los_km": 9.0}).config_hash()


@pytest.mark.parametrize(
    "body,field,expect",
    [
        (
            "extends: medium\ntraffic: {per_rout: 3}\n",
            "traffic.per_rout",
            "did you mean 'per_route'",
        ),
        ("extends: medium\nbogus: 1\n", "bogus", "unknown key"),
        (
            "extends: medium\ntraffic: {per_route: three}\n",
            "traffic.per_route",
            "expected an integer",
        ),
        (
            "extends: medium\ntraffic: {per_route: 2.5}\n",
            "traffic.per_route",
            "expected an integer",
        ),
        ("extends: medium\nseparation: {los_km: -1}\n", "separation.los_km", "[0.0, 100.0]"),
        (
            "extends: medium\nseparation: {los_terminates: yes please}\n",
            "separation.los_terminates",
            "true/false",
        ),
        ("extends: medium\ntraffic: {routes: 13}\n", "traffic.routes", "at most 12"),
        ("extends: medium\nownship: {min_speed_kt: 600}\n", "ownship.min_speed_kt", "min_speed_kt"),
        (
            "extends: medium\naircraft: [{position_km: [1, 2], heading_deg: 90, speed_kt: 400}]\n",
            "aircraft[0].level",
            "missing required field",
        ),
        (
            "extends: medium\naircraft: [{position_km: [1], heading_deg: 90, speed_kt: 400,"
            " level: 1}]\n",
            "aircraft[0].position_km",
            "a list of 2 numbers",
        ),
        (
            "extends: medium\naircraft: [{position_km: [1, 2], heading_deg: 90, speed_kt: 4,"
            " level: 3}]\n",
            "aircraft[0].level",
            "[0, 2]",
        ),
        (
            "extends: medium\nlearning_intruders: [{airway: 20}]\n",
            "learning_intruders[0].airway",
            "index below 12",
        ),
        ("extends: medium\nseparation: 10\n", "separation", "expected a mapping"),
        ("extends: medium\ntime: {dt_s: .nan}\n", "time.dt_s", "finite"),
        ("extends: 5\n", "extends", "expected a scenario name or path"),
        ("extends: nowhere\n", "extends", "unknown scenario name"),
    ],
)
def test_bad_yaml_names_file_field_and_expectation(tmp_path, body, field, expect):
    p = write(tmp_path, "bad.yaml", body)
    with pytest.raises(ScenarioError) as ei:
        load_scenario(p)
    msg = str(ei.value)
    assert str(p) in msg and f"'{field}'" in msg and expect in msg


def test_invalid_yaml_syntax_and_non_mapping(tmp_path):
    p = write(tmp_path, "bad.yaml", "traffic: {per_route: [1, 2\n")
    with pytest.raises(ScenarioError, match="invalid YAML"):
        load_scenario(p)
    q = write(tmp_path, "list.yaml", "- 1\n- 2\n")
    with pytest.raises(ScenarioError, match="mapping at the top level"):
        load_scenario(q)


def test_missing_file_and_unknown_name():
    with pytest.raises(ScenarioError, match="no such scenario file"):
        load_scenario("/nonexistent/x.yaml")
    with pytest.raises(ScenarioError, match="unknown scenario name"):
        load_scenario("hihg")


def test_circular_extends(tmp_path):
    write(tmp_path, "a.yaml", "extends: b.yaml\n")
    b = write(tmp_path, "b.yaml", "extends: a.yaml\n")
    with pytest.raises(ScenarioError, match="circular extends"):
        load_scenario(b)


def test_field_docs_cover_every_field_with_units():
    rows = field_docs()
    paths = {r[0] for r in rows}
    assert {"traffic.per_route", "separation.los_km", "reward.nmac", "ownship.start"} <= paths
    assert all(doc for _, _, doc in rows)
