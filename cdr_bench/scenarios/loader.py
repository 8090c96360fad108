"""Scenario registry: YAML files under ``scenarios/``, ``extends:`` inheritance, by name or path.

A scenario is named by its path relative to the registry root without ``.yaml``
(``medium``, ``curriculum/stage-03``, ``tactical/head-on``) or given as a path to a YAML file.
``extends: NAME`` loads the parent first: a registry name, or a relative ``.yaml`` path from the
extending file that stays inside the registry or the extending file's own directory. Mappings
merge key by key; every other value (lists included) replaces the parent's. Files whose name
starts with ``_`` are bases: they can be extended but are not listed.

Every file is read defensively (a hostile file ends in one :class:`ScenarioError` naming it,
never a traceback, a hang or unbounded memory): at most :data:`MAX_FILE_BYTES`, UTF-8 text, YAML
without anchors, aliases, tags, merge keys or duplicate keys, nested at most :data:`MAX_DEPTH` deep,
integers of at most :data:`MAX_INT_DIGITS` digits, at most :data:`MAX_EXTENDS` parents. A file
outside the registry may not use the id of a registry scenario for different content.
"""

from __future__ import annotations

import copy
import difflib
import functools
import os
from pathlib import Path
from typing import Any

import yaml
from yaml.composer import ComposerError
from yaml.constructor import ConstructorError
from yaml.events import AliasEvent
from yaml.nodes import MappingNode, Node, ScalarNode

from cdr_bench._data import data_dir
from cdr_bench.errors import short_repr
from cdr_bench.scenarios.schema import ScenarioConfig, ScenarioError, from_mapping, name_problem

MAX_FILE_BYTES = 1 << 20
"""Largest scenario file read (1 MiB; the shipped ones are below 2 KiB)."""
MAX_DEPTH = 20
"""Deepest nesting of YAML mappings and lists (the schema needs 4)."""
MAX_INT_DIGITS = 64
"""Longest integer literal."""
MAX_EXTENDS = 16
"""Longest chain of ``extends:``."""


def registry_root() -> Path:
    """Directory holding the shipped scenarios (``CDR_BENCH_SCENARIOS`` overrides it): the
    repository's ``scenarios/`` in a source checkout, the package's copy of it in a wheel."""
    override = os.environ.get("CDR_BENCH_SCENARIOS")
    return Path(override) if override else data_dir("scenarios")


def _registry_names(include_bases: bool = False) -> list[str]:
    root = registry_root()
    names = []
    for p in root.rglob("*.yaml"):
        rel = p.relative_to(root).with_suffix("")
        if include_bases or not any(part.startswith("_") for part in rel.parts):
            names.append(rel.as_posix())
    return sorted(names)


def list_scenarios() -> list[str]:
    """Names of every shipped scenario, sorted."""
    return _registry_names()


def _label(path: Path | str) -> str:
    """A path as it appears in messages (one line whatever its characters)."""
    text = os.fspath(path)
    return text if text.isprintable() else short_repr(text, 200)


def _within(path: Path, directory: Path) -> bool:
    return path.resolve().is_relative_to(directory.resolve())


def _is_file(path: Path, *, or_other: bool = False) -> bool:
    """``path`` is a file (or, with ``or_other``, exists at all); False for a name the OS
    refuses (too long, an embedded NUL)."""
    try:
        return path.exists() if or_other else path.is_file()
    except (OSError, ValueError):
        return False


def _registry_file(name: str, source: str, field: str, *, bases: bool) -> Path:
    """The registry file of ``name``, or a ScenarioError (with a close match when one exists).

    Only names that :func:`~cdr_bench.scenarios.schema.name_problem` accepts are looked up, so
    a look-up never leaves the registry (no ``..``, no absolute path)."""
    problem = name_problem(name)
    if problem is not None:
        file_hint = "" if field else "; a scenario file's path ends in .yaml"
        raise ScenarioError(source, field, f"not a registry scenario name: {problem}{file_hint}")
    root = registry_root()
    candidate = root / f"{name}.yaml"
    if _is_file(candidate) and _within(candidate, root):
        return candidate.resolve()
    known = _registry_names(include_bases=bases)
    close = difflib.get_close_matches(name, known, n=1)
    if close:
        hint = f"did you mean {close[0]!r}?"
    else:
        hint = f"known: {', '.join(list_scenarios())}"
    raise ScenarioError(source, field, f"unknown scenario name {name!r}; {hint}")


