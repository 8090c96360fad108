"""One metric registry (cdr_bench.evaluate.metrics): every metric is defined once, and a metric
registered at run time over facts already in the per-episode records is computed when a result
is read, is a column of the per-result tables and of ``leaderboard.json`` (and of the pages when
it is not a detail column), and is compared by ``cdr-bench compare`` -- without a result file
changing (files hold facts; metrics are computed at read time)."""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from cdr_bench.evaluate import metrics, report
from cdr_bench.evaluate.compare import compare, comparison_table
from cdr_bench.evaluate.metrics import (
    Metric,
    get_metric,
    group_metrics,
    register_metric,
    unregister_metric,
    wilson_interval,
)
from cdr_bench.evaluate.results import read_episodes, read_result
from cdr_bench.leaderboard import page_tables
from tests.leaderboard import conftest as lb_conftest
from tests.leaderboard.conftest import snapshot

evaluated_repo = lb_conftest.evaluated_repo
"""The miniature leaderboard of tests/leaderboard (a session fixture: evaluated once)."""
repo = lb_conftest.repo
"""A private copy of it."""

MANOEUVRED = Metric(
    "manoeuvred_rate",
    "manoeuvred",
    "rate",
    False,
    lambda r: r["manoeuvres"] > 0,
    doc="Flights with at least one decision other than hold.",
)
"""A detail column: the share of flights with at least one manoeuvre."""

MIN_SEP = Metric(
    "min_sep_km",
    "min sep km",
    "mean",
    True,
    lambda r: r["min_sep_km"],
    lambda r: r["min_sep_km"] is not None,
    detail=False,
    doc="Smallest separation of a flight from any same-level aircraft.",
)
"""A main column (on the leaderboard's pages): the mean minimum separation."""


@pytest.fixture
def registered(request: pytest.FixtureRequest) -> Iterator[Metric]:
    m: Metric = request.param
    register_metric(m)
    try:
        yield m
    finally:
        unregister_metric(m.key)


def _results(lb: Path) -> list[Path]:
    return sorted(p for p in (lb / "results").glob("*.json") if "multimodal" not in p.name)


def _render(lb: Path, monkeypatch: pytest.MonkeyPatch, plots: bool) -> dict[str, bytes]:
    from cdr_bench.leaderboard import plots as plots_module
    from cdr_bench.leaderboard.build import render_all

    if not plots:
        monkeypatch.setattr(plots_module, "render_plots", lambda data: {})
    return render_all(lb, lb / "results", "weave")


def _records(path: Path, sid: str) -> list[dict[str, Any]]:
    eps = read_episodes(path, read_result(path))
    return [ac for e in eps if e["scenario"] == sid for ac in e["aircraft"]]


def test_every_metric_is_registered_once_and_group_metrics_computes_them() -> None:
    keys = [m.key for m in metrics.METRICS]
    assert len(keys) == len(set(keys))
    assert [c.key for c in report.COLUMNS] == keys
    assert [c.key for c in page_tables.MAIN_COLUMNS] == [
        m.key for m in metrics.METRICS if not m.detail
    ]
    assert set(metrics.PAPER_FIVE) | set(metrics.FIELD_METRICS) <= set(keys)
    rec = {
        "outcome": "success",
        "steps": 10,
        "los": False,
        "nmac": False,
        "goal_reward": 1.0,
        "safety_reward": 0.0,
        "invalid_actions": 1,
        "los_events": 0,
        "los_s": 0.0,
        "severity": None,
        "conflicts": 0,
        "path_km": 5.0,
        "direct_km": 4.0,
        "flight_s": 60.0,
        "direct_s": 50.0,
        "manoeuvres": 2,
        "nmac_events": 0,
    }
    assert list(group_metrics([rec])) == ["episodes", *keys]
    with pytest.raises(ValueError, match="already defined"):
        register_metric(get_metric("success_rate"))
    with pytest.raises(ValueError, match="built in"):
        unregister_metric("success_rate")


