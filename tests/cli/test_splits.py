"""Validation and test episodes apart: ``cdr-bench evaluate`` and sweeps evaluate on validation by
default, a sweep cannot evaluate on the leaderboard's test set, and no landed sweep did."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from cdr_bench.errors import UserError
from cdr_bench.evaluate.seeds import SPLITS, TEST_SEED, split_of
from cdr_bench.scale.config import load_sweep
from tests.cli.test_evaluate_cli import AGENTS, cdr, evaluate  # noqa: F401 (fixture)
from tests.scale.helpers import tiny_sweep

ROOT = Path(__file__).resolve().parents[2]


def test_the_splits_are_three_distinct_base_seeds() -> None:
    assert SPLITS == {"validation": 1, "validation-0": 0, "test": 20261127}
    assert {split_of(v) for v in SPLITS.values()} == set(SPLITS) and split_of(7) is None


@pytest.mark.parametrize(
    "extra, seed, split",
    [((), 1, "validation"), (("--split", "test"), TEST_SEED, "test"), (("--seed", 7), 7, None)],
)
def test_evaluate_runs_on_validation_unless_told(cdr, tmp_path, extra, seed, split) -> None:  # noqa: F811
    r = evaluate(cdr, AGENTS / "direct", tmp_path / "r.json", *extra, episodes=2)
    assert r.returncode == 0, r.stderr
    doc = json.loads((tmp_path / "r.json").read_text())
    assert (doc["base_seed"], doc["split"]) == (seed, split)


def test_split_and_seed_together_are_refused(cdr, tmp_path) -> None:  # noqa: F811
    r = evaluate(cdr, AGENTS / "direct", tmp_path / "r.json", "--split", "test", "--seed", 1)
    assert r.returncode == 2 and "--split and --seed both name the episodes" in r.stderr


def _sweep(tmp_path: Path, evaluation: dict) -> Path:
    path = tiny_sweep(tmp_path, [1])
    doc = yaml.safe_load(path.read_text())
    doc["evaluation"] = {"scenarios": ["tactical/head-on"], "episodes": 2, **evaluation}
    path.write_text(yaml.safe_dump(doc))
    return path


def test_sweeps_evaluate_on_validation_and_never_on_test(tmp_path) -> None:
    assert load_sweep(_sweep(tmp_path, {})).evaluation["seed"] == SPLITS["validation"]
    assert load_sweep(_sweep(tmp_path, {"split": "validation-0"})).evaluation["seed"] == 0
    for bad in ({"split": "test"}, {"seed": TEST_SEED}):
        with pytest.raises(UserError, match="the test episodes score a finished"):
            load_sweep(_sweep(tmp_path, bad))


@pytest.mark.artefacts
def test_no_landed_sweep_saw_the_test_episodes() -> None:
    seeds = {
        json.loads(p.read_text()).get("base_seed")
        for p in (ROOT / "sweeps" / "landed").rglob("*.json")
        if p.name in ("result.json", "args.json") and "base_seed" in p.read_text()
    }
    assert seeds and TEST_SEED not in seeds
