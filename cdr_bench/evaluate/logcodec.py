"""The stored form of a per-episode log: the same facts without the fields other fields give.

A per-episode log (:mod:`cdr_bench.evaluate.results`) is one canonical JSON line per episode; its
SHA-256 (``episodes_sha256``) is over that text, and every reader sees that text. What is stored
(inside the xz, :func:`cdr_bench.evaluate.results.compress_log`) may leave out, line by line,
a field whose value follows from the line itself, the line before it or a header line:

=================  ============================================================================
field              left out when it equals
=================  ============================================================================
``scenario``       the line before's
``episode``        the line before's + 1 (0 at the first line of a scenario)
``seed``           :func:`cdr_bench.evaluate.seeds.derive_seed` of the header's base seed and
                   the scenario's configuration hash (only where the writer states them)
``steps``          the largest of the aircraft's ``steps``
aircraft ``id``    the header's identifier for that position in that scenario
aircraft ``steps`` the number of decisions (``len(actions)``)
``manoeuvres``     the decisions other than hold (``d``)
``los``/``nmac``   ``los_events > 0`` / ``nmac_events > 0``
``path_km``        ``direct_km`` (a flight that never left its direct route)
``direct_s``       ``flight_s``
=================  ============================================================================

The first stored line is then a header (``{"cdr-bench log": 1, ...}``, the key order of the
records and the derivation inputs). :func:`encode` returns the stored text only if
:func:`decode` gives back the input byte for byte, and the input itself otherwise (any log the
rules do not fit: other keys, another key order, other number types); so the stored form is
lossless by construction and a reader needs no other file. These derived fields are about half
of what an xz-compressed log holds (most of it the 63-bit episode seeds).

A damaged or hostile stored form is a ``ValueError`` (the caller names the file); what it
decodes to is checked by the caller against ``episodes_sha256`` like any log text.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

from cdr_bench.evaluate.seeds import derive_seed

TAG = "cdr-bench log"
VERSION = 1
HOLD_CODE = "d"
"""``ACTION_CODE[HOLD]`` (:data:`cdr_bench.evaluate.runner.ACTION_CODE`, action 13)."""

MAX_AIRCRAFT_PER_LINE = 4096
"""A stored line of more aircraft is refused (with identifiers of at most 64 characters, a line
cannot expand without bound)."""
_EPISODE_KEYS = ("scenario", "episode", "seed", "steps", "aircraft")


def _dumps(obj: Any) -> str:
    return json.dumps(obj, separators=(",", ":"))


def _same(a: Any, b: Any) -> bool:
    """Equal as JSON text would be (``True`` is not ``1``, ``1.0`` is not ``1``)."""
    return type(a) is type(b) and a == b


class _Rules:
    """The derivations, given a header (``ids``: scenario -> aircraft identifiers; ``seeds``:
    scenario -> [base seed, configuration hash])."""

    def __init__(self, header: Mapping[str, Any]) -> None:
        self.ids: Mapping[str, list[str]] = header.get("ids") or {}
        self.seeds: Mapping[str, list[Any]] = header.get("seeds") or {}
        self.aircraft_keys: list[str] = list(header.get("aircraft_keys") or [])

    def aircraft(self, scenario: Any, k: int, rec: dict[str, Any]) -> dict[str, Any]:
        """Derived values of one aircraft's record (from its stored fields)."""
        out: dict[str, Any] = {}
        ids = self.ids.get(scenario) if isinstance(scenario, str) else None
        if ids is not None and k < len(ids):
            out["id"] = ids[k]
        actions = rec.get("actions")
        if isinstance(actions, str):
            out["steps"] = len(actions)
            out["manoeuvres"] = len(actions) - actions.count(HOLD_CODE)
        for flag, events in (("los", "los_events"), ("nmac", "nmac_events")):
            if isinstance(rec.get(events), int):
                out[flag] = rec[events] > 0
        if "direct_km" in rec:
            out["path_km"] = rec["direct_km"]
        if "flight_s" in rec:
            out["direct_s"] = rec["flight_s"]
        return out

    def seed(self, scenario: Any, episode: Any) -> int | None:
        s = self.seeds.get(scenario) if isinstance(scenario, str) else None
        if s is None or not isinstance(episode, int) or isinstance(episode, bool):
            return None
        return derive_seed(s[0], scenario, s[1], episode)


def _max_steps(aircraft: Any) -> int | None:
    """The largest ``steps`` of the aircraft records (``None`` unless all are integers)."""
    if not isinstance(aircraft, list):
        return None
    steps = [a.get("steps") if isinstance(a, dict) else None for a in aircraft]
    ints = [s for s in steps if isinstance(s, int) and not isinstance(s, bool)]
    return max(ints) if ints and len(ints) == len(steps) else None


_MISSING = object()
_DERIVED_AIRCRAFT = ("id", "steps", "manoeuvres", "los", "nmac", "path_km", "direct_s")