def test_paired_terms_follow_the_aggregate() -> None:
    ok = {"outcome": "success", "los": True, "steps": 7, "invalid_actions": 2}
    assert get_metric("los_rate").paired(ok) == (1.0, 1.0)  # a binary outcome per episode
    assert get_metric("invalid_action_rate").paired(ok) == (2.0, 7.0)  # over decisions
    assert get_metric("avg_steps_success").paired(ok) == (7.0, 1.0)  # the value where it counts
    assert get_metric("avg_steps_success").paired({**ok, "outcome": "nmac"}) == (0.0, 0.0)
    per_h = get_metric("nmac_per_flight_hour").paired({"nmac_events": 1, "flight_s": 1800.0})
    assert per_h == (1.0, 0.5)
    assert get_metric("success_rate").point([ok, {**ok, "outcome": "timeout"}]) == 0.5
    assert math.isnan(get_metric("avg_steps_success").point([{**ok, "outcome": "nmac"}]))


@pytest.mark.slow
@pytest.mark.parametrize("registered", [MANOEUVRED], indirect=True)
def test_a_registered_metric_is_in_every_table_and_no_file_changes(
    registered: Metric, repo: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    lb = repo / "leaderboard"
    before = snapshot(lb)
    key, paths = registered.key, _results(lb)
    assert paths

    # computed when a result is read, with its Wilson interval
    result = read_result(paths[0])
    sid = result["scenarios"][0]["id"]
    recs = _records(paths[0], sid)
    k = sum(r["manoeuvres"] > 0 for r in recs)
    m = result["scenarios"][0]["metrics"]["ownship"][key]
    assert (m["count"], m["n"]) == (k, len(recs))
    assert m["value"] == round(k / len(recs), 6)
    assert m["ci95"] == [round(x, 6) for x in wilson_interval(k, len(recs))]

    # the per-result tables: a detail column (wide summary and report), not the compact one
    wide = report.summary_text(result, wide=True)
    assert "manoeuvred" in wide.splitlines()[1]
    assert "manoeuvred" not in report.summary_text(result)
    md = report.report_markdown([(str(paths[0]), result)])
    head = md.split("\n\n")[2].splitlines()[0].split(" | ")
    assert "manoeuvred" in head
    assert report.fmt_metric("rate", m) in md  # "x.x% [lo, hi]"

    # cdr-bench compare
    cmp = compare(lb / "results" / "direct.json", lb / "results" / "weave.json")
    rows = [r for r in cmp["rows"] if r["metric"] == key]
    assert len(rows) == len(cmp["scenarios"])
    assert all(r["ci95"][0] <= r["diff"] <= r["ci95"][1] for r in rows)
    assert key in comparison_table(cmp)

    # leaderboard.json: every scenario table has it with value and interval; the pages (main
    # columns only) do not
    files = _render(lb, monkeypatch, plots=False)
    data = json.loads(files["leaderboard.json"])
    for t in data["tables"]:
        for row in t["rows"]:
            got = row["metrics"][key]
            assert got["value"] is not None and None not in got["ci95"]
            assert got["ci95"][0] <= got["value"] <= got["ci95"][1]
    assert "manoeuvred" not in files["README.md"].decode()

    assert snapshot(lb) == before  # no result file (nor anything else) changed


@pytest.mark.slow
@pytest.mark.parametrize("registered", [MIN_SEP], indirect=True)
def test_a_registered_main_metric_is_a_column_of_the_pages(
    registered: Metric, repo: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    lb = repo / "leaderboard"
    before = snapshot(lb)
    files = _render(lb, monkeypatch, plots=True)
    data = json.loads(files["leaderboard.json"])
    ref = data["reference"]
    for t in data["tables"]:
        for row in t["rows"]:
            got = row["metrics"]["min_sep_km"]
            assert got["value"] is not None and got["value"] > 0
            vs = row["vs_reference"]["min_sep_km"]
            assert vs == "reference" if row["entry"] == ref else "diff" in vs
    assert "min sep km" in files["README.md"].decode()
    assert "<th>min sep km</th>" in files["index.html"].decode()
    assert "plots/min_sep_km.png" in files  # the per-density plot of a main column
    assert snapshot(lb) == before


def test_unregistered_metric_is_gone() -> None:
    assert "manoeuvred_rate" not in {m.key for m in metrics.METRICS}
    assert "min_sep_km" not in {c.key for c in report.COLUMNS}
