"""``cdr-bench leaderboard build`` from result files, ``--check`` on untampered and tampered
leaderboards, and the all-or-nothing behaviour with misbehaving submissions."""

from __future__ import annotations

import json
import re
import textwrap
from pathlib import Path

import pytest

from cdr_bench.evaluate.results import compress_log, log_text, read_result, sha256_text
from tests.leaderboard.conftest import (
    EPISODES,
    NO_FRESH,
    SCENARIOS,
    cdr,
    snapshot,
    submission_yaml,
)

CHECK = ("leaderboard", "build", "--check", "--reference", "weave", "--workers", 1, *NO_FRESH)
"""The check of the miniature leaderboard, for the tests of its pages and files (no entry flies
fresh episodes: tests/leaderboard/test_verify.py tests those)."""


def test_build_renders_tables_plots_and_is_deterministic(repo: Path) -> None:
    lb = repo / "leaderboard"
    before = snapshot(lb)
    for name in ("README.md", "index.html", "leaderboard.json"):
        (lb / name).unlink()
    r = cdr("leaderboard", "build", "--reference", "weave", cwd=repo)
    assert r.returncode == 0, r.stderr
    after = snapshot(lb)
    assert after == before  # same bytes as the build that evaluated: a function of the results

    readme = (lb / "README.md").read_text()
    for sid in SCENARIOS:
        assert f"### {sid}" in readme
    data = json.loads((lb / "leaderboard.json").read_text())
    low = next(t for t in data["tables"] if t["scenario"] == "low")
    assert {r["entry"] for r in low["rows"]} == {"direct", "weave"}
    assert all(r["episodes"] == EPISODES for r in low["rows"])
    # the paired comparison with the reference comes from the evaluator's compare()
    direct = next(r for r in low["rows"] if r["entry"] == "direct")
    assert direct["vs_reference"]["success_rate"]["significant"] in (True, False)
    assert next(r for r in low["rows"] if r["entry"] == "weave")["vs_reference"]["los_rate"] == (
        "reference"
    )
    assert "Weave (reference)" in readme
    # every table follows the ranking by the headline score (clean success on high)
    rk = data["ranking"]
    assert (rk["scenario"], rk["metric"]) == ("high", "clean_success_rate")
    order = [r["entry"] for r in rk["rows"]]
    for t in data["tables"]:
        assert [r["entry"] for r in t["rows"]] == order
    high = next(t for t in data["tables"] if t["scenario"] == "high")
    heads = [r["metrics"]["clean_success_rate"]["value"] for r in high["rows"]]
    if rk["rows"][1]["tied_with"] is None:
        assert heads[0] > heads[1]
    assert readme.index("## In one minute") < readme.index("## Ranking: clean success on high")
    top = next(e["display_name"] for e in data["entries"] if e["name"] == rk["leader"])
    assert f"**{top}** (" in readme and ") ranks first on the headline score" in readme
    # the best value of a marked column is bold on the row that holds it; never on steps
    for key in ("success_rate", "los_rate"):
        for name in low["best"][key]:
            row = next(r for r in low["rows"] if r["entry"] == name)
            v = row["metrics"][key]["value"]
            assert all(
                (o["metrics"][key]["value"] <= v)
                if key == "success_rate"
                else (o["metrics"][key]["value"] >= v)
                for o in low["rows"]
            )
    assert all(t["best"]["avg_steps_success"] == [] for t in data["tables"])
    # budget and seeds from the training logs; a scripted entry has none
    budget = {e["name"]: e["budget"] for e in data["entries"]}
    assert budget["direct"] is None
    assert budget["weave"] == {"transitions": 10000, "seeds": 2, "source": "training logs"}
    assert "| 10,000 | 2 |" in readme
    # the fixed encounter is one outcome, the family a rate with its interval
    tac = {t["scenario"]: t for t in data["tactical"]}
    assert tac["tactical/head-on-fixed"]["fixed"] and not tac["tactical/head-on"]["fixed"]
    assert all(c["kind"] == "rate" for c in tac["tactical/head-on"]["cells"].values())
    assert all(c["kind"] == "outcome" for c in tac["tactical/head-on-fixed"]["cells"].values())
    # replays recorded by the scorer for both entries, one file each
    assert data["replays"]["entries"] and sorted(data["replays"]["entries"]) == ["direct", "weave"]
    rp = json.loads((lb / "results" / "weave.replays.json").read_text())
    assert sorted(rp["traces"]) == ["tactical/head-on", "tactical/head-on-fixed"]
    fixed = rp["traces"]["tactical/head-on-fixed"]
    assert [t["episode"] for t in fixed] == [0, 1, 2]
    first = next(
        json.loads(x)
        for x in log_text(lb / "results" / "weave.jsonl.xz").splitlines()
        if '"scenario":"tactical/head-on-fixed"' in x
    )
    assert fixed[0]["seed"] == first["seed"]
    assert fixed[0]["outcomes"][0] == first["aircraft"][0]["outcome"]
    assert len(fixed[0]["frames"]) == first["steps"] + 1

    # published numbers in their own sections, marked published, beside the entry that names
    # them; never in a measured table
    beside = re.search(
        r"^### The paper's Table 2 on high — published.*?(?=^##)", readme, re.M | re.S
    )
    assert beside and "| PPO | high | 93.3 |" in beside.group(0)
    paper = re.search(r"^## Published numbers.*?(?=^## Plots)", readme, re.M | re.S)
    assert paper and "| PPO | low | 100 |" in paper.group(0)
    claims = re.search(r"^## Claims of the paper.*?(?=^## )", readme, re.M | re.S)
    assert claims and "| published | measured here | verdict |" in claims.group(0)
    ours = readme.replace(beside.group(0), "").replace(paper.group(0), "")
    ours = ours.replace(claims.group(0), "")
    assert "| PPO |" not in ours and "93.3" not in ours
    assert "Weave — published as “PPO” (Table 2)" in readme
    plots = {p.name for p in (lb / "plots").glob("*.png")}
    assert {"success_rate.png", "pareto.png", "learning_curves.png", "latency.png"} <= plots
    assert "learning_curves_fixed.png" in plots  # the weave logs have curve/ lines
    data = json.loads((lb / "leaderboard.json").read_text())
    (weave,) = [c for c in data["learning_curves"] if c["entry"] == "weave"]
    assert weave["fixed"] == [
        [[0, 0.1], [5000, 0.3], [10000, 0.5]],
        [[0, 0.2], [5000, 0.4], [10000, 0.6]],
    ]
    for p in plots:
        assert f"plots/{p}" in readme
    html = (lb / "index.html").read_text()
    assert sorted(re.findall(r'<img alt="[^"]*" src="plots/([^"]+)"', html)) == sorted(plots)
    assert not re.search(r'(src|href)="(https?:)?//', html), "external asset in index.html"


