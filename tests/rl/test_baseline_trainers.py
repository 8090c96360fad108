"""Every baseline trainer end to end through the CLI on a tiny budget: log, checkpoint, resume,
curve, and the shipped agent.py loading the checkpoint it wrote."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

TINY = [
    "--n-envs", "4", "--log-every", "100", "--checkpoint-every", "200",
    "--eval-episodes", "0", "--no-progress", "--width", "16",
]  # fmt: skip
OFF_POLICY = ["--learning-starts", "64", "--batch-size", "16", "--buffer-size", "2000"]
EXTRA = {
    "ppo": ["--n-steps", "32", "--ppo-batch-size", "32", "--n-epochs", "2"],
    "maskable-ppo": ["--n-steps", "32", "--ppo-batch-size", "32", "--n-epochs", "2"],
    "td3": OFF_POLICY,
    "rainbow": [*OFF_POLICY, "--n-atoms", "11"],
    "safe-dqn-x": OFF_POLICY,
}
AGENT_DIR = {
    "ppo": "ppo",
    "maskable-ppo": "maskable_ppo",
    "td3": "td3",
    "rainbow": "rainbow",
    "safe-dqn-x": "safe_dqn_x",
}
MASKED = {"maskable-ppo", "rainbow", "safe-dqn-x"}


def run(*args, env=None):
    return subprocess.run(
        [sys.executable, "-m", "cdr_bench", *args],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=dict(os.environ, OMP_NUM_THREADS="1", **(env or {})),
        timeout=120,
    )


def summary(stdout: str) -> dict:
    return json.loads(stdout[stdout.index("{") :])


@pytest.mark.slow
@pytest.mark.parametrize("name", list(AGENT_DIR))
def test_tiny_training_run_and_agent(tmp_path, name):
    d = tmp_path / "run"
    flags = [*TINY, *EXTRA[name]]
    r = run("train", name, "--run-dir", str(d), "--total-steps", "256", *flags)
    assert r.returncode == 0, r.stderr
    first = summary(r.stdout)
    assert first["step"] >= 256
    assert (d / "checkpoint.pt").exists() and (d / "curve.png").exists()
    r = run("train", name, "--run-dir", str(d), "--total-steps", "512", "--resume", *flags)
    assert r.returncode == 0, r.stderr
    assert summary(r.stdout)["step"] >= 512
    lines = [json.loads(x) for x in (d / "log.jsonl").read_text().splitlines()]
    assert sum("final" in x for x in lines) == 2  # the resumed run appended to the log
    assert any("charts/success_rolling" in x for x in lines)
    assert json.loads((d / "args.json").read_text())["algorithm"] == name

    # The shipped agent.py loads this checkpoint (weights only) and follows the protocol.
    code = (
        "import numpy as np, importlib.util as u\n"
        f"s = u.spec_from_file_location('a', 'agents/{AGENT_DIR[name]}/agent.py')\n"
        "m = u.module_from_spec(s); s.loader.exec_module(m)\n"
        "a = m.Agent(None, None)\n"
        "o = np.random.default_rng(0).uniform(-1, 1, (256, 42)).astype(np.float32)\n"
        "k = np.ones((256, 27), np.int8); k[:128, 2::3] = 0; k[128:, 0::3] = 0\n"
        "a.reset(3); x = a.act_batch(o, k); a.reset(4); y = a.act_batch(o, k)\n"
        "assert (x == y).all() and x.dtype == np.int64 and ((0 <= x) & (x < 27)).all()\n"
        "masked_ok = bool((k[np.arange(256), x] == 1).all())\n"
        "assert isinstance(a.act({'observation': o[0], 'action_mask': k[0]}), int)\n"
        "print('ok', masked_ok)\n"
    )
    r = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=dict(os.environ, CDR_BENCH_CHECKPOINT=str(d / "checkpoint.pt")),
        timeout=60,
    )
    assert r.stdout.startswith("ok"), r.stderr
    if name in MASKED:
        assert r.stdout.split()[1] == "True"  # a masked agent never picks a masked action
