"""Typed, frozen scenario configuration and its validation.

A scenario is one :class:`ScenarioConfig`. YAML files hold only values; this module holds the
schema: every field has a type, a unit in its name or doc, and (where it applies) a range.
:func:`from_mapping` builds a config from a plain mapping and rejects unknown keys, wrong types
and out-of-range values with a :class:`ScenarioError` naming the file, the field path and what
was expected.

This module imports neither PettingZoo, Gymnasium nor torch; the simulator consumes it.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import types
import typing
from dataclasses import dataclass, field
from typing import Any, Union

from cdr_bench.errors import ScenarioError


def _spec(doc: str, lo: float | None = None, hi: float | None = None, **kw: Any) -> Any:
    """A dataclass field with a docstring and an inclusive numeric range."""
    return field(metadata={"doc": doc, "min": lo, "max": hi}, **kw)


Point = tuple[float, float]


@dataclass(frozen=True)
class Airway:
    """A straight airway from ``start_km`` to ``end_km`` (both on or near the sector edge)."""

    start_km: Point = _spec("entry point [x, y] in km")
    end_km: Point = _spec("exit point [x, y] in km")


@dataclass(frozen=True)
class Aircraft:
    """An explicitly placed aircraft: flies straight at constant speed and level."""

    position_km: Point = _spec("initial position [x, y] in km")
    heading_deg: float = _spec("heading in degrees clockwise from north", 0.0, 360.0)
    speed_kt: float = _spec("ground speed in knots", 0.0, 1000.0)
    level: int = _spec("flight level index", 0, 2)


@dataclass(frozen=True)
class SectorConfig:
    size_km: float = _spec("side of the square sector in km", 10.0, 5000.0, default=400.0)
    boundary_terminates: bool = _spec(
        "end the episode (outcome 'boundary') when a controlled aircraft leaves the sector",
        default=False,
    )


@dataclass(frozen=True)
class TimeConfig:
    dt_s: float = _spec("simulation step in seconds", 1.0, 300.0, default=30.0)
    max_steps: int = _spec("horizon in steps; reaching it is a timeout", 1, 100_000, default=1000)


@dataclass(frozen=True)
class SeparationConfig:
    los_km: float = _spec("loss-of-separation horizontal threshold in km", 0.0, 100.0, default=10.0)
    nmac_km: float = _spec("near-mid-air-collision threshold in km", 0.0, 10.0, default=0.2)
    los_terminates: bool = _spec("a LoS ends the episode as a failure", default=False)


@dataclass(frozen=True)
class OwnshipConfig:
    speed_kt: float = _spec("initial speed in knots", 100.0, 1000.0, default=430.0)
    min_speed_kt: float = _spec("lowest commanded speed in knots", 50.0, 1000.0, default=330.0)
    max_speed_kt: float = _spec("highest commanded speed in knots", 50.0, 1000.0, default=530.0)
    heading_step_deg: float = _spec(
        "heading change of one action unit, deg", 0.0, 90.0, default=5.0
    )
    speed_step_kt: float = _spec("speed change of one action unit, kt", 0.0, 200.0, default=50.0)
    goal_radius_km: float = _spec("goal reached within this distance, km", 0.1, 100.0, default=5.0)
    goal_margin_km: float = _spec(
        "random goals keep this distance to every edge, km", 0.0, 1000.0, default=20.0
    )
    start_clearance_km: float = _spec(
        "random starts keep this distance to every intruder, km", 0.0, 200.0, default=20.0
    )
    start: Aircraft | None = _spec("explicit start (random boundary start when null)", default=None)
    goal_km: Point | None = _spec("explicit goal [x, y] in km (random when null)", default=None)


@dataclass(frozen=True)
class TrafficConfig:
    routes: int = _spec("number of airways used (the first N of 'airways')", 0, 64, default=12)
    per_route: int = _spec("steady-state aircraft per airway", 1, 16, default=3)
    speed_kt: float = _spec(
        "intruder speed in knots (431.965 kt = 800 km/h)", 50.0, 1000.0, default=431.965
    )
    spawn_clearance_km: float = _spec(
        "a spawn waits while a controlled aircraft at its level is closer than this, km",
        0.0,
        200.0,
        default=20.0,
    )


@dataclass(frozen=True)
class LearningIntruder:
    """A learning aircraft that flies its airway from start to end as its goal."""

    airway: int = _spec("index into 'airways'", 0, 63)


@dataclass(frozen=True)
class ObservationConfig:
    neighbours: int = _spec("number of nearest aircraft observed (K)", 1, 16, default=3)
    range_km: float = _spec("distance scale of relative positions, km", 1.0, 1000.0, default=100.0)
    lookahead_s: float = _spec(
        "time scale of closest-approach features, s", 1.0, 3600.0, default=600.0
    )


@dataclass(frozen=True)
class RewardConfig:
    goal: float = _spec("reward on reaching the goal", -100.0, 100.0, default=1.0)
    path: float = _spec("weight of -(d_goal / size)^2 per step", 0.0, 100.0, default=1.0)
    boundary: float = _spec("penalty per step outside the sector", 0.0, 100.0, default=0.5)
    step: float = _spec("penalty per step", 0.0, 100.0, default=0.01)
    los: float = _spec("penalty per aircraft in LoS during the step", 0.0, 100.0, default=0.5)
    nmac: float = _spec("penalty per aircraft in NMAC during the step", 0.0, 100.0, default=1.0)
    timeout: float = _spec("penalty when the horizon is reached", 0.0, 100.0, default=0.5)


@dataclass(frozen=True)
class ScenarioConfig:
    """One fully resolved scenario. Immutable; hashable by :meth:`config_hash`."""

    id: str = _spec("stable scenario id, e.g. 'medium' or 'curriculum/stage-03'", default="")
    description: str = _spec("one-line description", default="")
    version: int = _spec("bumped whenever a change alters results", 1, 10_000, default=1)
    sector: SectorConfig = _spec("sector geometry", default_factory=SectorConfig)
    time: TimeConfig = _spec("time step and horizon", default_factory=TimeConfig)
    separation: SeparationConfig = _spec("separation thresholds", default_factory=SeparationConfig)
    ownship: OwnshipConfig = _spec(
        "ownship performance, start and goal", default_factory=OwnshipConfig
    )
    traffic: TrafficConfig = _spec("airway traffic", default_factory=TrafficConfig)
    airways: tuple[Airway, ...] = _spec("the airway network", default=())
    aircraft: tuple[Aircraft, ...] = _spec("explicitly placed background aircraft", default=())
    learning_intruders: tuple[LearningIntruder, ...] = _spec(
        "learning aircraft (agents intruder_0, intruder_1, ...)", default=()
    )
    observation: ObservationConfig = _spec("observation layout", default_factory=ObservationConfig)
    reward: RewardConfig = _spec("reward weights", default_factory=RewardConfig)

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON form (tuples become lists)."""
        return json.loads(json.dumps(dataclasses.asdict(self)))

    def config_hash(self) -> str:
        """SHA-256 of the canonical JSON form: identifies the dynamics of the scenario."""
        blob = json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(blob.encode()).hexdigest()

    @property
    def n_learning_intruders(self) -> int:
        return len(self.learning_intruders)

    @property
    def n_route_intruders(self) -> int:
        return self.traffic.routes * self.traffic.per_route


