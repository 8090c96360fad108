"""sweeps/rainbow_replay_reset.py: the round-1 resume schedule (replay emptied at given
transition counts) on a tiny budget, and continuing after an interruption."""

import json
import subprocess
import sys
from types import SimpleNamespace

import pytest

from .helpers import sweep_script

torch = pytest.importorskip("torch")

rrr = sweep_script("rainbow_replay_reset")


@pytest.fixture(autouse=True)
def _train_in_process(monkeypatch):
    """The script's ``python -m cdr_bench train ...`` runs by :func:`cdr_bench.cli.main` in this
    process (the schedule is what is tested here, not the process it starts)."""
    from cdr_bench.cli import main

    def run(cmd):
        assert cmd[:4] == [sys.executable, "-m", "cdr_bench", "train"], cmd
        return subprocess.CompletedProcess(cmd, main(cmd[3:]))

    monkeypatch.setattr(rrr, "subprocess", SimpleNamespace(run=run))


TINY = [
    "--n-envs", "4", "--log-every", "100", "--checkpoint-every", "200", "--width", "16",
    "--learning-starts", "64", "--batch-size", "16", "--buffer-size", "2000", "--curve-every", "0",
]  # fmt: skip


@pytest.mark.slow
def test_replay_emptied_at_each_reset_and_the_run_finishes(tmp_path):
    run = tmp_path / "run"
    flags = [str(run), "--resets", "250", "--total-steps", "500", "--no-evaluate"]
    assert rrr.main([*flags, *TINY]) == 0
    resets = json.loads((run / "resets.json").read_text())
    assert len(resets) == 1 and 250 <= resets[0] < 300
    state = torch.load(run / "state.pt", weights_only=False)
    assert state["loop"]["step"] >= 500
    # Since the reset the replay holds only what was collected after it.
    n = len(state["replay"]["buffer"]["data"]["action"])
    assert 0 < n <= state["loop"]["step"] - resets[0] + 4
    # Re-running a finished run trains nothing more and empties nothing more.
    before = (run / "checkpoint.pt").read_bytes()
    assert rrr.main([*flags, *TINY]) == 0
    assert json.loads((run / "resets.json").read_text()) == resets
    assert (run / "checkpoint.pt").read_bytes() == before


def test_empty_replay_keeps_everything_else(tmp_path):
    run = tmp_path / "run"
    assert rrr.main([str(run), "--resets", "--total-steps", "200", "--no-evaluate", *TINY]) == 0
    before = torch.load(run / "state.pt", weights_only=False)
    assert len(before["replay"]["buffer"]["data"]["action"]) > 0
    step = rrr.empty_replay(run)
    after = torch.load(run / "state.pt", weights_only=False)
    assert step == before["loop"]["step"]
    assert len(after["replay"]["buffer"]["data"]["action"]) == 0
    assert after["replay"]["buffer"]["tree"].sum() == 0
    assert after["loop"]["learn_from"] == step + 64
    assert after["rng"] == before["rng"] and torch.equal(after["torch_rng"], before["torch_rng"])
    for part in ("net", "target"):
        for k, v in before["learner"][part].items():
            assert torch.equal(v, after["learner"][part][k]), (part, k)


@pytest.mark.parametrize(
    "flags", [["--total-steps", "-5"], ["--resets", "300", "200"], ["--resets", "0"]]
)
def test_bad_budgets_are_refused_before_anything_runs(tmp_path, flags):
    with pytest.raises(SystemExit) as e:
        rrr.main([str(tmp_path / "run"), "--no-evaluate", *flags])
    assert e.value.code == 2
    assert not (tmp_path / "run").exists()
