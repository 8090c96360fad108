"""Hostile and malformed scenario input: every case ends in one ScenarioError naming the file and
the field, never a traceback, a hang or unbounded memory (the CLI: exit code 2, no traceback)."""

from __future__ import annotations

from pathlib import Path

import pytest

import cdr_bench
from cdr_bench.errors import ScenarioError, UserError
from cdr_bench.scenarios import list_scenarios, load_scenario, registry_root
from cdr_bench.scenarios.loader import MAX_EXTENDS, MAX_FILE_BYTES

HEAD_ON = "extends: tactical/head-on\n"  # explicit start (200, 200) level 1, goal (330, 200)
AC = "{position_km: [%s, %s], heading_deg: 0, speed_kt: 400, level: %d}"


def _laughs() -> str:
    text = 'a: &a ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]\n'
    for prev, name in zip("abcdefgh", "bcdefghi", strict=True):
        text += f"{name}: &{name} [" + ", ".join([f"*{prev}"] * 9) + "]\n"
    return text + "description: *i\n"


def _aircraft(n: int) -> str:
    return "extends: medium\naircraft:\n" + "".join(f"  - {AC % (100, 100, 1)}\n" for _ in range(n))


# (file name, content, field named in the message ("" for the file itself), expected text)
CASES: list[tuple[str, str | bytes, str, str]] = [
    # -- encoding, size and YAML features
    ("binary.yaml", bytes(range(256)) * 4, "", "binary file"),
    ("latin1.yaml", "extends: medium\ndescription: caf\xe9\n".encode("latin-1"), "", "UTF-8"),
    ("int400.yaml", "extends: medium\ntime: {dt_s: " + "9" * 400 + "}\n", "", "400 digits"),
    ("int5000.yaml", "extends: medium\nversion: " + "9" * 5000 + "\n", "", "5000 digits"),
    ("nested.yaml", "extends: medium\ndescription: " + "[" * 20_000 + "\n", "", "nested more"),
    ("laughs.yaml", _laughs(), "", "anchors (&name) are not allowed"),
    ("alias.yaml", "extends: medium\ndescription: *x\n", "", "aliases (*name) are not allowed"),
    ("merge.yaml", "extends: medium\nsector: {<<: {size_km: 300}}\n", "", "merge keys"),
    (
        "duplicate.yaml",
        "extends: medium\ntraffic: {per_route: 2}\ntraffic: {per_route: 4}\n",
        "",
        "line 3, column 1: duplicate key 'traffic' (first given on line 2)",
    ),
    ("dup_inner.yaml", "extends: medium\ntime: {dt_s: 30, dt_s: 31}\n", "", "duplicate key 'dt_s'"),
    ("date.yaml", "extends: medium\ndescription: 2024-13-45\n", "", "cannot read this value"),
    ("two_docs.yaml", "extends: medium\n---\nextends: low\n", "", "invalid YAML"),
    ("unhashable.yaml", "extends: medium\n? [a, b]\n: 1\n", "", "unhashable"),
    ("python_tag.yaml", "extends: !!python/object:os.system {}\n", "", "tags (!!name)"),
    ("int_tag.yaml", "extends: medium\nversion: !!int ''\n", "", "tags (!!name)"),
    ("syntax.yaml", "traffic: {per_route: [1, 2\n", "", "invalid YAML at line"),
    ("list.yaml", "- 1\n- 2\n", "", "mapping at the top level"),
    ("huge.yaml", "# " + "x" * MAX_FILE_BYTES + "\n", "", "larger than 1024 KiB"),
    # -- sizes, numbers and texts
    ("many_aircraft.yaml", _aircraft(300), "aircraft", "at most 256 items, got 300"),
    (
        "many_airways.yaml",
        "extends: medium\nairways: ["
        + ", ".join(["{start_km: [0, 60], end_km: [400, 340]}"] * 65)
        + "]\n",
        "airways",
        "at most 64 items",
    ),
    (
        "many_learners.yaml",
        "extends: medium\nlearning_intruders: [" + ", ".join(["{airway: 1}"] * 17) + "]\n",
        "learning_intruders",
        "at most 16 items",
    ),
    (
        "coord_1e308.yaml",
        HEAD_ON + f"aircraft: [{AC % ('1.0e+308', '100.0', 1)}]\n",
        "aircraft[0].position_km[0]",
        "[-10000.0, 10000.0], got 1e+308",
    ),
    (
        "coord_inf.yaml",
        HEAD_ON + "ownship: {goal_km: [.inf, 200]}\n",
        "ownship.goal_km[0]",
        "finite",
    ),
    (
        "goal_1e5.yaml",
        HEAD_ON + "ownship: {goal_km: [100000, 200]}\n",
        "ownship.goal_km[0]",
        "[-10000.0, 10000.0]",
    ),
    ("big_int.yaml", "extends: medium\nversion: " + "9" * 60 + "\n", "version", "[1, 10000]"),
    (
        "long_text.yaml",
        "extends: medium\ntraffic: {per_route: " + "x" * 5000 + "}\n",
        "traffic.per_route",
        "expected an integer, got 'xxx",
    ),
    ("long_key.yaml", "extends: medium\n" + "k" * 1000 + ": 1\n", "'kkkk", "unknown key"),
    ("exponent.yaml", "extends: medium\ntime: {dt_s: 1e1}\n", "time.dt_s", "form 1.0e+5"),
    ("description_nl.yaml", 'extends: medium\ndescription: "a\\nb"\n', "description", "U+000A"),
    (
        "description_long.yaml",
        "extends: medium\ndescription: " + "d" * 600 + "\n",
        "description",
        "at most 500 characters",
    ),
    # -- geometry
    (
        "goal_outside.yaml",
        HEAD_ON + "ownship: {goal_km: [500, 200]}\n",
        "ownship.goal_km",
        "inside the sector [0, 400]",
    ),
    (
        "start_outside.yaml",
        HEAD_ON
        + "ownship: {start: {position_km: [-5, 200], heading_deg: 90, speed_kt: 430, level: 1}}\n",
        "ownship.start.position_km",
        "inside the sector",
    ),
    (
        "aircraft_outside.yaml",
        HEAD_ON + f"aircraft: [{AC % (401, 200, 1)}]\n",
        "aircraft[0].position_km",
        "inside the sector",
    ),
    (
        "nmac_at_start.yaml",
        HEAD_ON + f"aircraft: [{AC % (200.1, 200, 1)}]\n",
        "aircraft[0].position_km",
        "separation.nmac_km (0.2 km) from the ownship's start",
    ),
    (
        "start_speed.yaml",
        HEAD_ON
        + "ownship: {start: {position_km: [200, 200], heading_deg: 90, speed_kt: 50, level: 1}}\n",
        "ownship.start.speed_kt",
        "[330.0, 530.0]",
    ),
    (
        "clearance.yaml",
        "extends: medium\nsector: {size_km: 50}\nownship: {goal_margin_km: 1, start_clearance_km:"
        " 100}\nairways: [{start_km: [0, 25], end_km: [50, 25]}]\ntraffic: {routes: 1}\n",
        "ownship.start_clearance_km",
        "less than half of sector.size_km (25 km)",
    ),
    (
        "spawn_clearance.yaml",
        "extends: curriculum/stage-01\nsector: {size_km: 300}\n"
        "traffic: {spawn_clearance_km: 150}\n",
        "traffic.spawn_clearance_km",
        "less than half",
    ),
    (
        "goal_radius.yaml",
        "extends: medium\nsector: {size_km: 100}\n"
        "ownship: {goal_radius_km: 60, goal_margin_km: 1}\n"
        "airways: [{start_km: [0, 50], end_km: [100, 50]}]\ntraffic: {routes: 1}\n",
        "ownship.goal_radius_km",
        "less than half",
    ),
    (
        "airway_outside.yaml",
        "extends: medium\nairways: [{start_km: [1000, 1000], end_km: [2000, 1000]}]\n"
        "traffic: {routes: 1}\n",
        "airways[0]",
        "crossing the sector",
    ),
    (
        "airway_touching.yaml",
        "extends: medium\nairways: [{start_km: [400, 0], end_km: [900, 0]}]\n"
        "traffic: {routes: 1}\n",
        "airways[0]",
        "crossing the sector",
    ),
    (
        "goal_alone.yaml",
        "extends: medium\nownship: {goal_km: [100, 100]}\n",
        "ownship.goal_km",
        "start",
    ),
    # -- ids and names
    ("id_nul.yaml", 'extends: medium\nid: "a\\0b"\n', "id", "'a\\x00b'"),
    ("id_dotdot.yaml", "extends: medium\nid: a/../../b\n", "id", "none starting with '.'"),
    ("id_abs.yaml", "extends: medium\nid: /etc/passwd\n", "id", "'/'-separated parts"),
    ("id_long.yaml", "extends: medium\nid: " + "i" * 200 + "\n", "id", "at most 128 characters"),
    ("id_shadow.yaml", "extends: medium\nid: high\n", "id", "registry scenario with different"),
    ("high.yaml", "extends: medium\n", "id", "'high' is the id of a registry scenario"),
    ("my file.yaml", "extends: medium\n", "id", "set 'id:'"),
    # -- extends
    ("ext_dotdot.yaml", "extends: ../..\n", "extends", "not a registry scenario name"),
    ("ext_abs_name.yaml", "extends: /etc/hostname\n", "extends", "not a registry scenario name"),
    ("ext_abs_path.yaml", "extends: /etc/x.yaml\n", "extends", "a relative path"),
    ("ext_leaves.yaml", "extends: ../../../../x.yaml\n", "extends", "leaves the registry"),
    ("ext_typo.yaml", "extends: hihg\n", "extends", "did you mean 'high'?"),
    ("ext_base_typo.yaml", "extends: _bsae\n", "extends", "did you mean '_base'?"),
    ("ext_list.yaml", "extends: [medium]\n", "extends", "expected a scenario name or path"),
    # -- several problems at once
    (
        "several.yaml",
        "extends: medium\ntraffic: {per_route: 0, routes: 100}\n"
        "separation: {los_km: x}\nbogus: 1\n",
        "",
        "4 errors:",
    ),
]


