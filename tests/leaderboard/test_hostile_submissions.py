"""Hostile leaderboard submissions: every attack an independent review ran against the build
must fail, leave every committed file byte-identical, and the entry (where the build goes on)
must score exactly as the honest agent it wraps.

Each hostile agent is the ``direct`` reference agent plus an attack. Where the attack is silent
(it finds nothing to tamper with and carries on), the build succeeds and the entry's per-episode
records must be the ``direct`` entry's, line for line; where the attack raises, the build fails
with a one-line reason and writes nothing.
"""

from __future__ import annotations

import json
import os
import textwrap
from pathlib import Path

import pytest

from cdr_bench.evaluate.results import log_text, read_result
from cdr_bench.evaluate.sandbox import isolation
from tests.leaderboard.conftest import EPISODES, ROOT, cdr, submission_yaml

pytestmark = pytest.mark.skipif(
    isolation()[0] != "bwrap", reason=f"needs bubblewrap: {isolation()[1]}"
)

DIRECT = (ROOT / "agents" / "direct" / "agent.py").read_text()
MARKER = "cdr-bench-orphan-6d1f"

# Attacks run when the agent module is imported (inside the agent's process).
SILENT_ATTACKS = {
    "frame-walk": """
        import gc, sys
        def _teleport():
            frames, f = [], sys._getframe()
            while f is not None:
                frames.append(f)
                f = f.f_back
            for o in gc.get_objects() + [v for fr in frames for v in fr.f_locals.values()]:
                if type(o).__name__ in ("Simulator", "VectorEnv"):
                    sim = getattr(o, "sim", o)
                    sim.state.ac_pos[:, 0] = sim.state.goal[:, None, :]  # onto the goal
                    raise SystemExit("unreachable: found the scorer's simulator")
        _teleport()
    """,
    "monkeypatch": """
        import cdr_bench.evaluate.runner as _r, cdr_bench.evaluate.metrics as _m
        _real = _r.run_batch
        def _forged(*a, **k):
            out = _real(*a, **k)
            for e in out["episodes"]:
                for ac in e["aircraft"]:
                    ac["los"] = False
                    ac["outcome"] = "success"
            return out
        _r.run_batch = _forged
        _m.scenario_metrics = lambda eps: {}
    """,
    "staged-rewrite": """
        import glob, json, pathlib
        for p in glob.glob("leaderboard/**/*.json*", recursive=True) + glob.glob(
            "leaderboard/.build-*/**/*", recursive=True
        ):
            try:
                pathlib.Path(p).write_text("{}")
            except OSError:
                pass
    """,
    "edit-other-agent": """
        for p in ("agents/direct/agent.py", "agents/weave/agent.py", "README.md"):
            try:
                with open(p, "a") as f:
                    f.write("\\nraise SystemExit('sabotaged')\\n")
            except OSError:
                pass
    """,
    "outside-read": """
        import os, glob
        leaked = []
        for p in ["SECRET_PATH", "/etc/passwd",
                  "/root/.bashrc", "/proc/1/environ"] + glob.glob("/tmp/pytest-of-*/*"):
            try:
                with open(p) as f:
                    leaked.append(f.read(100))
            except OSError:
                pass
        if any("TOP-SECRET" in x or "root:" in x for x in leaked):
            raise RuntimeError("LEAKED " + repr(leaked)[:200])
    """,
    "network": """
        import socket
        try:
            socket.create_connection(("pypi.org", 443), timeout=5).close()
        except OSError:
            pass
        else:
            raise RuntimeError("NETWORK reachable")
    """,
    "orphans": f"""
        import subprocess, sys
        subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)", "{MARKER}"],
                         start_new_session=True, stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL)
    """,
}

FAILING_ATTACKS = {
    "pickle-via-importlib": (
        """
        import importlib
        _p = importlib.import_module("pick" + "le")
        _p.loads(_p.dumps(__import__("os").getcwd))
        """,
        "refused: unpickling posix.getcwd",
    ),
    "damage-then-raise": (
        """
        import glob
        for p in glob.glob("**/*", recursive=True):
            try:
                with open(p, "w") as f:
                    f.write("damaged")
            except OSError:
                pass
        raise RuntimeError("done damaging")
        """,
        "done damaging",
    ),
}


def tree(root: Path) -> dict[str, bytes]:
    """Every file of the repository (the staged build folders excluded)."""
    out = {}
    for p in sorted(root.rglob("*")):
        rel = p.relative_to(root).as_posix()
        if p.is_file() and not p.is_symlink() and "/.build-" not in f"/{rel}":
            out[rel] = p.read_bytes()
    return out


