"""Typed, frozen scenario configuration and its validation.

A scenario is one :class:`ScenarioConfig`. YAML files hold only values; this module holds the
schema: every field has a type, a unit in its name or doc, and (where it applies) a range.
:func:`from_mapping` builds a config from a plain mapping and rejects unknown keys, wrong types
and out-of-range values with a :class:`ScenarioError` naming the file, the field path and what
was expected.

Limits (well above every shipped scenario, so that no file can ask for unbounded work):
:data:`MAX_AIRWAYS` airways, :data:`MAX_AIRCRAFT` explicit aircraft,
:data:`MAX_LEARNING_INTRUDERS` learning intruders, coordinates within +-:data:`MAX_COORD_KM`,
ids of at most :data:`MAX_NAME_CHARS` characters (see :func:`name_problem`), a description of
at most :data:`MAX_TEXT_CHARS` printable characters. The file-level limits (size, nesting,
YAML features) are the loader's.

This module imports neither PettingZoo, Gymnasium nor torch; the simulator consumes it.
"""

from __future__ import annotations

import dataclasses
import difflib
import hashlib
import json
import math
import re
import types
import typing
import unicodedata
from dataclasses import dataclass, field
from typing import Any, Union

from cdr_bench.errors import MAX_QUOTED_CHARS, ScenarioError, short_repr

MAX_AIRWAYS = 64
"""Most airways a scenario may list (``learning_intruders[].airway`` indexes them)."""
MAX_AIRCRAFT = 256
"""Most explicitly placed background aircraft."""
MAX_LEARNING_INTRUDERS = 16
"""Most learning intruders."""
MAX_CONTROLLED_TRAFFIC = 1024
"""Most controlled airway aircraft (``traffic.controlled``; 64 airways x 16 per airway)."""
MAX_CONTROLLED_SPAWNS = 1024
"""Most controlled aircraft entering during an episode (``traffic.controlled_spawns``)."""
MAX_COORD_KM = 10_000.0
"""Every coordinate is within [-MAX_COORD_KM, MAX_COORD_KM] km (twice the largest sector)."""
MAX_NAME_CHARS = 128
"""Longest scenario id or registry name."""
MAX_TEXT_CHARS = 500
"""Longest description."""
KM_PER_S_PER_KT = 1.852 / 3600.0
"""km/s in one knot (:data:`cdr_bench.sim.units.KM_PER_S_PER_KT`; the schema sits below the
simulator)."""

_NAME_PART = r"[A-Za-z0-9_][A-Za-z0-9._+-]*"
_NAME = re.compile(rf"{_NAME_PART}(?:/{_NAME_PART})*")
# Control, format (bidi overrides), line/paragraph separators and surrogates.
_CONTROL_CATEGORIES = frozenset({"Cc", "Cf", "Cs", "Zl", "Zp"})


def _spec(
    doc: str,
    lo: float | None = None,
    hi: float | None = None,
    *,
    max_items: int | None = None,
    min_items: int | None = None,
    max_chars: int | None = None,
    name: bool = False,
    unless: str | None = None,
    **kw: Any,
) -> Any:
    """A dataclass field with a docstring, an inclusive numeric range (of each number of a
    point, a range or a list), the fewest and most items of a list, the most characters of a
    text, or a name's rules. ``unless``: the field is required unless that other field is
    given, and may not be given with it."""
    meta = {"doc": doc, "min": lo, "max": hi, "max_items": max_items, "name": name}
    if min_items is not None:
        meta["min_items"] = min_items
    if max_chars is not None:
        meta["max_chars"] = max_chars
    if unless is not None:
        meta["unless"] = unless
    return field(metadata=meta, **kw)


Point = tuple[float, float]
Range = float | tuple[float, float]
"""A number (fixed) or ``[lo, hi]``, drawn uniformly per episode (docs/model.md §8.3)."""


def range_bounds(value: Range) -> tuple[float, float]:
    """``(lo, hi)`` of a :data:`Range` (``(x, x)`` for a fixed number)."""
    if isinstance(value, tuple):
        return value
    return (value, value)