def _write(directory: Path, name: str, content: str | bytes) -> Path:
    p = directory / name
    if isinstance(content, bytes):
        p.write_bytes(content)
    else:
        p.write_text(content, encoding="utf-8")
    return p


def _assert_short(message: str) -> None:
    """A message never quotes an expanded value: short lines, bounded length."""
    assert len(message) < 3000, len(message)
    assert all(len(line) < 400 for line in message.splitlines()), message


@pytest.mark.parametrize(("name", "content", "field", "expect"), CASES, ids=[c[0] for c in CASES])
def test_hostile_file_gives_one_scenario_error(tmp_path, name, content, field, expect):
    p = _write(tmp_path, name, content)
    with pytest.raises(ScenarioError) as ei:
        load_scenario(p)
    msg = str(ei.value)
    assert str(p) in msg.splitlines()[0], msg
    if field:
        assert f"field '{field}" in msg, msg
    assert expect in msg, msg
    _assert_short(msg)


def test_several_problems_are_reported_together(tmp_path):
    p = _write(tmp_path, "several.yaml", dict((c[0], c[1]) for c in CASES)["several.yaml"])
    with pytest.raises(ScenarioError) as ei:
        load_scenario(p)
    fields = [path for path, _ in ei.value.problems]
    assert fields == ["bogus", "separation.los_km", "traffic.routes", "traffic.per_route"]
    lines = str(ei.value).splitlines()
    assert lines[0] == f"{p}: 4 errors:" and len(lines) == 5


