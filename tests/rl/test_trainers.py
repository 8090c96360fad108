"""Every trainer of ``cdr-bench train`` on tiny budgets: end to end through the CLI (log,
checkpoint, resume, curve, and the shipped agent.py loading the checkpoint it wrote), resuming
equals not stopping, and curriculum promotion inside the off-policy loop. Everything runs in this
process."""

import argparse
import importlib
import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from cdr_bench.rl.cli import TRAINERS  # noqa: E402
from cdr_bench.rl.common import RunLog  # noqa: E402

from .helpers import agent_module, cdr_bench, summary  # noqa: E402

TINY = [
    "--n-envs", "4", "--log-every", "100", "--checkpoint-every", "200",
    "--eval-episodes", "0", "--no-progress", "--width", "16",
]  # fmt: skip
OFF_POLICY = ["--learning-starts", "64", "--batch-size", "16", "--buffer-size", "2000"]
PPO = ["--n-steps", "32", "--ppo-batch-size", "32", "--n-epochs", "2"]
EXTRA = {
    "diffusion-ac": [*OFF_POLICY, "--critic-width", "16"],
    "ppo": PPO,
    "maskable-ppo": PPO,
    "td3": OFF_POLICY,
    "rainbow": [*OFF_POLICY, "--n-atoms", "11"],
    "safe-dqn-x": OFF_POLICY,
}
AGENT_DIR = {
    "diffusion-ac": "diffusion_ac",
    "ppo": "ppo",
    "maskable-ppo": "maskable_ppo",
    "td3": "td3",
    "rainbow": "rainbow",
    "safe-dqn-x": "safe_dqn_x",
}
MASKED = {"diffusion-ac", "maskable-ppo", "rainbow", "safe-dqn-x"}
OFF_POLICY_LOOP = {"diffusion-ac", "rainbow", "safe-dqn-x"}


SHARED_POLICY = {"ippo", "mappo"}
"""Trainers of one policy for every controlled aircraft: tested in test_mappo.py (their own run
directory: no curriculum, curve or resume)."""


def test_every_trainer_is_tested():
    assert set(EXTRA) == set(AGENT_DIR) == set(TRAINERS) - SHARED_POLICY


@pytest.mark.slow
@pytest.mark.parametrize("name", list(AGENT_DIR))
def test_tiny_training_run_and_agent(tmp_path, monkeypatch, name):
    d = tmp_path / "run"
    flags = [*TINY, *EXTRA[name], "--curve-episodes", "10"]  # the default 100: args.json
    r = cdr_bench("train", name, "--run-dir", str(d), "--total-steps", "256", *flags)
    assert r.returncode == 0, r.stderr
    first = summary(r.stdout)
    assert first["step"] >= 256
    assert (d / "checkpoint.pt").exists() and (d / "curve.png").exists()
    assert (d / "state.pt").exists()
    r = cdr_bench("train", name, "--run-dir", str(d), "--total-steps", "512", "--resume", *flags)
    assert r.returncode == 0, r.stderr
    assert summary(r.stdout)["step"] >= 512
    lines = [json.loads(x) for x in (d / "log.jsonl").read_text().splitlines()]
    assert sum("final" in x for x in lines) == 2  # the resumed run appended to the log
    assert any("charts/success_rolling" in x for x in lines)
    prefixes = {k.split("/")[0] for x in lines for k in x if "/" in k}
    assert prefixes <= {"charts", "losses", "curriculum", "curve"}
    # By default the learning curve starts with the initial policy (every 50,000 transitions).
    assert [x["curve/episodes"] for x in lines if "curve/success" in x] == [10]
    assert any(k.startswith("losses/") for x in lines for k in x)
    args = json.loads((d / "args.json").read_text())
    assert args["algorithm"] == name and args["curve_every"] == 50_000
    p = argparse.ArgumentParser()
    importlib.import_module(TRAINERS[name]).add_arguments(p, name)
    assert p.parse_args(["--run-dir", str(d)]).curve_episodes == 100  # the default
    meta = torch.load(d / "checkpoint.pt", weights_only=True)["meta"]
    assert meta["step"] >= 512 and meta["algorithm"] == name

    # The shipped agent.py loads this checkpoint (weights only) and follows the protocol.
    monkeypatch.setenv("CDR_BENCH_CHECKPOINT", str(d / "checkpoint.pt"))
    a = agent_module(AGENT_DIR[name]).Agent(None, None)
    monkeypatch.undo()
    o = np.random.default_rng(0).uniform(-1, 1, (256, 42)).astype(np.float32)
    k = np.ones((256, 27), np.int8)
    k[:128, 2::3] = 0
    k[128:, 0::3] = 0
    a.reset(3)
    x = a.act_batch(o, k)
    a.reset(3)
    y = a.act_batch(o, k)
    assert (x == y).all() and x.dtype == np.int64 and ((0 <= x) & (x < 27)).all()
    assert isinstance(a.act({"observation": o[0], "action_mask": k[0]}), int)
    if name in MASKED:  # a masked agent never picks a masked action
        assert (k[np.arange(256), x] == 1).all()


def train_in_process(name: str, run_dir: Path, *flags: str) -> dict:
    module = importlib.import_module(TRAINERS[name])
    p = argparse.ArgumentParser()
    module.add_arguments(p, name)
    ns = p.parse_args(["--run-dir", str(run_dir), *TINY, *EXTRA[name], *flags])
    return module.run(ns)