@dataclass(frozen=True)
class Airway:
    """A straight airway from ``start_km`` to ``end_km`` (both on or near the sector edge)."""

    start_km: Point = _spec("entry point [x, y] in km", -MAX_COORD_KM, MAX_COORD_KM)
    end_km: Point = _spec("exit point [x, y] in km", -MAX_COORD_KM, MAX_COORD_KM)


@dataclass(frozen=True)
class Aircraft:
    """An explicitly placed aircraft: flies straight at constant speed and level."""

    position_km: Point = _spec(
        "initial position [x, y] in km, inside the sector", -MAX_COORD_KM, MAX_COORD_KM
    )
    heading_deg: float = _spec("heading in degrees clockwise from north", 0.0, 360.0)
    speed_kt: float = _spec("ground speed in knots", 0.0, 1000.0)
    level: int = _spec("flight level index", 0, 2)


@dataclass(frozen=True)
class Encounter:
    """An aircraft placed relative to the ownship's nominal flight (straight at its start
    heading and speed): it reaches the closest point of approach (CPA) with the ownship after
    ``time_to_cpa_s``, passing at ``miss_km``. Each value is a number or ``[lo, hi]``, drawn
    uniformly per episode from the episode's seed (docs/model.md §8.3)."""

    time_to_cpa_s: Range = _spec(
        "time until the closest point of approach with the ownship's straight flight, s: a "
        "number or [lo, hi] drawn per episode",
        0.0,
        3600.0,
    )
    angle_deg: Range = _spec(
        "track minus the ownship's start heading, deg clockwise (180: head-on, 90: from the "
        "left, -90: from the right, 0: same direction): a number or [lo, hi]",
        -360.0,
        360.0,
    )
    miss_km: Range = _spec(
        "signed horizontal distance at the closest point of approach, km, positive when the "
        "aircraft is then on the ownship's right: a number or [lo, hi]",
        -1000.0,
        1000.0,
    )
    speed_kt: Range = _spec("ground speed in knots: a number or [lo, hi]", 1.0, 1000.0)
    level: int | tuple[int, ...] = _spec(
        "flight level index, or a list of distinct levels drawn uniformly per episode",
        0,
        2,
        min_items=1,
        max_items=3,
    )
    mirror: bool = _spec(
        "with probability 1/2 per episode the encounter is mirrored across the ownship's track "
        "(angle_deg and miss_km change sign)",
        default=False,
    )


@dataclass(frozen=True)
class PlacedAircraft:
    """A background aircraft placed explicitly: at a fixed position (``position_km``,
    ``heading_deg``, ``speed_kt``, ``level``) or by an ``encounter`` with the ownship."""

    position_km: Point | None = _spec(
        "initial position [x, y] in km, inside the sector (unless 'encounter')",
        -MAX_COORD_KM,
        MAX_COORD_KM,
        unless="encounter",
        default=None,
    )
    heading_deg: float | None = _spec(
        "heading in degrees clockwise from north (unless 'encounter')",
        0.0,
        360.0,
        unless="encounter",
        default=None,
    )
    speed_kt: float | None = _spec(
        "ground speed in knots (unless 'encounter')", 0.0, 1000.0, unless="encounter", default=None
    )
    level: int | None = _spec(
        "flight level index (unless 'encounter')", 0, 2, unless="encounter", default=None
    )
    encounter: Encounter | None = _spec(
        "placed relative to the ownship's straight flight, drawn per episode (needs "
        "ownship.start; instead of position_km, heading_deg, speed_kt, level)",
        default=None,
    )


