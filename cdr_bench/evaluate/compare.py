"""Paired comparison of two results run on the same episodes (``cdr-bench compare A B``).

The comparison runs on the scenarios both results hold (or those named with ``--scenario``),
each with the same config hash, episode count and episode seeds in both (common random
numbers); anything else is refused. For each scenario, aircraft role and
metric of the registry (:data:`cdr_bench.evaluate.metrics.METRICS`) the difference B - A comes
with a 95 % paired percentile-bootstrap interval: episodes are resampled jointly for both agents
(2000 resamples), and a metric is the ratio of per-episode sums of its facts
(:meth:`~cdr_bench.evaluate.metrics.Metric.paired`; so learning intruders are resampled as whole
episodes). Each scenario's resampled episodes come from a generator seeded with the sha256 of
its id (:func:`scenario_indices`), so a scenario's interval is the same whichever other
scenarios are compared (``--scenario high`` alone, all of them, or the leaderboard's claims).
A metric that is one yes/no outcome per episode (:data:`BINARY`: success, clean success, LoS on
the ownship) also gets McNemar's exact test (:func:`mcnemar_exact`: the two-sided binomial test
of the discordant episodes, on exact integers); :func:`holm` adjusts the p-values of a
statement that combines several tests.

Where the episodes have several controlled aircraft (the multi-agent scenarios), the system
metrics (:data:`cdr_bench.evaluate.metrics.SYSTEM_METRICS`: clean flights, LoS and NMAC per
flight hour over every pair, delay, who pays) are compared too, in rows of ``aircraft``
``system``: the same paired bootstrap over whole episodes, of the ratio of the per-episode
numerators and denominators the system metric sums
(:meth:`~cdr_bench.evaluate.metrics.Metric.compute_system`).
"""

from __future__ import annotations

import functools
import hashlib
import math
import os
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cdr_bench.errors import UserError
from cdr_bench.evaluate.metrics import (
    BOOTSTRAP_RESAMPLES,
    BOOTSTRAP_SEED,
    METRICS,
    ROLES,
    SYSTEM_METRICS,
    get_metric,
    role_of,
)
from cdr_bench.evaluate.results import read_episodes, read_result


def _sums(
    episodes: list[dict[str, Any]], role: str, names: list[str]
) -> dict[str, NDArray[np.float64]]:
    mine = [[ac for ac in ep["aircraft"] if role_of(ac["id"]) == role] for ep in episodes]
    out = {}
    for name in names:
        paired = get_metric(name).paired
        nd = np.zeros((len(episodes), 2))
        for i, acs in enumerate(mine):
            for ac in acs:
                num, den = paired(ac)
                nd[i, 0] += num
                nd[i, 1] += den
        out[name] = nd
    return out


def scenario_seed(sid: str, salt: str = "") -> int:
    """The bootstrap seed of one scenario: ``BOOTSTRAP_SEED`` and the scenario's id (``salt``
    appended) hashed with sha256, so a scenario's resampled episodes do not depend on which
    other scenarios are compared, nor on their order."""
    h = hashlib.sha256(f"{BOOTSTRAP_SEED}/{sid}{salt}".encode()).digest()
    return int.from_bytes(h[:8], "big")


@functools.lru_cache(maxsize=64)
def scenario_indices(sid: str, n: int) -> NDArray[np.int64]:
    """The resampled positions ``(BOOTSTRAP_RESAMPLES, n)`` of scenario ``sid``, from a generator
    seeded by :func:`scenario_seed`: the same for every pair of results and every subset of
    compared scenarios (``compare A B --scenario high`` and the leaderboard give the same
    interval), so drawn once per scenario (read-only)."""
    rng = np.random.default_rng(scenario_seed(sid))
    idx = rng.integers(0, n, (BOOTSTRAP_RESAMPLES, n))
    idx.flags.writeable = False
    return idx


BINARY = frozenset({"success_rate", "clean_success_rate", "los_rate", "nmac_rate"})
"""Metrics that are one yes/no outcome per episode for the ownship (one aircraft per episode):
their paired comparison also gets McNemar's exact test (when every episode's fact is 0 or 1)."""


def measurable(b: int, c: int, tests: int = 1, alpha: float = 0.05) -> bool:
    """Whether ``b + c`` discordant episodes could reject at ``alpha`` even if all fell on one
    side, after a Holm correction over ``tests`` tests (its strictest step): with fewer, the
    test cannot decide and a claim resting on it is "not measurable", not "not held"."""
    return tests * mcnemar_exact(b + c, 0) < alpha


