"""Real subprocess runs of the rl subcommands on tiny budgets."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def run(*args, env=None):
    return subprocess.run(
        [sys.executable, "-m", "cdr_bench", *args],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=env,
        timeout=120,
    )


def test_train_checkpoint_resume_and_agent(tmp_path):
    d = tmp_path / "run"
    tiny = [
        "--n-envs",
        "8",
        "--learning-starts",
        "64",
        "--batch-size",
        "16",
        "--log-every",
        "50",
        "--eval-episodes",
        "0",
        "--no-progress",
        "--width",
        "32",
        "--buffer-size",
        "1000",
    ]
    r = run("train", "diffusion-ac", "--run-dir", str(d), "--total-steps", "200", *tiny)
    assert r.returncode == 0, r.stderr
    assert (d / "checkpoint.pt").exists() and (d / "state.pt").exists()
    first = json.loads(r.stdout[r.stdout.index("{") :])
    assert first["step"] >= 200 and first["updates"] > 0
    r = run("train", "diffusion-ac", "--run-dir", str(d), "--total-steps", "400", "--resume", *tiny)
    assert r.returncode == 0, r.stderr
    second = json.loads(r.stdout[r.stdout.index("{") :])
    assert second["step"] >= 400 and second["updates"] > first["updates"]
    lines = [json.loads(x) for x in (d / "log.jsonl").read_text().splitlines()]
    assert sum("final" in x for x in lines) == 2  # the resumed run appended to the log
    assert (d / "curve.png").exists()

    # The agent protocol with this checkpoint, deterministic given the seed.
    env = dict(os.environ, CDR_BENCH_CHECKPOINT=str(d / "checkpoint.pt"))
    code = (
        "import numpy as np, importlib.util as u\n"
        "s = u.spec_from_file_location('a', 'agents/diffusion_ac/agent.py')\n"
        "m = u.module_from_spec(s); s.loader.exec_module(m)\n"
        "a = m.Agent(None, None)\n"
        "o = np.random.default_rng(0).uniform(-1, 1, (64, 42)).astype(np.float32)\n"
        "k = np.ones((64, 27), np.int8); k[:, 2::3] = 0\n"
        "a.reset(3); x = a.act_batch(o, k); a.reset(3); y = a.act_batch(o, k)\n"
        "assert (x == y).all() and (x % 3 != 2).all()\n"
        "assert isinstance(a.act({'observation': o[0], 'action_mask': k[0]}), int)\n"
        "print('ok')\n"
    )
    r = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=env, timeout=60
    )
    assert r.stdout.strip() == "ok", r.stderr

    r = run(
        "latency",
        "agents/diffusion_ac",
        "--batch-sizes",
        "1,4",
        "--decisions",
        "8",
        "--min-calls",
        "3",
        env=env,
    )
    assert r.returncode == 0, r.stderr
    assert "| 1 | 8 | 8 |" in r.stdout and "| 4 | 3 | 12 |" in r.stdout  # calls, decisions
    r = run("latency", "agents/diffusion_ac", "--batch-sizes", "1,x", env=env)
    assert r.returncode == 2 and "--batch-sizes" in r.stdout + r.stderr

    out = tmp_path / "mm.json"
    r = run(
        "multimodal",
        "agents/diffusion_ac",
        "--scenario",
        "curriculum/stage-01",
        "--samples",
        "16",
        "--max-steps",
        "5",
        "--out",
        str(out),
        env=env,
    )
    assert r.returncode == 0, r.stderr
    res = json.loads(out.read_text())
    assert sum(res["all"]) == 16 and 0 <= res["normalised_entropy"] <= 1
    assert out.with_suffix(".png").exists()


def test_bad_ablation_is_a_user_error(tmp_path):
    r = run(
        "train",
        "diffusion-ac",
        "--run-dir",
        str(tmp_path),
        "--ablation",
        "nope",
        "--total-steps",
        "10",
        "--no-progress",
    )
    assert r.returncode == 2 and "ablation" in r.stdout + r.stderr


def test_mode_summary():
    from cdr_bench.evaluate.analysis import mode_summary

    s = mode_summary([0] * 26 + [10])
    assert s == {"modes": 1, "normalised_entropy": 0.0}
    u = mode_summary([1] * 27, threshold=0.01)
    assert u["modes"] == 27 and abs(u["normalised_entropy"] - 1) < 1e-9
    assert np.isclose(mode_summary([5, 5] + [0] * 25)["normalised_entropy"], np.log(2) / np.log(27))