def orphans() -> list[str]:
    found = []
    for d in Path("/proc").iterdir():
        try:
            cmd = (d / "cmdline").read_bytes()
        except OSError:
            continue
        if MARKER.encode() in cmd and str(os.getpid()) != d.name:
            found.append(d.name)
    return found


def add_evil(repo: Path, attack: str, secret: Path | None = None) -> Path:
    folder = repo / "agents" / "evil"
    folder.mkdir()
    code = textwrap.dedent(attack).replace("SECRET_PATH", str(secret))
    (folder / "agent.py").write_text(DIRECT + "\n" + code)
    (repo / "leaderboard" / "submissions" / "evil.yaml").write_text(submission_yaml("agents/evil"))
    return folder


def build(repo: Path) -> tuple[int, str]:
    r = cdr(
        "leaderboard",
        "build",
        "--evaluate",
        "evil",
        "--episodes",
        EPISODES,
        "--reference",
        "weave",
        "--workers",
        1,
        cwd=repo,
        timeout=300,
    )
    return r.returncode, r.stderr


def episodes(path: Path) -> list[dict]:
    text = log_text(path)
    return [json.loads(line) for line in text.splitlines() if line.strip()]


def test_silent_attacks_have_no_effect(repo: Path, tmp_path: Path) -> None:
    """One agent runs every silent attack at import (one build, to keep CI short); each is
    written so that, should it succeed, the build fails or the scores or files change."""
    secret = tmp_path / "secret.txt"
    secret.write_text("TOP-SECRET")
    attacks = "\n".join(
        f"# --- {name}\n" + textwrap.dedent(code) for name, code in SILENT_ATTACKS.items()
    )
    add_evil(repo, attacks, secret)
    before = tree(repo)
    code, err = build(repo)
    assert code == 0, err
    assert not orphans(), "the agent's processes outlived the build"
    after = tree(repo)
    results = repo / "leaderboard" / "results"
    changed = sorted(k for k in set(before) | set(after) if before.get(k) != after.get(k))
    # only the evil entry's results and the pages that list it may change
    allowed_prefixes = ("leaderboard/results/evil.", "leaderboard/plots/")
    allowed = {"leaderboard/README.md", "leaderboard/index.html", "leaderboard/leaderboard.json"}
    unexpected = [k for k in changed if not k.startswith(allowed_prefixes) and k not in allowed]
    assert not unexpected, f"files changed: {unexpected}"
    # the entry scores exactly as the honest agent it wraps
    assert episodes(results / "evil.jsonl.xz") == episodes(results / "direct.jsonl.xz")
    evil, direct = read_result(results / "evil.json"), read_result(results / "direct.json")
    assert [s["metrics"] for s in evil["scenarios"]] == [s["metrics"] for s in direct["scenarios"]]


@pytest.mark.parametrize("name", sorted(FAILING_ATTACKS))
def test_failing_attack_leaves_every_file_identical(repo: Path, name: str) -> None:
    attack, expected = FAILING_ATTACKS[name]
    add_evil(repo, attack)
    before = tree(repo)
    code, err = build(repo)
    assert code == 2, err
    assert expected in err and "submission evil" in err, err
    assert "Traceback" not in err
    assert tree(repo) == before
    assert not list((repo / "leaderboard").glob(".build-*")), "staging folder left behind"


def test_symlinked_agent_outside_the_repository_is_refused(repo: Path, tmp_path: Path) -> None:
    outside = tmp_path / "outside-agent"
    outside.mkdir()
    (outside / "agent.py").write_text(DIRECT)
    (repo / "agents" / "evil").symlink_to(outside, target_is_directory=True)
    (repo / "leaderboard" / "submissions" / "evil.yaml").write_text(submission_yaml("agents/evil"))
    before = tree(repo)
    code, err = build(repo)
    assert code == 2, err
    assert "outside the repository" in err and "evil.yaml: agent" in err, err
    assert tree(repo) == before


def test_symlinked_file_inside_an_agent_folder_is_refused(repo: Path, tmp_path: Path) -> None:
    secret = tmp_path / "weights.npz"
    secret.write_bytes(b"not really weights")
    folder = add_evil(repo, "")
    (folder / "weights.npz").symlink_to(secret)
    before = tree(repo)
    code, err = build(repo)
    assert code == 2, err
    assert "outside" in err and "weights.npz" in err, err
    assert tree(repo) == before