def mcnemar_exact(b: int, c: int) -> float:
    """McNemar's exact test: the two-sided binomial test (p = 1/2) of ``b`` against ``c``, the
    discordant pairs (A yes, B no) and (A no, B yes); computed on exact integers and fractions
    (``scipy.stats.binomtest(b, b + c).pvalue``). 1 when there is no discordant pair."""
    if b < 0 or c < 0:
        raise ValueError(f"discordant counts must be >= 0, got {b}, {c}")
    n, k = b + c, min(b, c)
    if n == 0 or b == c:
        return 1.0
    tail = sum(math.comb(n, i) for i in range(k + 1))
    return float(min(Fraction(1), Fraction(2 * tail, 2**n)))


def holm(pvalues: list[float]) -> list[float]:
    """Holm's step-down adjusted p-values (same order as given): the i-th smallest times
    ``m - i`` (i from 0), made non-decreasing, capped at 1. A statement that combines ``m``
    tests holds at 5 % for the tests whose adjusted p-value is below 0.05."""
    m = len(pvalues)
    order = sorted(range(m), key=lambda i: pvalues[i])
    out = [0.0] * m
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * pvalues[i]))
        out[i] = running
    return out


def _discordant(na: NDArray[np.float64], nb: NDArray[np.float64]) -> tuple[int, int] | None:
    """``(b, c)``: episodes A yes / B no and A no / B yes, when both sides are one 0/1 outcome per
    episode (a denominator of 1 and a numerator of 0 or 1 everywhere); None otherwise."""
    for nd in (na, nb):
        if not (np.all(nd[:, 1] == 1) and np.all((nd[:, 0] == 0) | (nd[:, 0] == 1))):
            return None
    a, b = na[:, 0] == 1, nb[:, 0] == 1
    return int(np.sum(a & ~b)), int(np.sum(~a & b))


def _ratio(nd: NDArray[np.float64], idx: NDArray[np.int64] | None = None) -> Any:
    if idx is None:
        d = nd[:, 1].sum()
        return nd[:, 0].sum() / d if d > 0 else np.nan
    # gathered from a contiguous column: the same (resamples, n) array as nd[idx, 0], faster,
    # so the same sums
    num = np.ascontiguousarray(nd[:, 0])[idx].sum(axis=-1)
    den = np.ascontiguousarray(nd[:, 1])[idx].sum(axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1), np.nan)


def _roles(episodes: list[dict[str, Any]]) -> list[str]:
    """The roles flown in these episodes, in :data:`~cdr_bench.evaluate.metrics.ROLES` order
    (the order of a result's ``metrics``)."""
    seen = {role_of(ac["id"]) for ep in episodes for ac in ep["aircraft"]}
    return [r for r in ROLES if r in seen]


_LOADED: dict[tuple[str, int, int], tuple[dict[str, Any], list[dict[str, Any]]]] = {}


def _load(path: str | os.PathLike[str]) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """A result and its episodes, read (and verified) once per file version: the leaderboard
    compares each result with many others."""
    p = Path(path).resolve()
    st = p.stat() if p.is_file() else None
    key = (str(p), st.st_mtime_ns if st else -1, st.st_size if st else -1)
    if key not in _LOADED:
        result = read_result(path, metrics=False)  # the comparison reads the episodes only
        _LOADED[key] = (result, read_episodes(path, result))
    return _LOADED[key]