def test_a_file_with_the_content_of_a_registry_scenario_may_carry_its_id(tmp_path):
    p = _write(tmp_path, "high.yaml", "extends: high\n")
    assert load_scenario(p).config_hash() == load_scenario("high").config_hash()
    q = _write(
        tmp_path, "mine.yaml", "extends: medium\nid: my/medium-8km\nseparation: {los_km: 8}\n"
    )
    assert load_scenario(q).id == "my/medium-8km"


def test_extends_by_relative_path_stays_beside_the_file_or_in_the_registry(tmp_path):
    (tmp_path / "sub").mkdir()
    _write(tmp_path, "sub/parent.yaml", "extends: low\n")
    child = _write(tmp_path, "child.yaml", "extends: sub/parent.yaml\n")
    assert load_scenario(child).traffic.per_route == 2
    up = _write(tmp_path, "sub/up.yaml", "extends: ../child.yaml\n")
    with pytest.raises(ScenarioError, match="leaves the registry"):
        load_scenario(up)
    # The shipped tactical scenarios extend "../_base.yaml": inside the registry.
    assert "tactical/head-on" in list_scenarios()
    assert (registry_root() / "tactical" / "head-on.yaml").read_text().count("../_base.yaml")


def test_extends_chain_is_bounded(tmp_path):
    _write(tmp_path, "s0.yaml", "extends: medium\n")
    for i in range(1, MAX_EXTENDS + 2):
        _write(tmp_path, f"s{i}.yaml", f"extends: s{i - 1}.yaml\n")
    # s(n) -> ... -> s0 -> medium -> _base: n + 3 files
    assert load_scenario(tmp_path / f"s{MAX_EXTENDS - 3}.yaml").traffic.per_route == 3
    top = tmp_path / f"s{MAX_EXTENDS - 2}.yaml"
    with pytest.raises(ScenarioError, match=f"more than {MAX_EXTENDS} levels") as ei:
        load_scenario(top)
    assert str(ei.value).startswith(f"{top}: field 'extends'")


