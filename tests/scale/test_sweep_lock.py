"""Two sweep processes in one output folder (one per core) never run the same trial twice: a
trial another live process is running is left to it."""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

from cdr_bench.scale.config import load_sweep
from cdr_bench.scale.sweep import ELSEWHERE, TRIAL_LOCK, remove_idle_work, run_trial

from .helpers import tiny_sweep


def _hold(path: Path) -> int:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX)
    return fd


def test_a_trial_locked_by_another_process_is_left_to_it(tmp_path: Path) -> None:
    (trial,) = load_sweep(tiny_sweep(tmp_path, [1])).trials
    out = tmp_path / "out"
    fd = _hold(out / ".work" / f"{trial.key}{TRIAL_LOCK}")
    try:
        assert run_trial(trial, str(out)) == {"key": trial.key, ELSEWHERE: True}
    finally:
        os.close(fd)
    assert not list((out / ".work").glob(f"{trial.key}-*"))  # no second attempt started


def test_a_live_attempt_folder_is_left_to_its_process(tmp_path: Path) -> None:
    """An attempt of a sweep process that takes no trial lock (an earlier version) counts."""
    (trial,) = load_sweep(tiny_sweep(tmp_path, [1])).trials
    out = tmp_path / "out"
    fd = _hold(out / ".work" / f"{trial.key}-live0001" / ".lock")
    try:
        assert run_trial(trial, str(out)) == {"key": trial.key, ELSEWHERE: True}
    finally:
        os.close(fd)
    assert [p.name for p in (out / ".work").glob(f"{trial.key}-*")] == [f"{trial.key}-live0001"]


def test_idle_trial_locks_are_removed_held_ones_kept(tmp_path: Path) -> None:
    work = tmp_path / ".work"
    (work / f"a{TRIAL_LOCK}").parent.mkdir(parents=True)
    (work / f"a{TRIAL_LOCK}").write_text("")
    fd = _hold(work / f"b{TRIAL_LOCK}")
    try:
        remove_idle_work(tmp_path)
        assert sorted(p.name for p in work.iterdir()) == [f"b{TRIAL_LOCK}"]
    finally:
        os.close(fd)
    remove_idle_work(tmp_path)
    assert not work.exists()
