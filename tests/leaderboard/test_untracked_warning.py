"""The warning about agent files that git does not track names each file once (a checkpoint
in the agent folder that is also the entry's checkpoint used to be listed twice)."""

from __future__ import annotations

import subprocess
from pathlib import Path
from types import SimpleNamespace

from cdr_bench.leaderboard.build import untracked_agent_files


def test_each_untracked_file_is_named_once(tmp_path: Path) -> None:
    subprocess.run(["git", "init", "-q", str(tmp_path)], check=True)
    agent = tmp_path / "agents" / "a"
    (agent / "seeds" / "2").mkdir(parents=True)
    (agent / "agent.py").write_text("class Agent: ...\n")
    (agent / "seeds" / "2" / "checkpoint.pt").write_bytes(b"x")
    subprocess.run(["git", "-C", str(tmp_path), "add", "agents/a/agent.py"], check=True)
    # the two fields the function reads
    sub = SimpleNamespace(agent="agents/a", checkpoint="agents/a/seeds/2/checkpoint.pt")
    assert untracked_agent_files(sub, tmp_path) == ["agents/a/seeds/2/checkpoint.pt"]
