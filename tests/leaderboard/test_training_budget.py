"""The ranking's training columns: the scenario(s) an entry was trained on (its submission's
``trained_on``) and its total training budget, a parent run's transitions included (an entry
whose seeds continue another entry's run, ``parent: NAME seed K``)."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import pytest

from cdr_bench.leaderboard.data import add_parent_budgets, total_transitions
from cdr_bench.leaderboard.page_tables import fmt_budget
from cdr_bench.leaderboard.submission import Seed

ROOT = Path(__file__).resolve().parents[2]


def _entry(name: str, parents: list[str | None]) -> SimpleNamespace:
    seeds = tuple(Seed(k + 1, f"c{k}.pt", f"l{k}.jsonl", p) for k, p in enumerate(parents))
    return SimpleNamespace(name=name, sub=SimpleNamespace(seeds=seeds))


def _budget(t: int | list[int] | None, seeds: int = 3) -> dict:
    return {"transitions": t, "seeds": seeds, "source": "training logs"}


def test_a_continued_run_counts_its_parents_transitions() -> None:
    entries = [
        _entry("step-1", [None, None, None]),
        _entry("step-2", ["step-1 seed 1"] * 3),
        _entry("scratch", [None, None]),
    ]
    info = {
        "step-1": (_budget(500_000), [], []),
        "step-2": (_budget(400_000), [], []),
        "scratch": (_budget(1_000_000, 2), [], []),
    }
    add_parent_budgets(entries, info)  # type: ignore[arg-type]
    b = info["step-2"][0]
    assert b["parent_transitions"] == 500_000 and b["parent"] == "step-1"
    assert total_transitions(b) == 900_000
    assert fmt_budget(b) == ("900,000 (500,000 of its parent + 400,000)", "3")
    for name in ("step-1", "scratch"):
        assert "parent_transitions" not in info[name][0]
        assert total_transitions(info[name][0]) == info[name][0]["transitions"]


def test_unknown_or_mixed_parents_add_nothing() -> None:
    entries = [_entry("a", ["gone seed 1"]), _entry("b", ["x seed 1", "y seed 1"])]
    info = {
        "a": (_budget(10), [], []),
        "b": (_budget(10), [], []),
        "x": (_budget(5), [], []),
        "y": (_budget(5), [], []),
    }
    add_parent_budgets(entries, info)  # type: ignore[arg-type]
    assert "parent_transitions" not in info["a"][0] and "parent_transitions" not in info["b"][0]


@pytest.mark.artefacts
def test_the_committed_ranking_shows_training_scenario_and_total_budget() -> None:
    data = json.loads((ROOT / "leaderboard" / "leaderboard.json").read_text())
    ent = {e["name"]: e for e in data["entries"]}
    step2, step1 = ent["mvp-improve-2"]["budget"], ent["mvp-improve"]["budget"]
    assert step2["parent"] == "mvp-improve"
    assert step2["parent_transitions"] == step1["transitions"]
    assert ent["diffusion-ac"]["trained_on"].startswith("the DPSC curriculum")
    assert ent["ppo"]["trained_on"] == "medium" and ent["mvp"]["trained_on"] is None
    readme = (ROOT / "leaderboard" / "README.md").read_text()
    assert "| trained on | training transitions (total) | seeds |" in readme
    total = step1["transitions"] + step2["transitions"]
    assert f"| high | {total:,} ({step1['transitions']:,} of its parent + " in readme
