"""The sensitivity study (paper Fig. 7) read from landed sweep trials: the per-factor rule of
its claims, the centre trial counted in every factor, and bad inputs as clear errors."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from cdr_bench.errors import UserError
from cdr_bench.leaderboard import sensitivity as sens

ROOT = Path(__file__).resolve().parents[2]
FIXED = {"T": 10, "polyak": 0.005, "critic-width": 128, "total-steps": 100000}


def _trial(d: Path, key: str, factor: str, label: str, seed: int, success: float) -> None:
    t = d / key
    t.mkdir(parents=True)
    flags = dict(FIXED)
    if factor in FIXED:
        flags[factor] = float(label) if "." in label else int(label)
    (t / "trial.json").write_text(
        json.dumps(
            {
                "factor": factor,
                "label": label,
                "seed": seed,
                "result": "result.json",
                "train_flags": flags,
            }  # fmt: skip
        )
    )
    metrics = {
        "success_rate": {"value": min(1.0, success + 0.1)},  # the paper's metric, not judged
        "clean_success_rate": {"value": success},
        "nmac_rate": {"value": 0.0},
        "goal_reward": {"value": success},
        "safety_reward": {"value": -1.0},
    }
    scen = [{"id": s, "episodes": 10, "metrics": {"ownship": metrics}} for s in ("low", "high")]
    (t / "result.json").write_text(json.dumps({"scenarios": scen}))


def _grid(tmp: Path, t_values: dict[str, list[float]], n: int = 3) -> Path:
    """Trials of the T factor (``label -> clean success per seed``; "10" is the centre trial)."""
    d = tmp / "trials"
    for label, per_seed in t_values.items():
        for seed, v in enumerate(per_seed[:n], start=1):
            factor = "default" if label == "10" else "T"
            _trial(d, f"{factor}-{label}-{seed}", factor, "default" if factor == "default"
                   else label, seed, v)  # fmt: skip
    return d


def _lb(tmp: Path, trials: Path) -> Path:
    lb = tmp / "lb"
    (lb / "published").mkdir(parents=True)
    shutil.copy(ROOT / "leaderboard" / "published" / "fig7.yaml", lb / "published" / "fig7.yaml")
    (lb / "sensitivity.yaml").write_text(f"trials: {Path('..') / trials.name}\n")
    return lb


def _claim(tmp: Path, grid: dict[str, list[float]], n: int = 3) -> dict[str, str]:
    lb = _lb(tmp, _grid(tmp, grid, n))
    rows = {r["id"]: r for r in sens.claim_rows(sens.load_study(lb))}
    return rows["fig7-T"]


BASE = {"8": [0.50, 0.52, 0.51], "20": [0.80, 0.81, 0.79], "40": [0.7] * 3, "80": [0.7] * 3}


def test_held_when_best_in_range_and_every_seed_above_those_outside(tmp_path: Path) -> None:
    row = _claim(tmp_path, {**BASE, "10": [0.6, 0.62, 0.61]})
    assert row["verdict"] == "held", row
    assert "best at 20" in row["measured"]
    assert "20: 80.0 % ± 0.8 (3; success 90.0 %)" in row["measured"]
    assert row["measured"].startswith("early training: 100,000 transitions per trial; clean")
    assert row["test"].startswith("on clean success: ")


def test_judged_on_clean_success_not_on_success(tmp_path: Path) -> None:
    """The verdict is the clean success's (best at 8, outside the paper's values), and the
    trials' budget is stated against the reference entry's."""
    trials = _grid(tmp_path, {**BASE, "10": [0.6, 0.62, 0.61], "8": [0.95] * 3})
    lb = _lb(tmp_path, trials)
    row = {r["id"]: r for r in sens.claim_rows(sens.load_study(lb), 1_000_000)}["fig7-T"]
    assert row["verdict"] == "not held" and "best at 8, outside" in row["measured"]
    assert "(10 % of the reference Diffusion-AC's 1,000,000)" in row["measured"]


def test_not_held_when_best_is_outside_the_papers_values(tmp_path: Path) -> None:
    row = _claim(tmp_path, {**BASE, "8": [0.9, 0.91, 0.92], "10": [0.6] * 3})
    assert row["verdict"] == "not held"
    assert "best at 8, outside" in row["measured"]


def test_not_held_when_one_seed_overlaps_a_value_outside(tmp_path: Path) -> None:
    # best mean at 20, but one seed of 20 is below one seed of 8: U > 0
    row = _claim(tmp_path, {**BASE, "8": [0.50, 0.52, 0.78], "20": [0.77, 0.9, 0.9],
                            "10": [0.6] * 3})  # fmt: skip
    assert row["verdict"] == "not held"
    assert "not separated from 8" in row["measured"]


def test_not_measured_until_every_value_has_three_seeds(tmp_path: Path) -> None:
    row = _claim(tmp_path, {**BASE, "10": [0.6] * 3}, n=2)
    assert row["verdict"] == "not measured"
    assert "waiting for 3 seeds at 8, 10, 20, 40, 80" in row["measured"]


def test_centre_trial_counts_in_factors_without_trials_of_their_own(tmp_path: Path) -> None:
    lb = _lb(tmp_path, _grid(tmp_path, {"10": [0.6, 0.7, 0.8]}))
    st = sens.load_study(lb)
    assert st is not None
    by = {f["factor"]: f for f in st["factors"]}
    pts = {p["value"]: p for p in by["polyak"]["points"]}
    assert pts["0.005"]["seeds"] == [1, 2, 3] and pts["0.001"]["seeds"] == []
    assert pts["0.001"]["paper"] == -100.4 and pts["0.005"]["recommended"]
    # the temperature column has no numeric centre (its default anneals): no point for it
    assert [p["value"] for p in by["temperature"]["points"]] == ["0.1", "1", "5", "10"]
    # the paper's value without a trial of ours is shown, ours without a paper value too
    assert pts["0.01"]["mean"] is None


def test_no_study_file_means_one_not_measured_claim(tmp_path: Path) -> None:
    assert sens.load_study(tmp_path) is None
    (row,) = sens.claim_rows(None)
    assert row["verdict"] == "not measured"


@pytest.mark.parametrize(
    ("break_it", "words"),
    [
        (lambda d, lb: (lb / "sensitivity.yaml").write_text("trials: nowhere\n"),
         ["sensitivity.yaml", "trials", "not a folder"]),
        (lambda d, lb: (lb / "sensitivity.yaml").write_text("trials: ../trials\nextra: 1\n"),
         ["sensitivity.yaml", "exactly one field"]),
        (lambda d, lb: (d / "T-8-1" / "trial.json").write_text('{"factor": "T"}'),
         ["T-8-1/trial.json", "'label'", "expected str"]),
        (lambda d, lb: (d / "T-8-1" / "trial.json").write_text(
            (d / "T-8-1" / "trial.json").read_text().replace('"result.json"', '"../../x.json"')),
         ["T-8-1/trial.json", "outside the trial's folder"]),
        (lambda d, lb: (d / "T-8-1" / "result.json").write_text('{"scenarios": [{}]}'),
         ["T-8-1/result.json", "not a cdr-bench result file"]),
        (lambda d, lb: (d / "T-8-1" / "result.json").write_text("{"),
         ["T-8-1/result.json", "cannot read"]),
        (lambda d, lb: (lb / "published" / "fig7.yaml").write_text(
            (lb / "published" / "fig7.yaml").read_text().replace("metric: reward", "metric: x")),
         ["fig7.yaml", "factors.polyak.metric", "success_rate, reward"]),
        (lambda d, lb: (lb / "published" / "fig7.yaml").write_text(
            (lb / "published" / "fig7.yaml").read_text().replace("8: 84.62", "8: high")),
         ["fig7.yaml", "factors.T.values.8", "expected a number"]),
    ],
)  # fmt: skip
def test_bad_inputs_are_clear_errors(tmp_path: Path, break_it, words: list[str]) -> None:  # type: ignore[no-untyped-def]
    d = _grid(tmp_path, {**BASE, "10": [0.6] * 3})
    lb = _lb(tmp_path, d)
    break_it(d, lb)
    with pytest.raises(UserError) as e:
        sens.load_study(lb)
    for w in words:
        assert w in str(e.value), (w, str(e.value))


def test_committed_study_matches_the_landed_trials() -> None:
    """The leaderboard's section is what the landed trials give (no stale copy)."""
    data = json.loads((ROOT / "leaderboard" / "leaderboard.json").read_text())
    assert data["sensitivity"] == sens.load_study(ROOT / "leaderboard")
