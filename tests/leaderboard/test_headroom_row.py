"""The unranked headroom row (``cdr-bench leaderboard headroom``): planned on the ranking's
own episodes, shown apart from the ranking on both pages, replayed by ``--check``, and refused
when it is not on the ranking's episodes."""

from __future__ import annotations

import json
import re
from pathlib import Path

from tests.leaderboard.conftest import EPISODES, cdr

BUILD = ("leaderboard", "build", "--reference", "weave", "--workers", 1)


def test_headroom_row_is_shown_apart_and_replayed_by_the_check(repo: Path) -> None:
    lb = repo / "leaderboard"
    r = cdr("leaderboard", "headroom", "--reference", "weave", cwd=repo)
    assert r.returncode == 0, r.stderr
    assert "wrote leaderboard/headroom/high.json: clean success" in r.stderr
    result = json.loads((lb / "headroom" / "high.json").read_text())
    weave = json.loads((lb / "results" / "weave.json").read_text())
    assert result["base_seed"] == weave["base_seed"]
    assert result["scenarios"][0]["episodes"] == EPISODES
    r = cdr(*BUILD, cwd=repo)
    assert r.returncode == 0, r.stderr
    readme = (lb / "README.md").read_text()
    ranking = readme[readme.index("## Ranking") : readme.index("### Headroom")]
    assert "planner" not in ranking.lower()  # never a ranked row
    row = re.search(
        r"\| Clairvoyant planner \(knows the traffic; not an agent\) \| ([\d.]+)%", readme
    )
    assert row, readme[readme.index("### Headroom") :][:800]
    assert "McNemar exact p = " in readme and "Headroom, not ranked." in readme
    page = (lb / "index.html").read_text()
    assert 'id="table-headroom"' in page
    data = json.loads((lb / "leaderboard.json").read_text())
    assert data["headroom"]["episodes"] == EPISODES
    # the check replays the planner's decisions with the entries' (8 episodes more)
    r = cdr(*BUILD[:2], "--check", *BUILD[2:], "--fresh-episodes", 0, cwd=repo)
    assert r.returncode == 0, r.stderr
    replayed = re.search(r"check passed: (\d+) episodes replayed", r.stderr)
    assert replayed and int(replayed.group(1)) % (EPISODES * 4) == EPISODES, r.stderr


def test_headroom_on_other_episodes_is_refused(repo: Path) -> None:
    lb = repo / "leaderboard"
    assert cdr("leaderboard", "headroom", "--reference", "weave", cwd=repo).returncode == 0
    path = lb / "headroom" / "high.json"
    doc = json.loads(path.read_text())
    doc["base_seed"] += 1
    path.write_text(json.dumps(doc, indent=1) + "\n")
    r = cdr(*BUILD, cwd=repo)
    assert r.returncode != 0
    assert "not on the ranking's episodes of high" in r.stderr and "Traceback" not in r.stderr
    r = cdr("leaderboard", "headroom", "--reference", "nobody", cwd=repo)
    assert r.returncode != 0 and "--reference" in r.stderr and "Traceback" not in r.stderr
