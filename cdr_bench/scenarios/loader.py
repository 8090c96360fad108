"""Scenario registry: YAML files under ``scenarios/``, ``extends:`` inheritance, by name or path.

A scenario is named by its path relative to the registry root without ``.yaml``
(``medium``, ``curriculum/stage-03``, ``tactical/head-on``) or given as a path to a YAML file.
``extends: NAME`` (a registry name, or a path relative to the extending file) loads the parent
first; mappings merge key by key, every other value (lists included) replaces the parent's.
Files whose name starts with ``_`` are bases: they can be extended but are not listed.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import yaml

from cdr_bench.scenarios.schema import ScenarioConfig, ScenarioError, from_mapping

_PACKAGE_DATA = Path(__file__).resolve().parent.parent / "_data" / "scenarios"


def registry_root() -> Path:
    """Directory holding the shipped scenarios (``CDR_BENCH_SCENARIOS`` overrides it)."""
    override = os.environ.get("CDR_BENCH_SCENARIOS")
    return Path(override) if override else _PACKAGE_DATA


def list_scenarios() -> list[str]:
    """Names of every shipped scenario, sorted."""
    root = registry_root()
    names = []
    for p in root.rglob("*.yaml"):
        rel = p.relative_to(root).with_suffix("")
        if not any(part.startswith("_") for part in rel.parts):
            names.append(rel.as_posix())
    return sorted(names)


def _resolve(name_or_path: str | os.PathLike[str], relative_to: Path | None = None) -> Path:
    text = os.fspath(name_or_path)
    p = Path(text)
    if text.endswith((".yaml", ".yml")):
        if not p.is_absolute() and relative_to is not None and (relative_to / p).exists():
            p = relative_to / p
        if not p.exists():
            raise ScenarioError(text, "", "no such scenario file")
        return p.resolve()
    candidate = registry_root() / f"{text}.yaml"
    if not candidate.exists():
        known = ", ".join(list_scenarios())
        raise ScenarioError(text, "", f"unknown scenario name (known: {known})")
    return candidate.resolve()


def _read_yaml(path: Path) -> dict[str, Any]:
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as e:
        raise ScenarioError(str(path), "", f"invalid YAML: {e}") from None
    except OSError as e:
        raise ScenarioError(str(path), "", f"cannot read: {e.strerror}") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ScenarioError(str(path), "", "expected a mapping at the top level")
    return data


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = v
    return out


def _load_mapping(path: Path, chain: tuple[Path, ...] = ()) -> dict[str, Any]:
    if path in chain:
        cycle = " -> ".join(str(p) for p in (*chain, path))
        raise ScenarioError(str(path), "extends", f"circular extends: {cycle}")
    data = _read_yaml(path)
    parent = data.pop("extends", None)
    if parent is None:
        return data
    if not isinstance(parent, str):
        raise ScenarioError(
            str(path), "extends", f"expected a scenario name or path, got {parent!r}"
        )
    try:
        parent_path = _resolve(parent, relative_to=path.parent)
    except ScenarioError as e:
        raise ScenarioError(str(path), "extends", e.message) from None
    return _merge(_load_mapping(parent_path, (*chain, path)), data)


def scenario_id_for(path: Path) -> str:
    root = registry_root().resolve()
    try:
        return path.resolve().relative_to(root).with_suffix("").as_posix()
    except ValueError:
        return path.stem


def load_scenario(
    name_or_path: str | os.PathLike[str] | ScenarioConfig, **overrides: Any
) -> ScenarioConfig:
    """Load a scenario by registry name or YAML path, applying nested ``overrides``.

    ``overrides`` are merged like an extending file: ``load_scenario("medium",
    separation={"los_km": 8.0})``. They are validated exactly like YAML values.
    """
    if isinstance(name_or_path, ScenarioConfig):
        if not overrides:
            return name_or_path
        data = name_or_path.to_dict()
        source = f"<{name_or_path.id} + overrides>"
    else:
        path = _resolve(name_or_path)
        data = _load_mapping(path)
        data.setdefault("id", scenario_id_for(path))
        source = str(path)
    if overrides:
        data = _merge(data, overrides)
        source = f"{source} (with overrides {sorted(overrides)})"
    return from_mapping(data, source)
