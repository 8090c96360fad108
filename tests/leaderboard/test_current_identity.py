"""The identity the check expects for each submission is computed without touching process
state: the check runs two submissions at once in threads, and a version that set
``CDR_BENCH_CHECKPOINT`` and the working directory around the hash let one thread hash a seed's
agent with another seed's checkpoint (a fresh-clone CI failed on it)."""

from __future__ import annotations

import json
import os
from concurrent.futures import ThreadPoolExecutor

import pytest

from cdr_bench.evaluate.loader import CHECKPOINT_ENV
from cdr_bench.leaderboard.data import current_identity
from cdr_bench.leaderboard.published import load_published
from cdr_bench.leaderboard.submission import load_submissions
from tests.leaderboard.conftest import ROOT

LB = ROOT / "leaderboard"


def _seeded_views():
    subs = load_submissions(LB, load_published(LB).names)
    views = [v for s in subs if s.seeds for v in (s, *s.seed_views())]
    assert len({v.checkpoint for v in views}) >= 6  # several agents, several checkpoints each
    return views


def _recorded(name: str) -> str:
    return json.loads((LB / "results" / f"{name}.json").read_text())["agent"]["sha256"]


def test_identity_reads_no_environment_or_working_directory(
    monkeypatch: pytest.MonkeyPatch, tmp_path
) -> None:
    def no_chdir(_path: object) -> None:
        raise AssertionError("current_identity changed the working directory")

    monkeypatch.chdir(tmp_path)  # not the repository
    monkeypatch.setenv(CHECKPOINT_ENV, "no/such/checkpoint.pt")
    monkeypatch.setattr(os, "chdir", no_chdir)
    for v in _seeded_views()[:4]:
        assert current_identity(v, ROOT)["sha256"] == _recorded(v.name), v.name
    assert os.environ[CHECKPOINT_ENV] == "no/such/checkpoint.pt"


def test_identity_in_threads_matches_the_committed_results() -> None:
    views = _seeded_views()
    with ThreadPoolExecutor(4) as pool:
        got = list(pool.map(lambda v: current_identity(v, ROOT)["sha256"], views * 3))
    assert got == [_recorded(v.name) for v in views * 3]