def _resolve(name_or_path: str | os.PathLike[str]) -> Path:
    """A scenario argument: a YAML file path (any, as the user gives it) or a registry name."""
    text = os.fspath(name_or_path)
    if text.endswith((".yaml", ".yml")):
        p = Path(text)
        if not _is_file(p, or_other=True):  # a directory or device: the reader says so
            raise ScenarioError(_label(text), "", "no such scenario file")
        return p.resolve()
    return _registry_file(text, _label(text), "", bases=False)


def _resolve_parent(parent: str, child: Path) -> Path:
    """The file named by ``extends:`` in ``child``: a registry name, or a relative ``.yaml`` path
    resolving inside the registry or inside ``child``'s directory."""
    source = _label(child)
    if not parent.endswith((".yaml", ".yml")):
        return _registry_file(parent, source, "extends", bases=True)
    rel = Path(parent)
    if rel.is_absolute() or "\\" in parent or "\x00" in parent:
        raise ScenarioError(
            source,
            "extends",
            f"expected a registry name or a relative path, got {short_repr(parent)}",
        )
    p = child.parent / rel
    if not (_within(p, registry_root()) or _within(p, child.parent)):
        raise ScenarioError(
            source,
            "extends",
            f"{short_repr(parent)} leaves the registry and this file's directory; name a "
            "registry scenario or a file beside this one",
        )
    if not _is_file(p):
        raise ScenarioError(source, "extends", f"no such scenario file {short_repr(parent)}")
    return p.resolve()


# ---------------------------------------------------------------------------------------------
# Reading one file