def _expand_aircraft(
    rules: _Rules, scenario: Any, k: int, rec: Any, plans: dict[tuple[str, ...], Any]
) -> Any:
    """One aircraft's full record from its stored one; ``plans`` caches, per stored key
    sequence, which template keys are stored and which derived (the decoder's hot loop)."""
    if not isinstance(rec, dict):
        return rec
    shape = tuple(rec)
    plan = plans.get(shape, _MISSING)
    if plan is _MISSING:
        stored = set(shape)
        plan = [
            (key, key in stored)
            for key in rules.aircraft_keys
            if key in stored or key in _DERIVED_AIRCRAFT
        ]
        plan += [(key, True) for key in shape if key not in rules.aircraft_keys]
        if all(is_stored for _, is_stored in plan):
            plan = None  # nothing to derive: the record as stored
        plans[shape] = plan
    if plan is None:
        return rec
    derived = rules.aircraft(scenario, k, rec)
    return {
        key: rec[key] if is_stored else derived[key]
        for key, is_stored in plan
        if is_stored or key in derived
    }


def _expand(
    rules: _Rules, rec: dict[str, Any], prev: tuple[Any, Any], plans: dict[tuple[str, ...], Any]
) -> dict[str, Any]:
    scenario = rec.get("scenario", prev[0])
    episode = rec["episode"] if "episode" in rec else (prev[1] + 1 if scenario == prev[0] else 0)
    aircraft = rec.get("aircraft")
    if isinstance(aircraft, list):
        aircraft = [_expand_aircraft(rules, scenario, k, a, plans) for k, a in enumerate(aircraft)]
    derived: dict[str, Any] = {"scenario": scenario, "episode": episode}
    if "aircraft" in rec:
        derived["aircraft"] = aircraft
    seed = rules.seed(scenario, episode)
    if seed is not None:
        derived["seed"] = seed
    steps = _max_steps(aircraft)
    if steps is not None:
        derived["steps"] = steps
    out = {}
    for key in _EPISODE_KEYS:
        if key in rec or key in derived:
            out[key] = rec[key] if key in rec and key != "aircraft" else derived[key]
    for key, value in rec.items():
        if key not in out:
            out[key] = value
    return out


def _compact(rules: _Rules, rec: dict[str, Any], prev: tuple[Any, Any]) -> dict[str, Any]:
    scenario, episode = rec.get("scenario"), rec.get("episode")
    out: dict[str, Any] = {}
    for key, value in rec.items():
        if key == "scenario" and prev[0] is not None and _same(value, prev[0]):
            continue
        if key == "episode" and isinstance(value, int) and not isinstance(value, bool):
            if value == (prev[1] + 1 if scenario == prev[0] else 0):
                continue
        if key == "seed" and _same(value, rules.seed(scenario, episode)):
            continue
        if key == "steps":
            if _same(value, _max_steps(rec.get("aircraft"))):
                continue
        if key == "aircraft" and isinstance(value, list):
            value = [
                {
                    k: v
                    for k, v in a.items()
                    if not _same(v, rules.aircraft(scenario, i, a).get(k, _MISSING))
                }
                if isinstance(a, dict)
                else a
                for i, a in enumerate(value)
            ]
        out[key] = value
    return out


def encode(text: str, seeds: Mapping[str, tuple[int, str]] | None = None) -> str:
    """The stored form of the log ``text`` (see the module docstring), or ``text`` itself when
    the rules do not give it back exactly. ``seeds``: scenario id -> (base seed, configuration
    hash) of the run, so that episode seeds derived the documented way are left out."""
    if not text.endswith("\n") or text.startswith('{"' + TAG):
        return text
    try:
        records = [json.loads(line) for line in text[:-1].split("\n")]
    except (json.JSONDecodeError, RecursionError):
        return text
    if not records or not all(isinstance(r, dict) for r in records):
        return text
    ids: dict[str, list[str]] = {}
    aircraft_keys: list[str] = []
    for r in records:
        aircraft, scenario = r.get("aircraft"), r.get("scenario")
        if not isinstance(aircraft, list) or not isinstance(scenario, str):
            return text
        if not aircraft_keys and aircraft and isinstance(aircraft[0], dict):
            aircraft_keys = list(aircraft[0])
        names: list[Any] = [a.get("id") if isinstance(a, dict) else None for a in aircraft]
        known = ids.setdefault(scenario, [])
        if all(isinstance(n, str) for n in names) and names[: len(known)] == known[: len(names)]:
            known.extend(names[len(known) :])
    header = {
        TAG: VERSION,
        "aircraft_keys": aircraft_keys,
        "ids": ids,
        "seeds": {k: [int(b), str(h)] for k, (b, h) in (seeds or {}).items()},
    }
    rules = _Rules(header)
    lines = [_dumps(header)]
    prev: tuple[Any, Any] = (None, -1)
    for r in records:
        lines.append(_dumps(_compact(rules, r, prev)))
        prev = (r.get("scenario"), r.get("episode"))
    stored = "\n".join(lines) + "\n"
    try:
        if decode(stored, len(text)) != text:
            return text
    except ValueError:
        return text
    return stored