def compare(
    path_a: str | os.PathLike[str],
    path_b: str | os.PathLike[str],
    scenarios: list[str] | None = None,
    metrics: list[str] | None = None,
) -> dict[str, Any]:
    """Per-metric paired differences B - A on the scenarios both hold (or ``scenarios``), for
    every metric or those named in ``metrics`` (the same numbers either way: the resampled
    episodes are drawn per scenario); :class:`UserError` if a compared scenario is not on the
    same episodes."""
    known = [m.key for m in (*METRICS, *SYSTEM_METRICS)]
    names = known if metrics is None else list(dict.fromkeys(metrics))
    unknown = [m for m in names if m not in known]
    if unknown:
        raise UserError(f"unknown metric(s) {unknown}; known: {', '.join(known)}")
    try:
        (a, ea), (b, eb) = _load(path_a), _load(path_b)
    except ValueError as e:
        raise UserError(str(e)) from None
    all_a = {s["id"]: s for s in a["scenarios"]}
    all_b = {s["id"]: s for s in b["scenarios"]}
    notes = []
    if scenarios:
        for sid in scenarios:
            for path, have in ((path_a, all_a), (path_b, all_b)):
                if sid not in have:
                    raise UserError(f"--scenario {sid}: not in {path} (it holds {', '.join(have)})")
        keep = list(dict.fromkeys(scenarios))
    else:
        keep = [s for s in all_a if s in all_b]
        if not keep:
            raise UserError(
                f"no scenario in common: {', '.join(all_a)} in {path_a} vs "
                f"{', '.join(all_b)} in {path_b}"
            )
        dropped = sorted((set(all_a) | set(all_b)) - set(keep))
        if dropped:
            notes.append(
                f"compared on {', '.join(keep)} only ({', '.join(dropped)}: in one result)"
            )
    sa = {k: all_a[k] for k in keep}
    sb = {k: all_b[k] for k in keep}
    for sid in sa:
        for key in ("config_hash", "episodes", "seeds_sha256"):
            if sa[sid][key] != sb[sid][key]:
                raise UserError(
                    f"not the same episodes: scenario {sid} differs in {key} "
                    f"({sa[sid][key]} vs {sb[sid][key]}); run both with the same scenario "
                    "version, --episodes and --seed"
                )
    pairs = {}
    for sid in sa:
        xa = [e for e in ea if e["scenario"] == sid]
        xb = [e for e in eb if e["scenario"] == sid]
        if [e["seed"] for e in xa] != [e["seed"] for e in xb]:
            raise UserError(f"not the same episodes: per-episode seeds of {sid} differ")
        pairs[sid] = (xa, xb)
    rows = []
    for sid, (xa, xb) in pairs.items():
        idx = scenario_indices(sid, len(xa))
        roles_b = _roles(xb)
        for role in _roles(xa):
            if role not in roles_b:
                continue
            shown = [n for n in names if get_metric(n).scope == "aircraft"]
            na, nb = _sums(xa, role, shown), _sums(xb, role, shown)
            for name in shown:
                row = _paired_row((sid, role, name), na[name], nb[name], idx)
                rows.append({**row, **_mcnemar(name, na[name], nb[name])})
        if max(len(e["aircraft"]) for e in xa) > 1:  # several controlled aircraft
            system = [n for n in names if get_metric(n).scope == "system"]
            rows += _system_rows(sid, xa, xb, idx, system)
    notes += _undefined_notes(rows)
    return {
        "a": {"path": str(path_a), "agent": a["agent"]["name"]},
        "b": {"path": str(path_b), "agent": b["agent"]["name"]},
        "scenarios": keep,
        "notes": notes,
        "rows": rows,
    }


def _system_sums(episodes: list[dict[str, Any]], key: str) -> NDArray[np.float64]:
    """``(episodes, 2)``: the per-episode numerator and denominator the system metric ``key``
    sums over a scenario (exposure in hours for a rate per hour)."""
    m = get_metric(key)
    assert m.over is not None  # a system metric always has its denominator
    nd = np.array(
        [[float(m.value(e["aircraft"])), float(m.over(e["aircraft"]))] for e in episodes],
        dtype=float,
    ).reshape(-1, 2)
    if m.aggregate == "per_h":
        nd[:, 1] /= 3600.0
    return nd


def _system_rows(
    sid: str,
    xa: list[dict[str, Any]],
    xb: list[dict[str, Any]],
    idx: NDArray[np.int64],
    keys: list[str],
) -> list[dict[str, Any]]:
    """The paired differences B - A of the system metrics ``keys`` on scenario ``sid`` (whole
    episodes resampled with ``idx``, as the aircraft rows)."""
    rows = []
    for key in keys:
        rows.append(
            _paired_row((sid, "system", key), _system_sums(xa, key), _system_sums(xb, key), idx)
        )
    return rows