@pytest.mark.slow
def test_check_reproduces_everything_but_a_tampered_line(repo: Path) -> None:
    """One check re-evaluates every submission: the only difference it reports is the line
    edited by hand, so the results, the other pages and the rest of README.md were reproduced.
    (That an untampered leaderboard passes is also CI's own check of the real one.)"""
    lb = repo / "leaderboard"
    readme = (lb / "README.md").read_text()
    m = re.search(r"\| 1 \| [^|]+ \| (?:\*\*)?(\d+\.\d)%", readme)
    assert m
    tampered = readme.replace(m.group(0), m.group(0).replace(m.group(1), "99.9"), 1)
    assert tampered != readme
    (lb / "README.md").write_text(tampered)
    r = cdr(*CHECK, cwd=repo)
    assert r.returncode == 1
    assert "check FAILED" in r.stderr
    assert "--- committed/README.md" in r.stderr and "+++ now/README.md" in r.stderr
    assert "99.9%" in r.stderr
    failed = r.stderr[r.stderr.index("check FAILED") :].split("\n\n")[1:]  # one per diff
    assert len(failed) == 1 and failed[0].startswith("--- committed/README.md"), failed
    changed = [x for x in failed[0].splitlines()[2:] if x[:1] in "+-"]
    assert len(changed) == 2 and "99.9%" in changed[0] and "99.9%" not in changed[1], failed


def test_check_fails_on_tampered_result_file(repo: Path) -> None:
    """A per-episode log edited without its hash: every reader refuses the pair. (Edits with
    the hash recomputed are caught by the replay: tests/leaderboard/test_verify.py.)"""
    lb = repo / "leaderboard"
    log = lb / "results" / "direct.jsonl.xz"
    text = log_text(log).replace('"outcome":"', '"outcome":"x', 1)
    log.write_bytes(compress_log(text))
    r = cdr(*CHECK, cwd=repo)
    assert r.returncode == 1
    assert "results/direct.json" in r.stderr
    assert "does not match it (episodes_sha256 differs" in r.stderr
    # plain build refuses it too, and writes nothing
    before = snapshot(lb)
    r = cdr("leaderboard", "build", "--reference", "weave", cwd=repo)
    assert r.returncode == 2 and "direct.json" in r.stderr
    assert snapshot(lb) == before