def records(stored: str) -> list[dict[str, Any]]:
    """The records of a log, stored form or plain JSON lines (without building its text:
    what every reader of a result needs); ``ValueError`` if it is damaged."""
    if not stored.startswith('{"' + TAG + '"'):
        try:
            return [json.loads(line) for line in stored.split("\n") if line.strip()]
        except (json.JSONDecodeError, RecursionError) as e:
            raise ValueError(f"a line is not JSON ({str(e)[:80]})") from None
    try:
        head, _, body = stored.partition("\n")
        rules = _Rules(_header(json.loads(head)))
        plans: dict[tuple[str, ...], Any] = {}
        out: list[dict[str, Any]] = []
        prev: tuple[Any, Any] = (None, -1)
        for line in body.split("\n"):
            if not line:
                continue
            rec = json.loads(line)
            if not isinstance(rec, dict):
                raise ValueError("a stored log line that is not a JSON object")
            if len(rec.get("aircraft") or ()) > MAX_AIRCRAFT_PER_LINE:
                raise ValueError(f"a stored log line of more than {MAX_AIRCRAFT_PER_LINE} aircraft")
            full = _expand(rules, rec, prev, plans)
            prev = (full.get("scenario"), full.get("episode"))
            if not isinstance(prev[1], int) or isinstance(prev[1], bool):
                raise ValueError("a stored log line without an episode number")
            out.append(full)
        return out
    except (json.JSONDecodeError, RecursionError, TypeError, KeyError, AttributeError) as e:
        raise ValueError(f"a damaged stored log ({str(e)[:80]})") from None


def decode(stored: str, limit: int) -> str:
    """The log text of a stored form (``stored`` itself if it has no header); ``ValueError`` if
    it is damaged or expands past ``limit`` characters."""
    if not stored.startswith('{"' + TAG + '"'):
        return stored
    lines, size = [], 0
    for r in records(stored):
        lines.append(_dumps(r) + "\n")
        size += len(lines[-1])
        if size > limit:
            raise ValueError(f"expands past {limit} characters")
    return "".join(lines)


def _header(header: Any) -> dict[str, Any]:
    """A stored form's header, checked (``ValueError`` otherwise)."""
    if not isinstance(header, dict) or header.get(TAG) != VERSION:
        raise ValueError(f"a stored log of another version ({str(header)[:40]})")
    ids, seeds, keys = header.get("ids"), header.get("seeds"), header.get("aircraft_keys")
    if not (isinstance(ids, dict) and isinstance(seeds, dict) and isinstance(keys, list)):
        raise ValueError("a stored log header without ids, seeds or aircraft_keys")
    for names in ids.values():
        if not (isinstance(names, list) and all(_short_str(n) for n in names)):
            raise ValueError("a stored log header with a malformed aircraft identifier")
    for v in seeds.values():
        if not (isinstance(v, list) and len(v) == 2 and isinstance(v[0], int)):
            raise ValueError("a stored log header with a malformed seed entry")
        if not _short_str(v[1]):
            raise ValueError("a stored log header with a malformed configuration hash")
    if not all(_short_str(k) for k in keys):
        raise ValueError("a stored log header with a malformed aircraft key")
    return header


def _short_str(x: Any) -> bool:
    return isinstance(x, str) and len(x) <= 64


def restore_files(paths: list[str]) -> int:
    """Rewrite the per-episode log of each result JSON in ``paths`` in its stored form (what
    :func:`cdr_bench.evaluate.results.write_results` writes now) and the JSON's
    ``episodes_sha256`` with it. The log's facts are unchanged: the JSON's hash must be that
    of the log as it was stored or of its text, and the stored form gives the text back.
    Returns the bytes saved."""
    import json
    from pathlib import Path

    from cdr_bench.evaluate import results as rf

    saved = 0
    for name in paths:
        p = Path(name)
        result = json.loads(p.read_text())
        log = p.parent / result["episodes_file"]
        text = rf.log_text(log)
        if result["episodes_sha256"] not in (
            rf.sha256_text(text),
            rf.sha256_text(rf.stored_text(log)),
        ):
            raise ValueError(f"{p}: its log does not match it")
        seeds = {
            str(s["id"]): (int(result["base_seed"]), str(s["config_hash"]))
            for s in result["scenarios"]
        }
        stored = encode(text, seeds)
        if decode(stored, len(text)) != text:  # pragma: no cover - encode checks it
            raise ValueError(f"{log}: the stored form does not give the log back")
        data = rf.compress_log(stored)
        before = log.stat().st_size
        rf.atomic_write_text(log, data)
        rf.atomic_write_text(
            p, json.dumps({**result, "episodes_sha256": rf.sha256_text(stored)}, indent=1) + "\n"
        )
        saved += before - len(data)
        print(f"{log}: {before} -> {len(data)} bytes")
    return saved


if __name__ == "__main__":
    import sys

    print(f"saved {restore_files(sys.argv[1:])} bytes")