def test_not_a_regular_file(tmp_path):
    (tmp_path / "dir.yaml").mkdir()
    with pytest.raises(ScenarioError, match="not a regular file"):
        load_scenario(tmp_path / "dir.yaml")


REGISTRY_NAMES = [
    ("../../..", "not a registry scenario name"),
    ("/etc/passwd", "a scenario file's path ends in .yaml"),
    ("a/../../b", "not a registry scenario name"),
    ("tactical//head-on", "not a registry scenario name"),
    ("", "not a registry scenario name"),
    ("hihg", "did you mean 'high'?"),
    ("/nonexistent/x.yaml", "no such scenario file"),
]


@pytest.mark.parametrize(("name", "expect"), REGISTRY_NAMES)
def test_registry_names_never_leave_the_registry(name, expect):
    with pytest.raises(ScenarioError) as ei:
        load_scenario(name)
    assert expect in str(ei.value)


@pytest.mark.parametrize("bad", [None, 5, 2.5, ["medium"], b"medium", {"id": "x"}])
def test_parallel_env_with_a_wrong_scenario_argument(bad):
    with pytest.raises(UserError, match="expected a scenario: a registry name"):
        cdr_bench.parallel_env(scenario=bad)


def test_cli_validate_every_hostile_file_in_one_run(tmp_path, capsys):
    from cdr_bench.cli import main

    paths = [str(_write(tmp_path, name, content)) for name, content, _, _ in CASES]
    names = [n for n, _ in REGISTRY_NAMES]
    assert main(["scenarios", "validate", *paths, *names]) == 2
    out, err = capsys.readouterr()
    assert out == "" and "Traceback" not in err
    errors = [line for line in err.splitlines() if line.startswith("error ")]
    assert len(errors) == len(paths) + len(names), err
    for p in paths:
        assert any(p in line for line in errors), p
    assert main(["scenarios", "show", "../../.."]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert err.count("\n") == 1 and "not a registry scenario name" in err