BAD_AGENTS = {
    "crash": (
        "class Agent:\n"
        "    def __init__(self, o, a): pass\n"
        "    def act(self, obs):\n"
        "        raise RuntimeError('boom at step')\n",
        [],
        "boom at step",
    ),
    "garbage": (
        "import sys\n"
        "sys.stdout.write('\\x1b[2J\\x00\\x07' * 200)\n"
        "class Agent:\n"
        "    def __init__(self, o, a): pass\n"
        "    def act(self, obs):\n"
        "        print('\\x1b[31mGARBAGE\\x00')\n"
        "        return 'left please'\n",
        [],
        "invalid action",
    ),
    "hang": (
        "import time\ntime.sleep(600)\nclass Agent:\n    pass\n",
        ["--timeout", "4"],
        "wall-clock limit of 4 s",
    ),
    "spin": (
        "while True:\n    pass\n",
        ["--cpu-limit", "2"],
        "the CPU time limit",
    ),
    "hog": (
        "blob = bytearray(8 * 1024 ** 3)\nclass Agent:\n    pass\n",
        ["--memory-limit", "2048"],
        "MemoryError",
    ),
    "pickle": (
        "import pickle, os\n"
        "class Agent:\n"
        "    def __init__(self, o, a): self.p = pickle.loads(pickle.dumps(os.getcwd))\n"
        "    def act(self, obs): return 13\n",
        [],
        "refused: unpickling posix.getcwd",
    ),
}


@pytest.mark.parametrize("kind", sorted(BAD_AGENTS))
def test_misbehaving_submission_leaves_leaderboard_untouched(repo: Path, kind: str) -> None:
    code, flags, expected = BAD_AGENTS[kind]
    (repo / "agents" / "bad").mkdir()
    (repo / "agents" / "bad" / "agent.py").write_text(code)
    lb = repo / "leaderboard"
    (lb / "submissions" / "bad.yaml").write_text(submission_yaml("agents/bad"))
    before = {k: v for k, v in snapshot(lb).items() if k != "submissions/bad.yaml"}
    r = cdr(
        "leaderboard",
        "build",
        "--evaluate",
        "--episodes",
        EPISODES,
        "--reference",
        "weave",
        "--workers",
        1,
        *flags,
        cwd=repo,
        timeout=120,
    )
    assert r.returncode == 2, r.stderr
    err = r.stderr
    assert "submission bad" in err and expected in err, err
    assert "Traceback" not in err.split("last output")[0]
    assert "\x1b" not in err and "\x00" not in err  # the child's garbage is not echoed raw
    after = {k: v for k, v in snapshot(lb).items() if k != "submissions/bad.yaml"}
    assert after == before
    assert not list(lb.glob(".build-*")), "scratch folder left behind"


@pytest.mark.slow
def test_adding_a_submission_is_one_yaml_file(repo: Path) -> None:
    lb = repo / "leaderboard"
    (lb / "submissions" / "direct-again.yaml").write_text(
        submission_yaml("agents/direct/agent.py", display_name="Direct again")
    )
    r = cdr(
        "leaderboard",
        "build",
        "--evaluate",
        "direct-again",
        "--reference",
        "weave",
        "--workers",
        1,
        cwd=repo,
    )
    assert r.returncode == 0, r.stderr
    assert (lb / "results" / "direct-again.jsonl.xz").read_bytes() == (
        lb / "results" / "direct.jsonl.xz"
    ).read_bytes()  # same agent, same episodes (the count is taken from the committed results)
    assert "Direct again" in (lb / "README.md").read_text()


def test_build_refuses_results_on_other_episodes(repo: Path) -> None:
    lb = repo / "leaderboard"
    r = cdr(
        "evaluate",
        "agents/direct/agent.py",
        *[a for sid in SCENARIOS for a in ("--scenario", sid)],
        "--episodes",
        EPISODES,
        "--seed",
        "7",
        "--out",
        "leaderboard/results/direct.json",
        "--force",
        "--no-progress",
        cwd=repo,
    )
    assert r.returncode == 0, r.stderr
    before = snapshot(lb)
    r = cdr("leaderboard", "build", "--reference", "weave", cwd=repo)
    assert r.returncode == 2
    assert "not run on the same episodes" in r.stderr
    assert snapshot(lb) == before


