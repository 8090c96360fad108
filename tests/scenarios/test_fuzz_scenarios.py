"""Fuzzing the scenario loader: random YAML-ish text, random bytes and random mutations of shipped
scenarios. The only exception allowed is ScenarioError (a UserError), and a scenario that
validates builds a simulator that resets and steps. Bounded to a few seconds."""

from __future__ import annotations

import atexit
import copy
import dataclasses
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cdr_bench.actions import HOLD
from cdr_bench.errors import ScenarioError
from cdr_bench.scenarios import from_mapping, load_scenario
from cdr_bench.scenarios.loader import registry_root
from cdr_bench.sim import Simulator

FUZZ = settings(
    max_examples=100,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)

_DIR = Path(tempfile.mkdtemp(prefix="cdr-bench-fuzz-"))
atexit.register(shutil.rmtree, _DIR, ignore_errors=True)

TOKENS = [
    "extends: ", "medium", "tactical/head-on", "../..", "_base", "\n", "  ", "- ", "{", "}",
    "[", "]", ", ", ": ", " ", "&a ", "*a", "<<: ", "!!int ", "!!binary ", "!!python/object ",
    "!!set ", "'", '"', "#", "---\n", "...\n", "? ", "|\n", ">\n", "1e5", "1.0e+308", ".inf",
    ".nan", "-0", "9" * 70, "traffic", "per_route", "routes", "sector", "size_km", "aircraft",
    "position_km", "ownship", "goal_km", "start", "id", "description", "airways", "start_km",
    "learning_intruders", "airway", "\t", "\x00", "\xe9", "\ufeff", "%YAML 1.1\n", "2024-13-45",
    "~", "null", "true", "0x1F", "0o17", "1_000", "400", "200", "0", "1", "-1", "3.5", "\\",
    "\r\n", "\x85", "\u2028",
]  # fmt: skip

yaml_ish = st.lists(st.sampled_from(TOKENS), max_size=40).map("".join)

REGISTRY = frozenset(
    f.relative_to(registry_root()).with_suffix("").as_posix()
    for f in registry_root().rglob("*.yaml")
)
"""Every name with a file in the registry, bases (``_base``) included."""
BASES = {
    name: load_scenario(name).to_dict()
    for name in ("tactical/head-on", "marl/low-2", "curriculum/stage-03")
}

leaf = (
    st.none()
    | st.booleans()
    | st.integers(-3, 70)
    | st.integers()
    | st.integers(-(10**80), 10**80)
    | st.floats()
    | st.sampled_from([0.0, 0.1, 1e308, -1e308, 200.0, 399.9, 400.0, 1e4, 1e5, 5000.0])
    | st.text(max_size=12)
    | st.sampled_from(["medium", "high", "a/../b", "x" * 600, "1e5", "\x00"])
)
value = st.recursive(
    leaf,
    lambda inner: (
        st.lists(inner, max_size=4)
        | st.dictionaries(
            st.sampled_from(["start_km", "end_km", "position_km", "level", "x"])
            | st.text(max_size=6),
            inner,
            max_size=4,
        )
    ),
    max_leaves=12,
)


class _NoAliases(yaml.SafeDumper):
    """Writes a repeated object again instead of an alias (which scenario files refuse)."""

    def ignore_aliases(self, data: Any) -> bool:
        return True


def _paths(node: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    out = [prefix]
    if isinstance(node, dict):
        for k, v in node.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out += _paths(v, (*prefix, i))
    return out


def _mutate(data: st.DataObject, doc: dict[str, Any]) -> dict[str, Any]:
    """1 to 3 random edits: replace a value, delete an entry, add a key, grow a list."""
    for _ in range(data.draw(st.integers(1, 3))):
        path = data.draw(st.sampled_from(_paths(doc)[1:]))
        parent = doc
        for part in path[:-1]:
            parent = parent[part]
        op = data.draw(st.sampled_from(["set", "set", "set", "delete", "add", "repeat"]))
        if op == "set":
            parent[path[-1]] = data.draw(value)
        elif op == "delete":
            del parent[path[-1]]
        elif op == "add" and isinstance(parent, dict):
            parent[data.draw(st.text(max_size=8))] = data.draw(value)
        elif op == "repeat" and isinstance(parent, list):
            parent.extend([parent[path[-1]]] * data.draw(st.integers(1, 300)))
        if not doc:
            break
    return doc


def _load_file(content: str | bytes) -> Any:
    p = _DIR / "fuzz.yaml"
    if isinstance(content, bytes):
        p.write_bytes(content)
    else:
        p.write_text(content, encoding="utf-8", errors="surrogatepass")
    try:
        return load_scenario(p)
    except ScenarioError as e:
        assert str(p) in str(e) and len(str(e)) < 5000
        return None


def _run(cfg: Any) -> None:
    """A validated scenario builds, resets and steps."""
    sim = Simulator(cfg, 1)
    try:
        sim.reset([7])
    except ScenarioError as e:  # a valid but crowded scenario: no clear start (not a geometry bug)
        assert "no start with this clearance" in str(e)
        return
    sim.step(np.full((1, sim.M), HOLD))
    assert np.isfinite(sim.pos_km).all()


@FUZZ
@given(yaml_ish)
def test_yaml_ish_text(text):
    _load_file(text)


@FUZZ
@given(st.binary(max_size=300))
def test_random_bytes(raw):
    _load_file(raw)


@pytest.mark.slow
@FUZZ
@given(st.data(), st.sampled_from(sorted(BASES)))
def test_mutated_shipped_scenarios(data, base):
    doc = _mutate(data, copy.deepcopy(BASES[base]))  # plain YAML data: dicts, lists, scalars
    # a file may carry a registry scenario's id only with its content (the loader's rule for
    # files; a mapping has no file): ids of the whole registry are renamed, not only the bases'
    if isinstance(doc.get("id"), str) and doc["id"] in REGISTRY:
        doc["id"] = "fuzz/mutant"
    try:
        cfg = from_mapping(doc, "<fuzz>")
    except ScenarioError as e:
        assert str(e).startswith("<fuzz>: ") and len(str(e)) < 5000
        cfg = None
    try:
        text = yaml.dump(doc, Dumper=_NoAliases)
    except yaml.YAMLError:
        return
    from_file = _load_file(text)
    assert (cfg is None) == (from_file is None)
    if cfg is not None:
        if "id" not in doc:  # a file without an id takes its file name's; a mapping has none
            assert (cfg.id, from_file.id) == ("", "fuzz")
            from_file = dataclasses.replace(from_file, id=cfg.id)
        assert from_file.config_hash() == cfg.config_hash()
        _run(cfg)


@pytest.mark.parametrize("base", sorted(BASES))
def test_unmutated_bases_run(base):
    _run(from_mapping(BASES[base]))