def assert_same_run(a: Path, b: Path, steps: int) -> None:
    """Runs ``a`` and ``b`` ended at the same step with the same weights and the same log."""
    ca = torch.load(a / "checkpoint.pt", weights_only=True)
    cb = torch.load(b / "checkpoint.pt", weights_only=True)
    assert ca["meta"]["step"] == cb["meta"]["step"] >= steps
    for k, v in ca["state_dict"].items():
        assert torch.equal(v, cb["state_dict"][k]), k
    assert json.dumps(log_lines(a)) == json.dumps(log_lines(b))


def log_lines(run_dir: Path) -> list[dict]:
    rows = [json.loads(x) for x in (run_dir / "log.jsonl").read_text().splitlines()]
    return [{k: v for k, v in r.items() if k != "wall_s"} for r in rows if "final" not in r]


@pytest.mark.slow
@pytest.mark.parametrize("name", list(AGENT_DIR))
def test_resume_equals_uninterrupted(tmp_path, monkeypatch, name):
    """A run stopped and resumed ends with the same weights and the same log as a run that was
    never stopped. The off-policy loop is stopped anywhere (its schedules span the budget, so
    the budget stays); SB3 runs stop at the end of a shorter budget (their schedules are
    constant)."""
    a, b = tmp_path / "a", tmp_path / "b"
    total = ["--total-steps", "600", *CURVE]
    train_in_process(name, a, *total)
    if name in OFF_POLICY_LOOP:
        calls = iter(range(10_000))
        monkeypatch.setattr(RunLog, "out_of_time", lambda self: next(calls) == 70)
        stopped = train_in_process(name, b, *total)
        monkeypatch.undo()
    else:
        stopped = train_in_process(name, b, "--total-steps", "300", *CURVE)
    assert 0 < stopped["step"] < 600
    train_in_process(name, b, *total, "--resume")
    assert_same_run(a, b, 600)


CURVE = ["--curve-every", "150", "--curve-episodes", "3"]


@pytest.mark.slow
def test_stop_at_pauses_without_changing_the_run(tmp_path):
    """``--stop-at`` pauses an off-policy run at a transition count with its schedules still
    spanning ``--total-steps``; resumed, it ends exactly as a run never paused."""
    a, b = tmp_path / "a", tmp_path / "b"
    total = ["--total-steps", "600", *CURVE]
    train_in_process("rainbow", a, *total)
    paused = train_in_process("rainbow", b, *total, "--stop-at", "250")
    assert 250 <= paused["step"] < 300
    assert torch.load(b / "state.pt", weights_only=False)["loop"]["step"] == paused["step"]
    train_in_process("rainbow", b, *total, "--resume")
    assert_same_run(a, b, 600)
    r = cdr_bench("train", "rainbow", "--run-dir", str(tmp_path / "c"), "--stop-at", "-5")
    assert r.returncode == 2 and "--stop-at: expected a value in [0, inf), got -5" in r.stderr
    assert "Traceback" not in r.stderr and not (tmp_path / "c").exists()


@pytest.mark.slow
@pytest.mark.parametrize("name", list(AGENT_DIR))
def test_learning_curve_points_leave_training_unchanged(tmp_path, name):
    """Evaluating the greedy policy on the fixed evaluation set every ``curve_every``
    transitions adds ``curve/`` log lines and changes nothing else: same weights, same
    training log as a run without them."""
    a, b = tmp_path / "a", tmp_path / "b"
    train_in_process(name, a, "--total-steps", "600", "--curve-every", "0")
    train_in_process(name, b, "--total-steps", "600", *CURVE)
    ca = torch.load(a / "checkpoint.pt", weights_only=True)
    cb = torch.load(b / "checkpoint.pt", weights_only=True)
    for k, v in ca["state_dict"].items():
        assert torch.equal(v, cb["state_dict"][k]), k
    rows = log_lines(b)
    curve = [r for r in rows if "curve/success" in r]
    assert json.dumps(log_lines(a)) == json.dumps([r for r in rows if r not in curve])
    steps = [r["step"] for r in curve]
    assert len(steps) >= 3 and all(y - x >= 150 for x, y in zip(steps, steps[1:], strict=False))
    for r in curve:
        assert r["curve/scenario"] == "high" and r["curve/episodes"] == 3
        assert 0 <= r["curve/clean_success"] <= r["curve/success"] <= 1
    assert not any("curve/success" in r for r in log_lines(a))


@pytest.mark.slow
def test_promotions_in_the_off_policy_loop(tmp_path):
    """With a promotion after every 4 episodes, the loop climbs stages, logs each promotion and
    moves Diffusion-AC's teacher temperature along its stage schedule."""
    out = train_in_process(
        "diffusion-ac", tmp_path, "--total-steps", "2500", "--window", "4", "--promote-at", "0"
    )
    rows = [json.loads(x) for x in (tmp_path / "log.jsonl").read_text().splitlines()]
    promoted = [r["curriculum/promoted_to"] for r in rows if "curriculum/promoted_to" in r]
    assert len(promoted) >= 2 and promoted == list(range(2, 2 + len(promoted)))
    assert out["stage"] == promoted[-1]
    taus = [r["charts/tau"] for r in rows if "charts/tau" in r]
    stages = [r["curriculum/stage"] for r in rows if "charts/tau" in r]
    assert np.all(np.diff(taus) <= 0) and taus[0] > taus[-1] and stages[-1] > stages[0]
