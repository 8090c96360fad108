"""Strict validation of submission files, the published tables, and the guards against
unpickling (static scan of agent code, safe checkpoint loading)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from cdr_bench.errors import UserError
from cdr_bench.leaderboard.published import load_published
from cdr_bench.leaderboard.submission import SubmissionError, load_submission, load_submissions
from tests.leaderboard.conftest import (
    ROOT,
    SCENARIOS,
    WEAVE_SEEDS,
    cdr,
    make_repo,
    submission_yaml,
)

GOOD = submission_yaml("agents/direct/agent.py")
LEARNED = submission_yaml(
    "agents/weave", training="python t.py", checkpoint="agents/weave/seed-1.npz"
)


@pytest.fixture
def lb(tmp_path: Path) -> Path:
    return make_repo(tmp_path)


def write(lb: Path, text: str, name: str = "entry") -> Path:
    p = lb / "submissions" / f"{name}.yaml"
    p.write_text(text)
    return p


def test_good_submission(lb: Path) -> None:
    s = load_submission(write(lb, GOOD), lb.parent)
    assert s.name == "entry" and s.agent == "agents/direct/agent.py"
    assert s.scenarios == SCENARIOS and s.suite is None
    assert s.group == "scripted" and s.training_logs == () and s.replays == ()
    assert s.authors == ("test",) and s.training is None and s.checkpoint is None


def test_repository_submissions_are_valid() -> None:
    subs = load_submissions(ROOT / "leaderboard", load_published(ROOT / "leaderboard").names)
    names = {s.name for s in subs}
    assert {"direct", "random", "mvp", "diffusion-ac"} <= names
    for s in subs:
        assert s.suite == {"single-agent": "paper", "multi-agent": "marl"}[s.track]
    assert {s.name for s in subs if s.track == "multi-agent"} >= {"mvp-all", "mvp-reciprocal"}


BAD = {
    "unknown key": (GOOD + "colour: blue\n", "colour", "unknown field"),
    "missing key": (GOOD.replace("authors: [test]\n", ""), "authors", "missing required"),
    "authors type": (GOOD.replace("authors: [test]", "authors: test"), "authors", "list"),
    "author item": (GOOD.replace("authors: [test]", "authors: [3]"), "authors[0]", "string"),
    "agent missing": (
        GOOD.replace("agents/direct/agent.py", "agents/nope.py"),
        "agent",
        "does not exist",
    ),
    "agent absolute": (
        GOOD.replace("agents/direct/agent.py", "/etc/passwd"),
        "agent",
        "relative to the repository root",
    ),
    "agent escapes": (
        GOOD.replace("agents/direct/agent.py", "../agents/direct/agent.py"),
        "agent",
        "relative to the repository root",
    ),
    "pickle checkpoint": (
        GOOD.replace("training: null", "training: python train.py")
        + "checkpoint: agents/direct/model.pkl\n",
        "checkpoint",
        "without unpickling",
    ),
    "checkpoint without training": (
        GOOD + "checkpoint: agents/direct/model.pt\n",
        "training",
        "command that trained",
    ),
    "unknown scenario": (
        GOOD.replace("tactical/head-on", "tactical/nope"),
        "scenarios[2]",
        "unknown",
    ),
    "unknown suite": (
        GOOD.replace(f"[{', '.join(SCENARIOS)}]", "atari"),
        "scenarios",
        "suite",
    ),
    "training type": (GOOD.replace("training: null", "training: [a, b]"), "training", "string"),
    "published row": (GOOD + "published_as: GPT-5\n", "published_as", "unknown row"),
    "published rows": (
        GOOD + "published_as: [Diffusion-AC, GPT-5]\n",
        "published_as[1]",
        "unknown row 'GPT-5'",
    ),
    "published row twice": (
        GOOD + "published_as: [Diffusion-AC, Diffusion-AC]\n",
        "published_as",
        "named twice",
    ),
    "published rows empty": (GOOD + "published_as: []\n", "published_as", "non-empty list"),
    "multimodality elsewhere": (
        GOOD + "multimodality: [tactical/crossing]\n",
        "multimodality[0]",
        "not one of this entry's scenarios",
    ),
    "not a mapping": ("- agent: x\n", "", "expected a mapping"),
    "unknown group": (GOOD + "group: baseline\n", "group", "expected one of"),
    "scripted with logs": (
        GOOD + "training_logs: [agents/direct/agent.py]\n",
        "training_logs[0]",
        "expected a .jsonl or .jsonl.xz file",
    ),
    "learned without training": (GOOD + "group: learned\n", "training", "training command"),
    "budget shape": (
        GOOD.replace("training: null", "training: python t.py") + "budget: {transitions: 5}\n",
        "budget",
        "expected {transitions: N, seeds: K}",
    ),
    "budget value": (
        GOOD.replace("training: null", "training: python t.py")
        + "budget: {transitions: 0, seeds: 1}\n",
        "budget.transitions",
        "positive integer",
    ),
    "replays elsewhere": (
        GOOD + "replays: [tactical/crossing]\n",
        "replays[0]",
        "not one of this entry's scenarios",
    ),
    "bad yaml": ("agent: [unclosed\n", "", "not valid YAML"),
    "seeds of a scripted entry": (
        GOOD + f"seeds: {WEAVE_SEEDS}\n",
        "seeds",
        "scripted entry has no training seeds",
    ),
    "one seed": (
        LEARNED + "seeds: [{seed: 1, checkpoint: agents/weave/seed-1.npz, "
        "training_log: agents/weave/log-1.jsonl}]\n",
        "seeds",
        "two or more",
    ),
    "seed keys": (
        LEARNED + "seeds: [{seed: 1, checkpoint: agents/weave/seed-1.npz}, {seed: 2}]\n",
        "seeds[0]",
        "expected {seed: K, checkpoint: FILE, training_log: FILE.jsonl[.xz]}",
    ),
    "seed number": (
        LEARNED + f"seeds: {WEAVE_SEEDS.replace('seed: 2', 'seed: two')}\n",
        "seeds[1].seed",
        "non-negative integer",
    ),
    "seed twice": (
        LEARNED + f"seeds: {WEAVE_SEEDS.replace('seed: 2', 'seed: 1')}\n",
        "seeds",
        "a seed is listed twice",
    ),
    "seed checkpoint missing": (
        LEARNED + f"seeds: {WEAVE_SEEDS.replace('seed-2.npz', 'seed-9.npz')}\n",
        "seeds[1].checkpoint",
        "does not exist",
    ),
    "seed log not jsonl": (
        LEARNED + f"seeds: {WEAVE_SEEDS.replace('log-2.jsonl', 'seed-2.npz')}\n",
        "seeds[1].training_log",
        "expected a .jsonl or .jsonl.xz file",
    ),
    "checkpoint not a seed": (
        LEARNED.replace("seed-1.npz", "other.npz") + f"seeds: {WEAVE_SEEDS}\n",
        "checkpoint",
        "expected one of the seeds' checkpoints",
    ),
    "seeds and training_logs": (
        LEARNED + f"seeds: {WEAVE_SEEDS}\ntraining_logs: [agents/weave/log-1.jsonl]\n",
        "training_logs",
        "not given with seeds",
    ),
    "seeds against budget": (
        LEARNED + f"seeds: {WEAVE_SEEDS}\nbudget: {{transitions: 10000, seeds: 3}}\n",
        "budget",
        "declares 3 seed(s), seeds lists 2",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_submission_names_file_and_field(lb: Path, case: str) -> None:
    text, field, what = BAD[case]
    (lb.parent / "agents" / "direct" / "model.pkl").write_bytes(b"x")
    (lb.parent / "agents" / "direct" / "model.pt").write_bytes(b"x")
    (lb.parent / "agents" / "weave" / "other.npz").write_bytes(b"x")
    p = write(lb, text)
    with pytest.raises(SubmissionError) as e:
        load_submission(p, lb.parent, load_published(lb).names)
    msg = str(e.value)
    assert msg.startswith(f"{p}: {field}: " if field else f"{p}: "), msg
    assert what in msg
    assert e.value.field == field


def test_learned_submission_fields(lb: Path) -> None:
    text = GOOD.replace("training: null", "training: python t.py") + (
        "group: ablation\ntraining_logs: [agents/weave/log-1.jsonl]\n"
        "budget: {transitions: 10000, seeds: 1}\nreplays: [tactical/head-on]\n"
    )
    s = load_submission(write(lb, text), lb.parent)
    assert s.group == "ablation" and s.training_logs == ("agents/weave/log-1.jsonl",)
    assert s.budget == (10000, 1) and s.replays == ("tactical/head-on",)
    s = load_submission(write(lb, GOOD.replace("training: null", "training: x")), lb.parent)
    assert s.group == "learned"  # the default with a training command


def test_seeds(lb: Path) -> None:
    s = load_submission(write(lb, LEARNED + f"seeds: {WEAVE_SEEDS}\n"), lb.parent)
    assert [x.seed for x in s.seeds] == [1, 2] and s.seed == 1
    assert s.training_logs == ("agents/weave/log-1.jsonl", "agents/weave/log-2.jsonl")
    (view,) = s.seed_views()
    assert view.name == "entry.seed-2" and view.checkpoint == "agents/weave/seed-2.npz"
    assert view.training_logs == ("agents/weave/log-2.jsonl",)
    assert view.replays == () and view.multimodality == () and view.published_as == ()
    assert view.scenarios == s.scenarios and view.agent == s.agent


def test_a_training_log_may_be_kept_as_xz(lb: Path) -> None:
    """A shipped training log is ``.jsonl.xz``; the leaderboard reads it as the plain log."""
    from cdr_bench.evaluate.results import compress_log
    from cdr_bench.leaderboard.data import _read_log

    plain = lb.parent / "agents" / "weave" / "log-2.jsonl"
    packed = plain.with_name("log-2.jsonl.xz")
    want = _read_log(plain)
    packed.write_bytes(compress_log(plain.read_text()))
    plain.unlink()
    seeds = WEAVE_SEEDS.replace("log-2.jsonl", "log-2.jsonl.xz")
    s = load_submission(write(lb, LEARNED + f"seeds: {seeds}\n"), lb.parent)
    assert s.training_logs == ("agents/weave/log-1.jsonl", "agents/weave/log-2.jsonl.xz")
    assert _read_log(packed) == want and want[-1] == {"final": {"step": 10000, "wall_s": 1.0}}


def test_one_entry_may_reproduce_two_paper_rows_and_a_row_one_entry(lb: Path) -> None:
    rows = "published_as: [Diffusion-AC, Diffusion-AC (Complete)]\n"
    s = load_submission(write(lb, GOOD + rows), lb.parent, load_published(lb).names)
    assert s.published_as == ("Diffusion-AC", "Diffusion-AC (Complete)")
    one = load_submission(write(lb, GOOD + "published_as: PPO\n", "one"), lb.parent)
    assert one.published_as == ("PPO",)
    write(lb, GOOD + "published_as: Diffusion-AC (Complete)\n", "other")
    with pytest.raises(UserError) as e:
        load_submissions(lb, load_published(lb).names)
    msg = str(e.value)
    assert "other.yaml: published_as: the paper's row 'Diffusion-AC (Complete)'" in msg
    assert "entry.yaml" in msg


def test_bad_file_name(lb: Path) -> None:
    p = write(lb, GOOD, name="My Agent")
    with pytest.raises(SubmissionError, match="lower-case"):
        load_submission(p, lb.parent)


def test_cli_reports_bad_submission_in_one_line(lb: Path) -> None:
    write(lb, GOOD + "colour: blue\n")
    r = cdr("leaderboard", "build", cwd=lb.parent)
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0
    assert "entry.yaml: colour: unknown field" in r.stderr


def test_published_tables_loaded_verbatim() -> None:
    pub = load_published(ROOT / "leaderboard")
    t2 = pub.table("Table 2")
    assert len(t2) == 15 and len(pub.table("Table 3")) == 5
    dac = pub.lookup("Diffusion-AC", "high")
    assert dac is not None and dac.values["success_rate"] == 94.1
    assert dac.values["average_safety_reward"] == -1.98
    assert "Diffusion-AC" in pub.names() and "W/O DPSC" in pub.names()


def test_safeload_refuses_pickled_objects(tmp_path: Path) -> None:
    torch = pytest.importorskip("torch")
    good, evil = tmp_path / "good.pt", tmp_path / "evil.pt"
    torch.save({"w": torch.zeros(3)}, good)

    class Evil:
        def __reduce__(self):  # runs at unpickling time
            return (print, ("PWNED",))

    torch.save({"w": Evil()}, evil)
    run = [sys.executable, "-m", "cdr_bench.leaderboard.safeload"]
    r = subprocess.run([*run, str(good)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    r = subprocess.run([*run, str(evil)], capture_output=True, text=True)
    assert r.returncode == 2
    assert "PWNED" not in r.stdout and "not loadable without unpickling" in r.stderr
