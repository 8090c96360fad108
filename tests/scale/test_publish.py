"""A trial publishes its folder once: complete, atomically, and never over another attempt.

Trainer and evaluator are replaced by stubs (no Ray, no training): these tests are about the
folder protocol of :func:`cdr_bench.scale.sweep.run_trial`."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from cdr_bench.scale import sweep as sw
from cdr_bench.scale.config import load_sweep

from .helpers import tiny_sweep


def _stub_run(on_evaluate=None, fail: str | None = None):
    def run(cmd, stdout=None, stderr=None, env=None):
        step = cmd[3]  # python -m cdr_bench <step>
        if step == fail:
            return subprocess.CompletedProcess(cmd, 1)
        if step == "evaluate":
            out = Path(cmd[cmd.index("--out") + 1])
            out.write_text(json.dumps({"agent": {"path": "work"}, "scenarios": []}))
            if on_evaluate:
                on_evaluate()
        return subprocess.CompletedProcess(cmd, 0)

    return run


@pytest.fixture
def trial(tmp_path):
    return load_sweep(tiny_sweep(tmp_path, [1])).trials[0]


def test_publishes_complete_folder(tmp_path, trial, monkeypatch):
    monkeypatch.setattr(sw.subprocess, "run", _stub_run())
    out = tmp_path / "out"
    rec = sw.run_trial(trial, str(out))
    final = out / trial.key
    assert json.loads((final / sw.TRIAL_FILE).read_text()) == rec
    res = json.loads((final / sw.RESULT_FILE).read_text())
    assert res["agent"]["path"] == str(final / "agent.py")  # names its final folder
    assert (final / "agent.py").is_file()
    assert list((out / ".work").iterdir()) == []
    # a later attempt (a retry whose first run did land) does nothing
    monkeypatch.setattr(sw.subprocess, "run", _stub_run(fail="train"))
    assert sw.run_trial(trial, str(out)) == rec


def test_losing_attempt_is_discarded(tmp_path, trial, monkeypatch):
    out = tmp_path / "out"
    winner = {"key": trial.key, "attempt": "the other one"}

    def other_attempt_lands():
        (out / trial.key).mkdir(parents=True)
        (out / trial.key / sw.TRIAL_FILE).write_text(json.dumps(winner))

    monkeypatch.setattr(sw.subprocess, "run", _stub_run(on_evaluate=other_attempt_lands))
    assert sw.run_trial(trial, str(out)) == winner
    assert [p.name for p in (out / trial.key).iterdir()] == [sw.TRIAL_FILE]
    assert list((out / ".work").iterdir()) == []


def test_failed_step_publishes_nothing(tmp_path, trial, monkeypatch):
    monkeypatch.setattr(sw.subprocess, "run", _stub_run(fail="evaluate"))
    out = tmp_path / "out"
    with pytest.raises(RuntimeError, match="evaluate exited with 1"):
        sw.run_trial(trial, str(out))
    assert not (out / trial.key).exists()
    assert not sw.trial_done(out, trial)