class _ScenarioYamlLoader(yaml.SafeLoader):
    """PyYAML's safe loader without the features a scenario never needs and an attacker would
    use: anchors and aliases (the "billion laughs"), explicit tags, merge keys, duplicate keys
    (PyYAML keeps the last silently), deep nesting (Python's recursion limit) and huge
    integers."""

    _depth = 0
    _kind = "scenario files"
    """Named in the messages (a subclass reads other files with the same rules)."""

    def compose_node(self, parent: Node | None, index: Any) -> Node | None:
        if self.check_event(AliasEvent):
            event = self.peek_event()
            raise ComposerError(
                None, None, f"aliases (*name) are not allowed in {self._kind}", event.start_mark
            )
        event = self.peek_event()
        if getattr(event, "anchor", None) is not None:
            raise ComposerError(
                None, None, f"anchors (&name) are not allowed in {self._kind}", event.start_mark
            )
        if getattr(event, "tag", None) is not None:
            raise ComposerError(
                None, None, f"tags (!!name) are not allowed in {self._kind}", event.start_mark
            )
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                raise ComposerError(
                    None, None, f"nested more than {MAX_DEPTH} levels deep", event.start_mark
                )
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_mapping(self, node: MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: dict[Any, int] = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                raise ConstructorError(
                    None, None, "merge keys (<<) are not allowed", key_node.start_mark
                )
            key = self.construct_object(key_node, deep=True)
            try:
                first = seen.get(key)
            except TypeError:  # unhashable: the base class reports it
                break
            if first is not None:
                raise ConstructorError(
                    None,
                    None,
                    f"duplicate key {short_repr(key)} (first given on line {first})",
                    key_node.start_mark,
                )
            seen[key] = key_node.start_mark.line + 1
        return super().construct_mapping(node, deep=deep)

    def construct_yaml_int(self, node: ScalarNode) -> int:
        digits = sum(c.isdigit() for c in str(node.value))
        if digits > MAX_INT_DIGITS:
            raise ConstructorError(
                None,
                None,
                f"an integer of {digits} digits (at most {MAX_INT_DIGITS})",
                node.start_mark,
            )
        return super().construct_yaml_int(node)  # type: ignore[no-any-return]

    def construct_object(self, node: Node, deep: bool = False) -> Any:
        try:
            return super().construct_object(node, deep=deep)
        except yaml.YAMLError:
            raise
        except Exception as e:  # PyYAML's own bugs and limits, e.g. a timestamp 2024-13-45
            raise ConstructorError(
                None, None, f"cannot read this value ({short_repr(str(e))})", node.start_mark
            ) from None


_ScenarioYamlLoader.add_constructor("tag:yaml.org,2002:int", _ScenarioYamlLoader.construct_yaml_int)


def _yaml_problem(e: yaml.YAMLError) -> str:
    """A YAML error as one line: position and problem, without PyYAML's source excerpt."""
    if isinstance(e, yaml.reader.ReaderError):
        return f"invalid YAML at character {e.position}: unacceptable character {e.character!r}"
    mark = getattr(e, "problem_mark", None) or getattr(e, "context_mark", None)
    problem = getattr(e, "problem", None) or getattr(e, "context", None) or type(e).__name__
    where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
    text = " ".join(str(problem).split())
    if len(text) > 200:
        text = text[:197] + "..."
    return f"invalid YAML{where}: {text}"


def _read_text(path: Path) -> str:
    source = _label(path)
    if not path.is_file():
        raise ScenarioError(source, "", "not a regular file")
    try:
        with path.open("rb") as f:
            raw = f.read(MAX_FILE_BYTES + 1)
    except OSError as e:
        raise ScenarioError(source, "", f"cannot read: {e.strerror}") from None
    if len(raw) > MAX_FILE_BYTES:
        raise ScenarioError(source, "", f"file larger than {MAX_FILE_BYTES // 1024} KiB")
    if b"\x00" in raw:
        raise ScenarioError(source, "", "binary file (NUL bytes); expected YAML text")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise ScenarioError(
            source,
            "",
            f"not UTF-8 text (byte 0x{raw[e.start]:02x} at offset {e.start}); save it as UTF-8",
        ) from None


@functools.lru_cache(maxsize=512)
def _parsed(text: str, loader: type[_ScenarioYamlLoader]) -> Any:
    """``text`` parsed by ``loader`` (this module's hardened loader or a subclass), once per
    process and text: a leaderboard build loads each scenario of each submission several times,
    and parsing was 4/5 of a scenario's loading time. Keyed by the text itself, so an edited
    file is parsed again; an error is not kept (it is raised again on each call); callers get a
    copy (:func:`parse_yaml`)."""
    return yaml.load(text, Loader=loader)  # noqa: S506 - a SafeLoader subclass


def parse_yaml(text: str, loader: type[_ScenarioYamlLoader] = _ScenarioYamlLoader) -> Any:
    """``yaml.load(text, Loader=loader)``, from a per-process cache (a fresh copy each call)."""
    return copy.deepcopy(_parsed(text, loader))  # type: ignore[arg-type] # a class is hashable


def _read_yaml(path: Path) -> dict[str, Any]:
    text = _read_text(path)
    try:
        data = parse_yaml(text)
    except yaml.YAMLError as e:
        raise ScenarioError(_label(path), "", _yaml_problem(e)) from None
    except RecursionError:  # pragma: no cover - MAX_DEPTH stops nesting long before
        raise ScenarioError(_label(path), "", "invalid YAML: nested too deep") from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ScenarioError(_label(path), "", "expected a mapping at the top level")
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
        cycle = " -> ".join(_label(p) for p in (*chain, path))
        raise ScenarioError(_label(path), "extends", f"circular extends: {cycle}")
    if len(chain) >= MAX_EXTENDS:
        raise ScenarioError(_label(chain[0]), "extends", f"more than {MAX_EXTENDS} levels")
    data = _read_yaml(path)
    parent = data.pop("extends", None)
    if parent is None:
        return data
    if not isinstance(parent, str):
        raise ScenarioError(
            _label(path), "extends", f"expected a scenario name or path, got {short_repr(parent)}"
        )
    return _merge(_load_mapping(_resolve_parent(parent, path), (*chain, path)), data)


def scenario_id_for(path: Path) -> str:
    root = registry_root().resolve()
    try:
        return path.resolve().relative_to(root).with_suffix("").as_posix()
    except ValueError:
        return path.stem


def _check_not_shadowing(cfg: ScenarioConfig, path: Path, source: str) -> None:
    """A file may carry the id of a registry scenario only with that scenario's content."""
    root = registry_root()
    shipped = root / f"{cfg.id}.yaml"
    if not shipped.is_file() or shipped.resolve() == path or not _within(shipped, root):
        return
    if load_scenario(cfg.id).config_hash() != cfg.config_hash():
        raise ScenarioError(
            source,
            "id",
            f"{cfg.id!r} is the id of a registry scenario with different content; set another "
            "'id:' (or rename the file)",
        )


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
    elif isinstance(name_or_path, (str, os.PathLike)):
        path = _resolve(name_or_path)
        data = _load_mapping(path)
        source = _label(path)
        if "id" not in data:
            data["id"] = scenario_id_for(path)
            problem = name_problem(data["id"])
            if problem is not None:
                raise ScenarioError(
                    source, "id", f"the file name gives no valid id ({problem}); set 'id:'"
                )
        cfg = from_mapping(data, source)
        _check_not_shadowing(cfg, path, source)
        if not overrides:
            return cfg
    else:
        raise ScenarioError(
            "",
            "",
            "expected a scenario: a registry name (cdr-bench scenarios list), a YAML path or a "
            f"ScenarioConfig, got {short_repr(name_or_path)} of type {type(name_or_path).__name__}",
        )
    return from_mapping(_merge(data, overrides), f"{source} (with overrides {sorted(overrides)})")
