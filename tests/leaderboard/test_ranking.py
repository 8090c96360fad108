"""The ranking by the headline score, best marks, fixed encounters and the generated conclusion,
on fabricated result files (written by the evaluator's own writer, on the registry's scenario
configs and episode seeds, so every reader accepts them): five entries whose outcomes are drawn
from one uniform number per episode, so that their paired differences are known."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cdr_bench.evaluate import results as rf
from cdr_bench.evaluate.metrics import scenario_metrics
from cdr_bench.evaluate.seeds import episode_seeds
from cdr_bench.leaderboard.data import Entry, build_data, fixed_geometry, outcome_text
from cdr_bench.leaderboard.plots import entry_styles, pareto_front, render_plots
from cdr_bench.leaderboard.published import load_published
from cdr_bench.leaderboard.render import conclusion, render_markdown
from cdr_bench.leaderboard.submission import Submission
from cdr_bench.scenarios import load_scenario
from tests.leaderboard.conftest import ROOT

N = 300
HIGH, FAMILY, FIXED = "high", "tactical/head-on", "tactical/head-on-fixed"


def _record(outcome: str, los: Any, steps: int, extra_km: float) -> dict[str, Any]:
    los = bool(los)
    ok = outcome == "success"
    return {
        "id": "ownship_0",
        "outcome": outcome,
        "steps": steps,
        "los": bool(los),
        "nmac": outcome == "nmac",
        "goal_reward": 1.0 if ok else -1.0,
        "safety_reward": -1.0 if los else 0.0,
        "invalid_actions": 0,
        "min_sep_km": 5.0 if los else 20.0,
        "severity": 0.4 if los else None,
        "los_events": int(bool(los)),
        "los_s": 10.0 if los else 0.0,
        "nmac_events": int(outcome == "nmac"),
        "conflicts": 1,
        "manoeuvres": 2,
        "flight_s": 400.0 + 10 * extra_km,
        "path_km": 100.0 + extra_km,
        "direct_km": 100.0,
        "direct_s": 400.0,
    }


def _clean(u: float, i: int, name: str) -> bool:
    return {
        "mvp": u < 0.90,
        "alpha": u < 0.89 or 0.90 <= u < 0.905,  # differs from mvp on a few episodes each way
        "beta": u < 0.60,
        "direct": u < 0.50,
        "random": u < 0.05,
    }[name]


EXTRA_KM = {"mvp": 2.0, "alpha": 1.0, "beta": 0.5, "direct": 0.0, "random": 0.1}
GROUP = {"mvp": "scripted", "alpha": "learned", "beta": "learned", "direct": "scripted"}
GROUP["random"] = "scripted"


def _episodes(name: str, sid: str, u: np.ndarray, w: np.ndarray) -> list[dict[str, Any]]:
    out = []
    for i in range(N):
        if sid == FIXED:  # one encounter: the same outcome every time, unless the agent draws
            if name == "random":
                rec = _record("success" if w[i] < 0.3 else "los", w[i] >= 0.3, 5, 0.1)
            elif name in ("mvp", "alpha"):
                rec = _record("success", False, 40, EXTRA_KM[name])
            else:
                rec = _record("los", True, 7, 0.0)
        elif name == "random" and not _clean(u[i], i, name):
            rec = _record("los", True, 3, 0.0)
        elif _clean(u[i], i, name):
            rec = _record("success", False, 20 if name == "random" else 40, EXTRA_KM[name])
        else:
            rec = _record("success", True, 41, EXTRA_KM[name])
        out.append({"episode": i, "seed": 0, "steps": rec["steps"], "aircraft": [rec]})
    return out


def _write(tmp: Path, name: str) -> Entry:
    rng = np.random.default_rng(7)
    u, w = rng.random(N), rng.random(N)
    scenarios, episodes = [], []
    for sid in (HIGH, FAMILY, FIXED):
        cfg = load_scenario(sid)
        seeds = episode_seeds(0, sid, cfg.config_hash(), 0, N)
        eps = _episodes(name, sid, u, w)
        for e, s in zip(eps, seeds, strict=True):
            e["seed"] = s
        episodes += [{"scenario": sid, **e} for e in eps]
        scenarios.append(
            {
                "id": sid,
                "config_hash": cfg.config_hash(),
                "config": cfg.to_dict(),
                "episodes": N,
                "seeds_sha256": rf.sha256_text(",".join(map(str, seeds))),
                "metrics": scenario_metrics(eps),
            }
        )
    lat = {"per_decision_ms": {"median": 0.1, "p99": 0.2}}
    result = {
        "schema_version": rf.SCHEMA_VERSION,
        "kind": rf.RESULT_KIND,
        "agent": {"name": name, "sha256": "0" * 64},
        "base_seed": 0,
        "batch_size": 200,
        "versions": {"cdr-bench": "test"},
        "episodes_file": rf.episodes_path(Path(f"{name}.json")).name,
        "scenarios": scenarios,
        "timing": {"decision_latency": {s["id"]: lat for s in scenarios}},
    }
    path = tmp / f"{name}.json"
    rf.write_results(path, result, episodes)
    sub = Submission(
        name=name,
        source=tmp / "submissions" / f"{name}.yaml",
        display_name=name.capitalize(),
        description="-",
        agent=f"agents/{name}",
        checkpoint=None,
        authors=("test",),
        reference="https://example.org",
        training=None if GROUP[name] == "scripted" else "train",
        scenarios=(HIGH, FAMILY, FIXED),
        suite=None,
        published_as=(),
        multimodality=(),
        group=GROUP[name],
    )
    return Entry(sub, path, rf.read_result(path), episodes=episodes)


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    tmp = tmp_path_factory.mktemp("fabricated")
    entries = [_write(tmp, n) for n in ("alpha", "beta", "direct", "mvp", "random")]
    return build_data(entries, load_published(ROOT / "leaderboard"), reference="mvp")


def test_ranked_by_headline_with_ties_broken_by_extra_path(data: dict[str, Any]) -> None:
    rk = data["ranking"]
    assert rk["scenario"] == "high" and rk["metric"] == "clean_success_rate"
    order = [r["entry"] for r in rk["rows"]]
    # mvp has the highest clean success, alpha is not significantly below it and flies less
    # extra path: alpha first, mvp second (tied); then by headline score
    assert order == ["alpha", "mvp", "beta", "direct", "random"]
    assert rk["tied"] == ["alpha", "mvp"]
    rows = {r["entry"]: r for r in rk["rows"]}
    assert rows["mvp"]["tied_with"] == 1 and rows["alpha"]["tied_with"] is None
    assert rk["tiers"] == [["alpha", "mvp"], ["beta"], ["direct"], ["random"]]
    assert rows["beta"]["tied_with"] is None
    assert not rows["mvp"]["vs_above"]["significant"]
    assert rows["beta"]["vs_above"]["significant"] and rows["beta"]["vs_above"]["diff"] < 0
    assert rk["runner_up"] == "beta" and rk["gap"]["significant"]
    # the per-scenario tables follow the ranking, not the success rate
    high = next(t for t in data["tables"] if t["scenario"] == "high")
    assert [r["entry"] for r in high["rows"]] == order
    assert [r["rank"] for r in high["rows"]] == [1, 2, 3, 4, 5]
    vs = {v["entry"]: v for v in rk["learned_vs_baseline"]}
    assert not vs["alpha"]["significant"] and vs["beta"]["significant"]
    # a tie group shares its first position; between groups strictly by score
    assert [r["shared_rank"] for r in rk["rows"]] == [1, 1, 3, 4, 5]
    assert rows["alpha"]["headline"]["aggregate"] == "one run"
    lo, hi = rows["alpha"]["headline"]["ci95"]
    assert lo < rows["alpha"]["headline"]["value"] < hi  # one run: episode noise, never 0-wide
    for g, nxt in zip(rk["tiers"], rk["tiers"][1:], strict=False):
        low = min(rows[e]["headline"]["value"] for e in g)
        assert all(rows[e]["headline"]["value"] <= low for e in nxt)


def test_no_best_mark_on_a_metric_that_rewards_failing(data: dict[str, Any]) -> None:
    high = next(t for t in data["tables"] if t["scenario"] == "high")
    steps = {r["entry"]: r["metrics"]["avg_steps_success"]["value"] for r in high["rows"]}
    assert min(steps, key=lambda k: steps[k]) == "random"  # random's few successes are short
    assert high["best"]["avg_steps_success"] == []
    assert high["best"]["timeout_rate"] == [] and high["best"]["goal_reward"] == []
    assert high["best"]["clean_success_rate"] == ["mvp"]
    assert high["best"]["los_rate"] == ["mvp"]
    md = render_markdown(data, load_published(ROOT / "leaderboard"), [])
    random_row = next(line for line in md.splitlines() if line.startswith("| 5 | Random |"))
    assert "**" not in random_row


def test_conclusion_names_leader_tie_significance_and_baseline(data: dict[str, Any]) -> None:
    text = " ".join(conclusion(data))
    assert text.startswith(
        "**Alpha** (a learned agent) ranks first on the headline score, clean success on `high`"
    )
    assert "(one run, 300 episodes; 95 % two-level bootstrap" in text
    assert "Its lead is not significant: in its tie group" in text
    assert "the group is ordered by extra path (Alpha 1.00 km, Mvp 2.00 km)" in text
    assert "Every other entry is significantly below the top score: the best of them, Beta" in (
        text
    )
    assert "against Mvp (95 % paired bootstrap" in text
    assert (
        "of the 2 learned agents that learn from scratch 1 is not significantly different from "
        "it (Alpha)"
    ) in text
    assert "; 1 is significantly below it (Beta)" in text
    assert "Holm-corrected over the 2 tests" in text
    assert "Direct, which never manoeuvres, succeeds in 100.0%" in text


def test_fixed_encounter_shows_single_outcome_family_an_interval(data: dict[str, Any]) -> None:
    tac = {t["scenario"]: t for t in data["tactical"]}
    assert tac[FAMILY]["fixed"] is False and tac[FIXED]["fixed"] is True
    fam = tac[FAMILY]["cells"]["random"]
    assert fam["kind"] == "rate" and fam["ci95"][0] < fam["value"] < fam["ci95"][1]
    cells = tac[FIXED]["cells"]
    assert cells["beta"] == {"kind": "outcome", "text": "LoS at step 7", "outcome": "los"}
    assert cells["mvp"]["text"] == "success"
    assert cells["random"]["kind"] == "varies" and "ci95" not in cells["random"]
    md = render_markdown(data, load_published(ROOT / "leaderboard"), [])
    table = md.split("## Tactical scenarios", 1)[1].split("##", 1)[0]
    beta = next(line for line in table.splitlines() if "| Beta |" in line)
    fam_cell, fixed_cell = beta.strip("|").split("|")[2:4]
    assert "% [" in fam_cell and fixed_cell.strip() == "LoS at step 7"
    # the fixed scenario's own table has no intervals either
    fixed_table = md.split(f"### {FIXED}", 1)[1].split("###", 1)[0]
    assert "fixed encounter" in fixed_table and "% [" not in fixed_table


def test_fixed_geometry_resets_the_simulator() -> None:
    for sid, fixed in ((FIXED, True), (FAMILY, False), ("low", False)):
        cfg = load_scenario(sid)
        s = {"id": sid, "config_hash": cfg.config_hash(), "config": cfg.to_dict(), "episodes": 50}
        assert fixed_geometry(s, 0) is fixed, sid


def test_outcome_text() -> None:
    assert outcome_text({"outcome": "los", "steps": 7, "los": True}) == "LoS at step 7"
    assert outcome_text({"outcome": "success", "steps": 30, "los": True}) == ("success after a LoS")
    assert outcome_text({"outcome": "nmac", "steps": 3, "los": True}) == "NMAC at step 3"


def test_pareto_front_and_styles(data: dict[str, Any]) -> None:
    pts = [("a", 1.0, 5.0), ("b", 2.0, 2.0), ("c", 3.0, 3.0), ("d", 0.5, 9.0), ("e", 2.0, 2.5)]
    assert pareto_front(pts) == ["d", "a", "b"]
    styles = entry_styles(data)
    pairs = {(s["color"], s["marker"]) for s in styles.values()}
    assert len(pairs) == len(styles) == 5
    assert len({s["marker"] for s in styles.values()}) == 5


def test_plots(data: dict[str, Any]) -> None:
    """Headline plots first; the tactical plot shows the family only (byte determinism of the
    plots: tests/leaderboard/test_build.py rebuilds and compares)."""
    a = render_plots(data)
    assert list(a)[:1] == ["pareto.png"] and "tactical_success_rate.png" in a
    assert all(png.startswith(b"\x89PNG") for png in a.values())


def test_an_interval_that_excludes_zero_never_reads_as_reaching_it() -> None:
    """A bound that one decimal would print as 0.0 keeps its sign and a significant digit (the
    ranking's MVP row was shown as -0.8 pp [-1.6, +0.0] ▼ for an upper bound of -0.04 pp)."""
    from cdr_bench.leaderboard.page_tables import fmt_diff, signed

    d = {"diff": -0.0078, "ci95": [-0.0164, -0.0004], "significant": True}
    assert fmt_diff("rate", d) == "-0.8 pp [-1.6, -0.04] ▼"
    assert [signed(x) for x in (0.0, -0.0, 0.04, -0.049, 1.26)] == [
        "+0.0",
        "+0.0",
        "+0.04",
        "-0.05",
        "+1.3",
    ]
