"""The multi-agent track: entries flying every controlled aircraft, ranked apart by the share of
clean flights on ``marl/high-all``; submissions that mix the tracks are refused."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from cdr_bench.evaluate.results import log_text
from cdr_bench.leaderboard.submission import SubmissionError, load_submission

from .conftest import ROOT, cdr

MARL = "[marl/low-2, marl/high-all]"
EPISODES = 8


def _marl_yaml(agent: str, name: str) -> str:
    return (
        f"display_name: {name}\nagent: {agent}\nauthors: [test]\n"
        "reference: https://example.org/paper\ntraining: null\n"
        f"scenarios: {MARL}\ntrack: multi-agent\n"
    )


@pytest.fixture(scope="module")
def marl_repo(evaluated_repo: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The miniature repository with two multi-agent entries scored (8 episodes)."""
    root = tmp_path_factory.mktemp("marl") / "repo"
    shutil.copytree(evaluated_repo, root)
    for name in ("mvp", "mvp_reciprocal"):
        (root / "agents" / name).mkdir()
        shutil.copy(ROOT / "agents" / name / "agent.py", root / "agents" / name / "agent.py")
    subs = root / "leaderboard" / "submissions"
    (subs / "mvp-all.yaml").write_text(_marl_yaml("agents/mvp/agent.py", "MVP all"))
    (subs / "recip.yaml").write_text(_marl_yaml("agents/mvp_reciprocal/agent.py", "Recip"))
    r = cdr(
        "leaderboard", "build", "--evaluate", "mvp-all", "recip", "--episodes", EPISODES,
        "--reference", "weave", "--workers", 1, cwd=root, timeout=600,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    return root


def test_multi_agent_entries_are_ranked_apart_on_clean_flights(marl_repo: Path) -> None:
    lb = marl_repo / "leaderboard"
    data = json.loads((lb / "leaderboard.json").read_text())
    single = {e["name"] for e in data["entries"]}
    assert single == {"direct", "weave"}  # the single-agent tables never hold them
    track = data["multi_agent"]
    assert track["scenario"] == "marl/high-all" and track["metric"] == "system_clean_rate"
    assert [r["entry"] for r in track["ranking"]] != []
    assert {r["entry"] for r in track["ranking"]} == {"mvp-all", "recip"}
    # the score is the ratio of sums over the episodes of the result file, recomputed here
    eps = [json.loads(line) for line in log_text(lb / "results" / "recip.jsonl.xz").splitlines()]
    high = [e for e in eps if e["scenario"] == "marl/high-all"]
    flights = sum(len(e["aircraft"]) for e in high)
    clean = sum(a["outcome"] == "success" and not a["los"] for e in high for a in e["aircraft"])
    row = next(r for r in track["ranking"] if r["entry"] == "recip")
    assert row["score"]["value"] == pytest.approx(clean / flights, abs=1e-6)
    lo, hi = row["score"]["ci95"]
    assert lo <= row["score"]["value"] <= hi
    assert row["vs_baseline"] is not None and "significant" in row["vs_baseline"]
    assert [t["scenario"] for t in track["tables"]] == ["marl/low-2", "marl/high-all"]
    readme = (lb / "README.md").read_text()
    assert "## Multi-agent track: every aircraft controlled" in readme
    assert "clean flights on marl/high-all" in readme
    html = (lb / "index.html").read_text()
    assert 'id="multi-agent"' in html and 'id="table-multi-agent"' in html


@pytest.mark.slow
def test_check_replays_and_reruns_the_multi_agent_entries(marl_repo: Path) -> None:
    r = cdr(
        "leaderboard", "build", "--check", "--evaluate", "mvp-all", "recip", "--reference", "weave",
        "--fresh-episodes", 200,
        "--all-seeds", "--workers", 1, cwd=marl_repo, timeout=600,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "200 fresh episodes of each track's headline scenario" in r.stderr
    assert "mvp-all: 200 fresh marl/high-all episodes" in r.stderr
    assert "recip: agent re-run on marl/high-all batch 0" in r.stderr


@pytest.mark.parametrize(
    ("scenarios", "track", "field", "says"),
    [
        ("paper", "multi-agent", "scenarios[0]", "one controlled aircraft"),
        ("[marl/low-2, marl/high-all]", "single-agent", "scenarios[0]", "track: multi-agent"),
        ("[marl/low-2]", "multi-agent", "scenarios", "ranks on 'marl/high-all'"),
        ("marl", "both", "track", "expected one of single-agent, multi-agent"),
    ],
)
def test_a_submission_in_the_wrong_track_is_refused(
    tmp_path: Path, scenarios: str, track: str, field: str, says: str
) -> None:
    (tmp_path / "agents").mkdir()
    (tmp_path / "agents" / "a.py").write_text("")
    src = tmp_path / "x.yaml"
    src.write_text(
        "agent: agents/a.py\nauthors: [t]\nreference: https://example.org\ntraining: null\n"
        f"scenarios: {scenarios}\ntrack: {track}\n"
    )
    with pytest.raises(SubmissionError) as e:
        load_submission(src, tmp_path)
    assert e.value.field == field and says in str(e.value)
