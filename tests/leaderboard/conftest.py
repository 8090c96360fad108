"""A miniature repository with a leaderboard: two agents (``direct``, scripted, and a ``weave``
agent that turns toward its goal while alternating climbs and descents, declared learned with
two training seeds: two checkpoints that set the period of its climbs and descents, and two
fabricated training logs), their submissions (both replaying the tactical head-on family
and its fixed encounter), the published tables, and result files written once per session by
the real ``build --evaluate`` (sandboxed subprocesses, 8 episodes per scenario)."""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
EPISODES = 8
NO_FRESH = ("--fresh-episodes", 0)
"""Flags of a ``--check`` that tests another part of the check: no entry flies the 200 fresh
episodes (tests/leaderboard/test_verify.py tests those)."""

WEAVE_AGENT = textwrap.dedent(
    """
    import os

    import numpy as np

    class Agent:
        def __init__(self, observation_space, action_space):
            self.t = 0
            ck = os.environ.get("CDR_BENCH_CHECKPOINT")
            self.period = int(np.load(ck)["period"]) if ck else 4

        def reset(self, seed):
            self.t = 0

        def act(self, observation):
            return int(self.act_batch(observation["observation"][None],
                                      observation["action_mask"][None])[0])

        def act_batch(self, observations, masks):
            self.t += 1
            rel = np.degrees(np.arctan2(observations[:, 9], observations[:, 10]))
            psi = np.where(rel > 2.5, 1, np.where(rel < -2.5, -1, 0))
            h = 1 if (self.t // self.period) % 2 else -1
            a = 9 * (psi + 1) + 3 + (h + 1)
            return np.where(masks[np.arange(len(a)), a] == 1, a, 9 * (psi + 1) + 4)
    """
)


WEAVE_SEEDS = (
    "[{seed: 1, checkpoint: agents/weave/seed-1.npz, training_log: agents/weave/log-1.jsonl}, "
    "{seed: 2, checkpoint: agents/weave/seed-2.npz, training_log: agents/weave/log-2.jsonl}]"
)
SCENARIOS = ("low", "high", "tactical/head-on", "tactical/head-on-fixed")
REPLAYS = "[tactical/head-on, tactical/head-on-fixed]"


def submission_yaml(agent: str, training: str = "null", **extra: str) -> str:
    lines = [
        f"agent: {agent}",
        "authors: [test]",
        "reference: https://example.org/paper",
        f"training: {training}",
        f"scenarios: [{', '.join(SCENARIOS)}]",
    ]
    lines += [f"{k}: {v}" for k, v in extra.items()]
    return "\n".join(lines) + "\n"


def cdr(
    *args: object, cwd: Path, timeout: float = 300, env: dict[str, str] | None = None
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "cdr_bench", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=timeout,
        env=env,
    )


def make_repo(root: Path) -> Path:
    """Agents, submissions and published tables (no results yet); returns the leaderboard dir."""
    (root / "agents" / "direct").mkdir(parents=True)
    shutil.copy(ROOT / "agents" / "direct" / "agent.py", root / "agents" / "direct" / "agent.py")
    (root / "agents" / "weave").mkdir()
    (root / "agents" / "weave" / "agent.py").write_text(WEAVE_AGENT)
    lb = root / "leaderboard"
    (lb / "submissions").mkdir(parents=True)
    shutil.copytree(ROOT / "leaderboard" / "published", lb / "published")
    for seed in (1, 2):
        log = [
            {"step": 1000 * k, "charts/success_rolling": min(1.0, 0.1 * k + 0.05 * seed)}
            for k in range(1, 11)
        ]
        log += [  # the fixed-evaluation curve of the trainers
            {"step": 5000 * k, "curve/scenario": "high", "curve/clean_success": 0.2 * k + seed / 10}
            for k in range(3)
        ]
        log.append({"final": {"step": 10000, "wall_s": 1.0}})
        (root / "agents" / "weave" / f"log-{seed}.jsonl").write_text(
            "".join(json.dumps(r) + "\n" for r in log)
        )
        np.savez(root / "agents" / "weave" / f"seed-{seed}.npz", period=np.array(2 + 2 * seed))
    (lb / "submissions" / "direct.yaml").write_text(
        submission_yaml("agents/direct/agent.py", display_name="Direct", replays=REPLAYS)
    )
    (lb / "submissions" / "weave.yaml").write_text(
        submission_yaml(
            "agents/weave",
            training="python -m weave.train",
            display_name="Weave",
            published_as="PPO",
            checkpoint="agents/weave/seed-1.npz",
            seeds=WEAVE_SEEDS,
            replays=REPLAYS,
        )
    )
    return lb


@pytest.fixture(scope="session")
def evaluated_repo(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The miniature repository after ``build --evaluate`` (do not modify: copy it). Built once
    per test run: the pytest-xdist processes share the temporary folder's parent, and the first
    to ask builds it there under a lock while the others wait (each process used to build its
    own, 10-15 s of CPU each)."""
    base = tmp_path_factory.getbasetemp()
    shared = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base  # this run's own
    root, built = shared / "lb-repo", shared / "lb-repo.built"
    with (shared / "lb-repo.lock").open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not built.exists():
            shutil.rmtree(root, ignore_errors=True)  # a build that failed before
            root.mkdir()
            _evaluate(root)
            built.touch()
    return root


def _evaluate(root: Path) -> None:
    make_repo(root)
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
        cwd=root,
    )
    assert r.returncode == 0, r.stderr


@pytest.fixture
def repo(evaluated_repo: Path, tmp_path: Path) -> Path:
    """A private copy of the evaluated miniature repository."""
    dst = tmp_path / "repo"
    shutil.copytree(evaluated_repo, dst)
    return dst


def snapshot(lb: Path) -> dict[str, bytes]:
    """Every file under the leaderboard folder, by relative path."""
    return {str(p.relative_to(lb)): p.read_bytes() for p in sorted(lb.rglob("*")) if p.is_file()}