def test_partial_check_needs_whole_batches(repo: Path) -> None:
    r = cdr("leaderboard", "build", "--check", "--episodes", "3", "--reference", "weave", cwd=repo)
    assert r.returncode == 2
    assert "--episodes" in r.stderr and textwrap.shorten(r.stderr, 400)


def test_check_names_agent_files_changed_since_evaluation(repo: Path) -> None:
    agent = repo / "agents" / "direct" / "agent.py"
    agent.write_text(agent.read_text() + "\n# retrained\n")
    r = cdr(
        "leaderboard",
        "build",
        "--check",
        "--evaluate",
        "direct",
        "--reference",
        "weave",
        "--workers",
        1,
        cwd=repo,
    )
    assert r.returncode == 1
    assert "results/direct.json: the agent's files changed" in r.stderr
    assert "changed: agent.py" in r.stderr
    assert "--evaluate direct" in r.stderr


def test_every_seed_scored_on_the_same_episodes_and_aggregated(repo: Path) -> None:
    lb = repo / "leaderboard"
    res = lb / "results"
    assert (res / "weave.json").exists() and (res / "weave.seed-2.json").exists()
    assert not (res / "weave.seed-2.replays.json").exists()  # per-episode extras: shown seed only
    one, two = (read_result(res / f) for f in ("weave.json", "weave.seed-2.json"))
    assert [s["seeds_sha256"] for s in one["scenarios"]] == [
        s["seeds_sha256"] for s in two["scenarios"]
    ]
    assert one["agent"]["sha256"] != two["agent"]["sha256"]  # the checkpoint is in the identity
    data = json.loads((lb / "leaderboard.json").read_text())
    rows = {r["entry"]: r for r in data["seeds"]["rows"]}
    w, d = rows["weave"], rows["direct"]
    assert w["seeds"] == [1, 2] and w["headline"]["runs"] == 2
    assert d["seeds"] == [None] and d["headline"]["aggregate"] == "one run"
    lo, hi = d["headline"]["ci95"]  # one run: its episode interval, never zero-width
    assert lo < d["headline"]["score"] < hi or 0.0 in (lo, hi) or 1.0 in (lo, hi)
    assert w["headline"]["aggregate"] == "mean" and w["units"] == [[1], [2]]
    hi = {s["id"]: s for s in one["scenarios"]}["high"]["metrics"]["ownship"]
    hi2 = {s["id"]: s for s in two["scenarios"]}["high"]["metrics"]["ownship"]
    per = [hi["clean_success_rate"]["value"], hi2["clean_success_rate"]["value"]]
    assert w["headline"]["per_run"] == per
    assert w["headline"]["score"] == pytest.approx(sum(per) / 2)  # the ranked score: the mean
    ranked = {r["entry"]: r for r in data["ranking"]["rows"]}["weave"]["headline"]
    assert ranked["value"] == w["headline"]["score"] and ranked["seeds"] == 2
    assert w["headline"]["iqm"] == pytest.approx(sum(per) / 2)  # 2 runs: nothing trimmed
    assert "## Seeds" in (lb / "README.md").read_text()
    assert 'id="table-seeds"' in (lb / "index.html").read_text()
    # a seed's result tampered with: the check fails naming the file; a missing one is an error
    p = res / "weave.seed-2.json"
    text = log_text(p.with_suffix(".jsonl.xz"))
    forged = text.replace('"outcome":"boundary"', '"outcome":"success"', 1)
    forged = forged.replace('"outcome":"timeout"', '"outcome":"success"', 1)
    forged = forged.replace('"los":true', '"los":false', 1) if forged == text else forged
    assert forged != text
    p.with_suffix(".jsonl.xz").write_bytes(compress_log(forged))
    doc = json.loads(p.read_text())
    doc["episodes_sha256"] = sha256_text(forged)
    p.write_text(json.dumps(doc, indent=1) + "\n")
    r = cdr(*CHECK, cwd=repo)
    assert r.returncode == 1 and "weave.seed-2.json" in r.stderr, r.stderr
    p.unlink()
    (res / "weave.seed-2.jsonl.xz").unlink()
    r = cdr("leaderboard", "build", "--reference", "weave", cwd=repo)
    assert r.returncode == 2 and "no result file for seed 2 of weave" in r.stderr