def _paired_row(
    where: tuple[str, str, str], na: NDArray[np.float64], nb: NDArray[np.float64], idx: Any
) -> dict[str, Any]:
    """One row of the comparison: at ``where`` (scenario ``sid``, ``who``: a role or
    ``system``, metric ``key``), the values of A and B (ratios of the per-episode sums ``na``,
    ``nb``), B - A and its 95 % paired percentile-bootstrap interval over the resampled
    episodes ``idx``."""
    sid, who, key = where
    va, vb = float(_ratio(na)), float(_ratio(nb))
    diffs = _ratio(nb, idx) - _ratio(na, idx)
    diffs = diffs[np.isfinite(diffs)]
    lo, hi = (
        (float(np.percentile(diffs, 2.5)), float(np.percentile(diffs, 97.5)))
        if diffs.size
        else (np.nan, np.nan)
    )
    undefined = [side for side, v in (("A", va), ("B", vb)) if v != v]
    return {
        "scenario": sid,
        "aircraft": who,
        "metric": key,
        "a": va,
        "b": vb,
        "diff": vb - va,
        "ci95": [lo, hi],
        "significant": bool(lo > 0 or hi < 0),
        **({"undefined": undefined} if undefined else {}),
    }


def _mcnemar(name: str, na: NDArray[np.float64], nb: NDArray[np.float64]) -> dict[str, Any]:
    """``{"mcnemar": {b, c, p}}`` for a binary metric (:data:`BINARY`), else nothing."""
    if name not in BINARY:
        return {}
    bc = _discordant(na, nb)
    if bc is None:
        return {}
    return {"mcnemar": {"b": bc[0], "c": bc[1], "p": mcnemar_exact(*bc)}}


def _why_undefined(key: str) -> str:
    """Why ``key`` has no value for a group of episodes: its denominator is zero."""
    m = next((m for m in (*METRICS, *SYSTEM_METRICS) if m.key == key), None)
    if m is None:
        return "no episode it counts"
    what = {
        "rate": "no trial to count it over",
        "mean": "no episode it is averaged over",
        "per_h": "no flight time to count it over",
    }.get(m.aggregate, "no episode it counts")
    return f"{what} ({m.doc.rstrip('.')})" if m.doc else what


def _undefined_notes(rows: list[dict[str, Any]]) -> list[str]:
    """One note per metric and side that has no value somewhere, naming where and why: the
    table shows ``n/a`` there, and the difference and its interval are undefined too."""
    where: dict[tuple[str, str], list[str]] = {}
    for r in rows:
        for side in r.get("undefined", []):
            where.setdefault((r["metric"], side), []).append(f"{r['scenario']}/{r['aircraft']}")
    notes = []
    for (key, side), places in where.items():
        shown = ", ".join(places[:4]) + (f" and {len(places) - 4} more" if len(places) > 4 else "")
        notes.append(
            f"{key} cannot be computed for {side} on {shown}: {_why_undefined(key)}; shown as "
            "n/a, with no difference"
        )
    return notes


def _fmt(spec: str, x: float) -> str:
    return "n/a" if x != x else spec.format(x)


def _fmt_mcnemar(m: dict[str, Any] | None) -> str:
    return "" if m is None else f"{m['p']:.3g} ({m['b']}/{m['c']})"


def comparison_table(cmp: dict[str, Any]) -> str:
    a, b = cmp["a"]["agent"], cmp["b"]["agent"]
    head = [
        "scenario", "aircraft", "metric", f"A={a}", f"B={b}", "B-A", "95% paired CI", "",
        "McNemar p (A+/B-, A-/B+)",
    ]  # fmt: skip
    rows = [head]
    kinds = {m.key: m.kind for m in (*METRICS, *SYSTEM_METRICS)}
    for r in cmp["rows"]:
        pct = kinds.get(r["metric"], "") == "rate"
        vf, df = ("{:.1f}%", "{:+.1f}") if pct else ("{:.3f}", "{:+.3f}")
        scale = 100 if pct else 1
        lo, hi = r["ci95"]
        rows.append(
            [
                r["scenario"],
                r["aircraft"],
                r["metric"],
                _fmt(vf, scale * r["a"]),
                _fmt(vf, scale * r["b"]),
                _fmt(df, scale * r["diff"]),
                f"[{_fmt(df, scale * lo)}, {_fmt(df, scale * hi)}]",
                "*" if r["significant"] else "",
                _fmt_mcnemar(r.get("mcnemar")),
            ]
        )
    w = [max(len(r[i]) for r in rows) for i in range(len(head))]
    return "\n".join("  ".join(c.ljust(x) for c, x in zip(r, w, strict=True)) for r in rows)