# --------------------------------------------------------------------------------------------
# Generic validation of a mapping against the dataclass schema


def _type_name(tp: Any) -> str:
    origin = typing.get_origin(tp)
    if origin in (Union, types.UnionType):
        return " or ".join(_type_name(a) for a in typing.get_args(tp))
    if tp is type(None):
        return "null"
    if origin is tuple:
        args = typing.get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a list of {_type_name(args[0])}"
        return f"a list of {len(args)} numbers"
    if dataclasses.is_dataclass(tp):
        return "a mapping"
    return {int: "an integer", float: "a number", bool: "true/false", str: "a string"}.get(
        tp, str(tp)
    )


def _convert(value: Any, tp: Any, source: str, path: str, meta: dict[str, Any]) -> Any:
    origin = typing.get_origin(tp)
    if origin in (Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        non_none = [a for a in args if a is not type(None)]
        return _convert(value, non_none[0], source, path, meta)
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise ScenarioError(source, path, f"expected a mapping, got {value!r}")
        return _build(tp, value, source, path)
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, (list, tuple)):
            raise ScenarioError(source, path, f"expected {_type_name(tp)}, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(
                _convert(v, args[0], source, f"{path}[{i}]", {}) for i, v in enumerate(value)
            )
        if len(value) != len(args):
            raise ScenarioError(source, path, f"expected {_type_name(tp)}, got {value!r}")
        return tuple(
            _convert(v, a, source, f"{path}[{i}]", meta)
            for i, (v, a) in enumerate(zip(value, args, strict=True))
        )
    if tp is bool:
        if not isinstance(value, bool):
            raise ScenarioError(source, path, f"expected true/false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ScenarioError(source, path, f"expected a string, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ScenarioError(source, path, f"expected an integer, got {value!r}")
        out: float = value
    elif tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ScenarioError(source, path, f"expected a number, got {value!r}")
        out = float(value)
        if not math.isfinite(out):
            raise ScenarioError(source, path, f"expected a finite number, got {value!r}")
    else:  # pragma: no cover - schema error, not user error
        raise TypeError(f"unsupported schema type {tp!r}")
    lo, hi = meta.get("min"), meta.get("max")
    if (lo is not None and out < lo) or (hi is not None and out > hi):
        raise ScenarioError(source, path, f"expected a value in [{lo}, {hi}], got {value!r}")
    return out if tp is float else int(out)


def _build(cls: Any, data: dict[str, Any], source: str, prefix: str) -> Any:
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    for key in data:
        if key not in fields:
            close = [k for k in fields if k.startswith(str(key)[:3])]
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise ScenarioError(
                source,
                f"{prefix}.{key}" if prefix else str(key),
                f"unknown key (allowed: {', '.join(sorted(fields))}){hint}",
            )
    kwargs = {}
    for name, f in fields.items():
        path = f"{prefix}.{name}" if prefix else name
        if name in data:
            kwargs[name] = _convert(data[name], hints[name], source, path, dict(f.metadata))
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ScenarioError(source, path, f"missing required field ({_type_name(hints[name])})")
    return cls(**kwargs)


def from_mapping(data: dict[str, Any], source: str = "") -> ScenarioConfig:
    """Build and cross-check a :class:`ScenarioConfig` from a plain mapping."""
    if not isinstance(data, dict):
        raise ScenarioError(source, "", f"expected a mapping at the top level, got {data!r}")
    cfg: ScenarioConfig = _build(ScenarioConfig, data, source, "")
    _cross_check(cfg, source)
    return cfg


def _cross_check(cfg: ScenarioConfig, source: str) -> None:
    o = cfg.ownship
    if o.min_speed_kt > o.max_speed_kt:
        raise ScenarioError(source, "ownship.min_speed_kt", "expected min_speed_kt <= max_speed_kt")
    if not o.min_speed_kt <= o.speed_kt <= o.max_speed_kt:
        raise ScenarioError(
            source, "ownship.speed_kt", f"expected a value in [{o.min_speed_kt}, {o.max_speed_kt}]"
        )
    if 2 * o.goal_margin_km >= cfg.sector.size_km:
        raise ScenarioError(
            source, "ownship.goal_margin_km", "expected less than half of sector.size_km"
        )
    if cfg.separation.nmac_km > cfg.separation.los_km:
        raise ScenarioError(source, "separation.nmac_km", "expected nmac_km <= los_km")
    if cfg.traffic.routes > len(cfg.airways):
        raise ScenarioError(
            source, "traffic.routes", f"expected at most {len(cfg.airways)} (the number of airways)"
        )
    for i, li in enumerate(cfg.learning_intruders):
        if li.airway >= len(cfg.airways):
            raise ScenarioError(
                source,
                f"learning_intruders[{i}].airway",
                f"expected an index below {len(cfg.airways)}",
            )
    for i, a in enumerate(cfg.airways):
        if math.dist(a.start_km, a.end_km) < 1.0:
            raise ScenarioError(source, f"airways[{i}]", "expected distinct start and end")
    if o.start is not None and o.goal_km is None:
        raise ScenarioError(source, "ownship.goal_km", "expected a goal when 'start' is given")


def _inner_dataclass(tp: Any) -> tuple[Any, str]:
    """The dataclass inside ``X``, ``X | None`` or ``tuple[X, ...]`` and the path suffix."""
    origin = typing.get_origin(tp)
    if origin in (Union, types.UnionType):
        for arg in typing.get_args(tp):
            inner, suffix = _inner_dataclass(arg)
            if inner is not None:
                return inner, suffix
    if origin is tuple:
        args = typing.get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis and dataclasses.is_dataclass(args[0]):
            return args[0], "[]"
    if dataclasses.is_dataclass(tp):
        return tp, ""
    return None, ""


def field_docs(cls: Any = ScenarioConfig, prefix: str = "") -> list[tuple[str, str, str]]:
    """(dotted path, type, doc) for every field: the scenario format reference."""
    rows = []
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        path = f"{prefix}.{f.name}" if prefix else f.name
        tp = hints[f.name]
        doc = f.metadata.get("doc", "")
        lo, hi = f.metadata.get("min"), f.metadata.get("max")
        if lo is not None:
            doc += f" [{lo}, {hi}]"
        rows.append((path, _type_name(tp), doc))
        inner, suffix = _inner_dataclass(tp)
        if inner is not None:
            rows.extend(field_docs(inner, path + suffix))
    return rows