@dataclass(frozen=True)
class SectorConfig:
    size_km: float = _spec("side of the square sector in km", 10.0, 5000.0, default=400.0)
    boundary_margin_km: float | None = _spec(
        "a controlled aircraft farther than this outside the sector ends its episode (outcome "
        "'boundary'); 0: on leaving; null: never (the paper's soft boundary)",
        0.0,
        1000.0,
        default=50.0,
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
    speed_kt: float = _spec(
        "initial speed in knots, within min/max_speed_kt", 100.0, 1000.0, default=430.0
    )
    min_speed_kt: float = _spec("lowest commanded speed in knots", 50.0, 1000.0, default=330.0)
    max_speed_kt: float = _spec("highest commanded speed in knots", 50.0, 1000.0, default=530.0)
    heading_step_deg: float = _spec(
        "heading change of one action unit, deg", 0.0, 90.0, default=5.0
    )
    speed_step_kt: float = _spec("speed change of one action unit, kt", 0.0, 200.0, default=50.0)
    goal_radius_km: float = _spec(
        "goal reached within this distance, km (below half the sector)", 0.1, 100.0, default=5.0
    )
    goal_margin_km: float = _spec(
        "random goals keep this distance to every edge, km (below half the sector)",
        0.0,
        1000.0,
        default=20.0,
    )
    start_clearance_km: float = _spec(
        "random starts keep this distance to every intruder, km (below half the sector)",
        0.0,
        200.0,
        default=20.0,
    )
    start: Aircraft | None = _spec(
        "explicit start inside the sector, speed within min/max_speed_kt, no aircraft at its "
        "level within separation.nmac_km (random boundary start when null)",
        default=None,
    )
    goal_km: Point | None = _spec(
        "explicit goal [x, y] in km, inside the sector (random when null; needs 'start')",
        -MAX_COORD_KM,
        MAX_COORD_KM,
        default=None,
    )


@dataclass(frozen=True)
class TrafficConfig:
    routes: int = _spec("number of airways used (the first N of 'airways')", 0, 64, default=12)
    per_route: int = _spec("steady-state aircraft per airway", 1, 16, default=3)
    speed_kt: float = _spec(
        "intruder speed in knots (431.965 kt = 800 km/h)", 50.0, 1000.0, default=431.965
    )
    spawn_clearance_km: float = _spec(
        "a spawn waits while a controlled aircraft at its level is closer than this, km "
        "(below half the sector)",
        0.0,
        200.0,
        default=20.0,
    )
    controlled: int = _spec(
        "airway aircraft in the sky at the start that are controlled (agents aircraft_0, ...), "
        "drawn per episode among the routes x per_route; each flies to its airway's end as its "
        "goal",
        0,
        MAX_CONTROLLED_TRAFFIC,
        default=0,
    )
    spawn: bool = _spec(
        "airways spawn new (background) aircraft; false: no spawns, the sky empties as its "
        "aircraft leave",
        default=True,
    )
    controlled_spawns: int = _spec(
        "the first N airway spawns of an episode enter as controlled aircraft (new agents "
        "aircraft_C.., C = traffic.controlled, in the order they enter), each flying to its "
        "airway's end; later spawns are background (none with spawn: false)",
        0,
        MAX_CONTROLLED_SPAWNS,
        default=0,
    )


@dataclass(frozen=True)
class LearningIntruder:
    """A learning aircraft: it flies its airway from start to end as its goal, or it is placed
    by an ``encounter`` with the ownship (as a placed background aircraft is) and its goal lies
    on its track as far past the encounter as it starts before it (twice the time to CPA)."""

    airway: int | None = _spec(
        "index into 'airways' (unless 'encounter')",
        0,
        MAX_AIRWAYS - 1,
        unless="encounter",
        default=None,
    )
    encounter: Encounter | None = _spec(
        "placed relative to the ownship's straight flight, drawn per episode, its goal at twice "
        "the time to CPA along its track (needs ownship.start; instead of airway)",
        default=None,
    )


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

    id: str = _spec(
        "stable scenario id, e.g. 'medium' or 'curriculum/stage-03' (letters, digits, '._+-', "
        f"parts separated by '/'; at most {MAX_NAME_CHARS} characters)",
        name=True,
        default="",
    )
    description: str = _spec(
        f"one-line description (at most {MAX_TEXT_CHARS} characters)",
        max_chars=MAX_TEXT_CHARS,
        default="",
    )
    version: int = _spec("bumped whenever a change alters results", 1, 10_000, default=1)
    sector: SectorConfig = _spec("sector geometry", default_factory=SectorConfig)
    time: TimeConfig = _spec("time step and horizon", default_factory=TimeConfig)
    separation: SeparationConfig = _spec("separation thresholds", default_factory=SeparationConfig)
    ownship: OwnshipConfig = _spec(
        "ownship performance, start and goal", default_factory=OwnshipConfig
    )
    traffic: TrafficConfig = _spec("airway traffic", default_factory=TrafficConfig)
    airways: tuple[Airway, ...] = _spec(
        f"the airway network, each crossing the sector (at most {MAX_AIRWAYS})",
        max_items=MAX_AIRWAYS,
        default=(),
    )
    aircraft: tuple[PlacedAircraft, ...] = _spec(
        f"explicitly placed background aircraft, fixed or by encounter (at most {MAX_AIRCRAFT})",
        max_items=MAX_AIRCRAFT,
        default=(),
    )
    learning_intruders: tuple[LearningIntruder, ...] = _spec(
        f"learning aircraft (agents intruder_0, intruder_1, ...; at most {MAX_LEARNING_INTRUDERS})",
        max_items=MAX_LEARNING_INTRUDERS,
        default=(),
    )
    observation: ObservationConfig = _spec("observation layout", default_factory=ObservationConfig)
    reward: RewardConfig = _spec("reward weights", default_factory=RewardConfig)

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON form (tuples become lists). Fields of :data:`OMITTED_AT_DEFAULT` are left
        out at their default, so that adding them changed no scenario's :meth:`config_hash`."""
        out = json.loads(json.dumps(dataclasses.asdict(self)))
        for section, name in OMITTED_AT_DEFAULT:
            part = out[section]
            default = next(f for f in dataclasses.fields(TrafficConfig) if f.name == name).default
            if part.get(name) == default:
                del part[name]
        for li in out["learning_intruders"]:  # an airway, or (added later) an encounter
            for name in ("airway", "encounter"):
                if li.get(name) is None:
                    del li[name]
        return out

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

    @property
    def n_controlled(self) -> int:
        """Controlled aircraft (agents) per episode: the ownship, the learning intruders and
        the controlled airway aircraft, those in the sky at the start and those entering
        later (docs/model.md §8.4)."""
        t = self.traffic
        return 1 + len(self.learning_intruders) + t.controlled + t.controlled_spawns


OMITTED_AT_DEFAULT = (
    ("traffic", "controlled"),
    ("traffic", "spawn"),
    ("traffic", "controlled_spawns"),
)
"""(section, field) pairs that :meth:`ScenarioConfig.to_dict` leaves out at their default (all
in :class:`TrafficConfig`): fields added after results had been published."""


# --------------------------------------------------------------------------------------------
# Generic validation of a mapping against the dataclass schema. Every problem of a mapping is
# collected (path, message) and reported at once; cross-field checks run once every field is
# valid.

_INVALID: Any = object()
"""What a conversion returns after recording a problem."""

Problems = list[tuple[str, str]]


def _type_name(tp: Any) -> str:
    origin = typing.get_origin(tp)
    if origin in (Union, types.UnionType):
        return " or ".join(_type_name(a) for a in typing.get_args(tp))
    if tp is type(None):
        return "null"
    if origin is tuple:
        args = typing.get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            plural = {int: "integers", float: "numbers"}.get(args[0])
            return f"a list of {plural or _type_name(args[0])}"
        return f"a list of {len(args)} numbers"
    if dataclasses.is_dataclass(tp):
        return "a mapping"
    return {int: "an integer", float: "a number", bool: "true/false", str: "a string"}.get(
        tp, str(tp)
    )


def name_problem(text: str) -> str | None:
    """Why ``text`` is not a valid scenario id or registry name (None when it is).

    One implementation for the ``id`` field, registry look-ups and ``extends:``.
    """
    if len(text) > MAX_NAME_CHARS:
        return f"expected a name of at most {MAX_NAME_CHARS} characters, got {len(text)}"
    if not _NAME.fullmatch(text):
        return (
            "expected letters, digits and '._+-' in '/'-separated parts, none starting with "
            f"'.', got {short_repr(text)}"
        )
    return None


def _text_problem(text: str, max_chars: int) -> str | None:
    if len(text) > max_chars:
        return f"expected at most {max_chars} characters, got {len(text)}"
    bad = next((c for c in text if unicodedata.category(c) in _CONTROL_CATEGORIES), None)
    if bad is not None:
        return f"expected one line of printable text, got the character U+{ord(bad):04X}"
    return None


def _convert(value: Any, tp: Any, path: str, meta: dict[str, Any], problems: Problems) -> Any:
    def bad(message: str) -> Any:
        problems.append((path, message))
        return _INVALID

    origin = typing.get_origin(tp)
    if origin in (Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        non_none = [a for a in args if a is not type(None)]
        if len(non_none) > 1:  # a number or a list (a range, a choice of levels)
            listed = isinstance(value, (list, tuple))
            arm = [a for a in non_none if (typing.get_origin(a) is tuple) == listed]
            if not arm:
                return bad(f"expected {_type_name(tp)}, got {short_repr(value)}")
            return _convert(value, arm[0], path, meta, problems)
        return _convert(value, non_none[0], path, meta, problems)
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            return bad(f"expected a mapping, got {short_repr(value)}")
        return _build(tp, value, path, problems)
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, (list, tuple)):
            return bad(f"expected {_type_name(tp)}, got {short_repr(value)}")
        if len(args) == 2 and args[1] is Ellipsis:
            most = meta.get("max_items")
            if most is not None and len(value) > most:
                return bad(f"expected at most {most} items, got {len(value)}")
            fewest = meta.get("min_items")
            if fewest is not None and len(value) < fewest:
                return bad(f"expected at least {fewest} item(s), got {len(value)}")
            item_meta = {"min": meta.get("min"), "max": meta.get("max")}
            items = [
                _convert(v, args[0], f"{path}[{i}]", item_meta, problems)
                for i, v in enumerate(value)
            ]
        else:
            if len(value) != len(args):
                return bad(f"expected {_type_name(tp)}, got {short_repr(value)}")
            items = [
                _convert(v, a, f"{path}[{i}]", meta, problems)
                for i, (v, a) in enumerate(zip(value, args, strict=True))
            ]
        return _INVALID if any(v is _INVALID for v in items) else tuple(items)
    if tp is bool:
        if not isinstance(value, bool):
            return bad(f"expected true/false, got {short_repr(value)}")
        return value
    if tp is str:
        if not isinstance(value, str):
            return bad(f"expected a string, got {short_repr(value)}")
        if meta.get("name"):
            problem = name_problem(value)
        else:
            problem = _text_problem(value, meta.get("max_chars", MAX_TEXT_CHARS))
        return value if problem is None else bad(problem)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            return bad(f"expected an integer, got {short_repr(value)}")
    elif tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return bad(f"expected a number, got {short_repr(value)}{_exponent_hint(value)}")
        if isinstance(value, float) and not math.isfinite(value):
            return bad(f"expected a finite number, got {short_repr(value)}")
    else:  # pragma: no cover - schema error, not user error
        raise TypeError(f"unsupported schema type {tp!r}")
    lo, hi = meta.get("min"), meta.get("max")
    # Compared before any conversion: Python compares a huge integer with a float exactly.
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        return bad(f"expected a value in [{lo}, {hi}], got {short_repr(value)}")
    return float(value) if tp is float else int(value)


def _exponent_hint(value: Any) -> str:
    """YAML 1.1 reads ``1e5`` and ``1.0e5`` as text: say so when a string is such a number."""
    if isinstance(value, str) and len(value) < 40 and "e" in value.lower():
        try:
            float(value)
        except ValueError:
            return ""
        return " (text: YAML reads an exponent only in the form 1.0e+5)"
    return ""


def _key_label(key: Any) -> str:
    if isinstance(key, str) and key.isprintable() and len(key) <= MAX_QUOTED_CHARS:
        return key
    return short_repr(key)


def _build(cls: Any, data: dict[Any, Any], prefix: str, problems: Problems) -> Any:
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    before = len(problems)
    for key in data:
        if key not in fields:
            label = _key_label(key)
            close = (
                difflib.get_close_matches(key, list(fields), n=1) if isinstance(key, str) else []
            )
            hint = f"; did you mean {close[0]!r}?" if close else ""
            problems.append(
                (
                    f"{prefix}.{label}" if prefix else label,
                    f"unknown key (allowed: {', '.join(sorted(fields))}){hint}",
                )
            )
    kwargs = {}
    for name, f in fields.items():
        path = f"{prefix}.{name}" if prefix else name
        unless = f.metadata.get("unless")
        if unless is not None:  # one of two alternatives (null counts as not given)
            given, other = data.get(name) is not None, data.get(unless) is not None
            if given and other:
                problems.append((path, f"expected either {unless!r} or {name!r}, not both"))
                continue
            if not given and not other:
                problems.append(
                    (path, f"missing required field ({_type_name(_non_null(hints[name]))})")
                )
                continue
        if name in data:
            kwargs[name] = _convert(data[name], hints[name], path, dict(f.metadata), problems)
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            problems.append((path, f"missing required field ({_type_name(hints[name])})"))
    return _INVALID if len(problems) > before else cls(**kwargs)


def _non_null(tp: Any) -> Any:
    """``X`` of ``X | None``."""
    args = [a for a in typing.get_args(tp) if a is not type(None)]
    return args[0] if len(args) == 1 else tp


def from_mapping(data: dict[str, Any], source: str = "") -> ScenarioConfig:
    """Build and cross-check a :class:`ScenarioConfig` from a plain mapping.

    Raises :class:`ScenarioError` carrying every problem found: first those of single fields
    (unknown keys, types, ranges, sizes), else those between fields (geometry, speeds).
    """
    if not isinstance(data, dict):
        raise ScenarioError(
            source, "", f"expected a mapping at the top level, got {short_repr(data)}"
        )
    problems: Problems = []
    cfg: ScenarioConfig = _build(ScenarioConfig, data, "", problems)
    if not problems:
        problems = _cross_problems(cfg)
    if problems:
        raise ScenarioError.of(source, problems)
    return cfg


def _inside(p: Point, size: float) -> bool:
    return 0.0 <= p[0] <= size and 0.0 <= p[1] <= size


def _length_inside(a: Airway, size: float) -> float:
    """Length (km) of the part of the airway inside the sector [0, size]^2 (Liang-Barsky)."""
    (x0, y0), (x1, y1) = a.start_km, a.end_km
    dx, dy = x1 - x0, y1 - y0
    t0, t1 = 0.0, 1.0
    for p, q in ((-dx, x0), (dx, size - x0), (-dy, y0), (dy, size - y0)):
        if p == 0.0:
            if q < 0.0:
                return 0.0
            continue
        t = q / p
        if p < 0.0:
            t0 = max(t0, t)
        else:
            t1 = min(t1, t)
    return max(0.0, t1 - t0) * math.hypot(dx, dy)


def _cross_problems(cfg: ScenarioConfig) -> Problems:
    """Checks between fields: speeds, and a geometry that fits the sector (so that ``reset``
    never meets a scenario it cannot start)."""
    out: Problems = []
    o, size = cfg.ownship, cfg.sector.size_km
    half = f"expected less than half of sector.size_km ({size / 2:g} km)"
    if o.min_speed_kt > o.max_speed_kt:
        out.append(("ownship.min_speed_kt", "expected min_speed_kt <= max_speed_kt"))
    else:
        bounds = f"expected a value in [{o.min_speed_kt}, {o.max_speed_kt}] (min/max_speed_kt)"
        if not o.min_speed_kt <= o.speed_kt <= o.max_speed_kt:
            out.append(("ownship.speed_kt", bounds))
        if o.start is not None and not o.min_speed_kt <= o.start.speed_kt <= o.max_speed_kt:
            out.append(("ownship.start.speed_kt", bounds))
    for name in ("goal_margin_km", "start_clearance_km", "goal_radius_km"):
        if 2 * getattr(o, name) >= size:
            out.append((f"ownship.{name}", half))
    if 2 * cfg.traffic.spawn_clearance_km >= size:
        out.append(("traffic.spawn_clearance_km", half))
    if cfg.separation.nmac_km > cfg.separation.los_km:
        out.append(("separation.nmac_km", "expected nmac_km <= los_km"))
    if cfg.traffic.routes > len(cfg.airways):
        out.append(
            ("traffic.routes", f"expected at most {len(cfg.airways)} (the number of airways)")
        )
    if cfg.traffic.controlled > cfg.n_route_intruders:
        out.append(
            (
                "traffic.controlled",
                f"expected at most routes x per_route = {cfg.n_route_intruders} (the airway "
                "aircraft in the sky at the start)",
            )
        )
    if cfg.traffic.controlled_spawns and not cfg.traffic.routes:
        out.append(
            ("traffic.controlled_spawns", "expected 0 without airway traffic (traffic.routes: 0)")
        )
    for i, li in enumerate(cfg.learning_intruders):
        if li.airway is not None and li.airway >= len(cfg.airways):
            out.append(
                (f"learning_intruders[{i}].airway", f"expected an index below {len(cfg.airways)}")
            )
        if li.encounter is not None:
            out += _encounter_problems(cfg, li.encounter, f"learning_intruders[{i}].encounter")
    for i, a in enumerate(cfg.airways):
        if math.dist(a.start_km, a.end_km) < 1.0:
            out.append((f"airways[{i}]", "expected distinct start and end"))
        elif _length_inside(a, size) < 1.0:
            out.append(
                (f"airways[{i}]", f"expected an airway crossing the sector [0, {size:g}] km")
            )
    inside = f"expected a point inside the sector [0, {size:g}] km"
    for i, ac in enumerate(cfg.aircraft):
        if ac.position_km is not None and not _inside(ac.position_km, size):
            out.append((f"aircraft[{i}].position_km", inside))
        if ac.encounter is not None:
            out += _encounter_problems(cfg, ac.encounter, f"aircraft[{i}].encounter")
    if o.goal_km is not None and not _inside(o.goal_km, size):
        out.append(("ownship.goal_km", inside))
    if o.start is None:
        if o.goal_km is not None:
            out.append(("ownship.goal_km", "expected no goal without an explicit 'start'"))
        return out
    if o.goal_km is None:
        out.append(("ownship.goal_km", "expected a goal when 'start' is given"))
    if not _inside(o.start.position_km, size):
        out.append(("ownship.start.position_km", inside))
    for i, ac in enumerate(cfg.aircraft):
        if (
            ac.position_km is not None
            and ac.level == o.start.level
            and math.dist(ac.position_km, o.start.position_km) < cfg.separation.nmac_km
        ):
            out.append(
                (
                    f"aircraft[{i}].position_km",
                    f"expected at least separation.nmac_km ({cfg.separation.nmac_km:g} km) from "
                    "the ownship's start at its level (an NMAC before the first step)",
                )
            )
    return out


def encounter_reach_km(cfg: ScenarioConfig, enc: Encounter) -> float:
    """Farthest distance, km, of an encounter's start from the ownship's start: the ownship
    flies ``time_to_cpa_s`` at its start speed, the aircraft at ``speed_kt``, apart by at most
    ``|miss_km|`` at the closest point of approach (needs ``ownship.start``)."""
    start = cfg.ownship.start
    assert start is not None
    t_hi = range_bounds(enc.time_to_cpa_s)[1]
    v_hi = range_bounds(enc.speed_kt)[1]
    miss = max(abs(x) for x in range_bounds(enc.miss_km))
    return (start.speed_kt + v_hi) * KM_PER_S_PER_KT * t_hi + miss


def _encounter_problems(cfg: ScenarioConfig, enc: Encounter, path: str) -> Problems:
    """Ranges ordered, distinct levels, an explicit ownship start, and every start it can draw
    inside the sector."""
    out: Problems = []
    for name in ("time_to_cpa_s", "angle_deg", "miss_km", "speed_kt"):
        lo, hi = range_bounds(getattr(enc, name))
        if lo > hi:
            out.append((f"{path}.{name}", f"expected [lo, hi] with lo <= hi, got [{lo}, {hi}]"))
    if isinstance(enc.level, tuple) and len(set(enc.level)) != len(enc.level):
        out.append((f"{path}.level", f"expected distinct levels, got {list(enc.level)}"))
    start, size = cfg.ownship.start, cfg.sector.size_km
    if start is None:
        out.append(
            (path, "expected an explicit ownship.start (an encounter is placed relative to it)")
        )
    elif not out:
        reach = encounter_reach_km(cfg, enc)
        x, y = start.position_km
        if min(x, y) - reach < 0.0 or max(x, y) + reach > size:
            out.append(
                (
                    path,
                    f"a start can be drawn up to {reach:.1f} km from the ownship's start "
                    "((ownship speed + speed_kt) x time_to_cpa_s + |miss_km|, upper bounds), "
                    f"outside the sector [0, {size:g}] km; expected shorter times or slower "
                    "speeds",
                )
            )
    return out


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
