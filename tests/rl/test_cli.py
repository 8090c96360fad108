"""``cdr-bench train`` wiring, user errors, and the analysis commands on a trained checkpoint."""

import json

import numpy as np
import pytest

from .helpers import agent_module, cdr_bench, summary


def test_train_help_lists_every_trainer_and_its_flags(capsys):
    from cdr_bench.rl.cli import TRAINERS
    from cdr_bench.rl.train_sb3 import main as train_sb3

    r = cdr_bench("train", "--help")
    assert r.returncode == 0 and all(name in r.stdout for name in TRAINERS)
    for name, flag in (("td3", "--action-noise"), ("rainbow", "--n-atoms"), ("ppo", "--n-steps")):
        r = cdr_bench("train", name, "--help")
        assert r.returncode == 0 and flag in r.stdout and "--max-episode-steps" in r.stdout
    assert "runs/maskable-ppo" in cdr_bench("train", "maskable-ppo", "--help").stdout
    with pytest.raises(SystemExit) as e:  # python -m cdr_bench.rl.train_sb3 td3 --help
        train_sb3(["td3", "--help"])
    assert e.value.code == 0 and "--action-noise" in capsys.readouterr().out


def test_sweeps_read_every_trainers_flags():
    from cdr_bench.rl.cli import TRAINERS
    from cdr_bench.scale.config import trainer_parser

    for name in TRAINERS:
        known = {a.option_strings[0] for a in trainer_parser(name)._actions if a.option_strings}
        assert {"--run-dir", "--seed", "--total-steps", "--resume", "--failure-penalty"} <= known


@pytest.mark.slow
def test_trained_checkpoint_with_agent_latency_and_multimodal(tmp_path, monkeypatch):
    d = tmp_path / "run"
    tiny = [
        "--n-envs", "8", "--learning-starts", "64", "--batch-size", "16", "--log-every", "50",
        "--eval-episodes", "0", "--no-progress", "--width", "32", "--buffer-size", "1000",
        "--curve-every", "0",  # no learning-curve point (100 episodes) and plot: not tested here
    ]  # fmt: skip
    r = cdr_bench("train", "diffusion-ac", "--run-dir", str(d), "--total-steps", "200", *tiny)
    assert r.returncode == 0, r.stderr
    first = summary(r.stdout)
    assert first["step"] >= 200 and first["updates"] > 0

    # The agent protocol with this checkpoint, deterministic given the seed.
    env = {"CDR_BENCH_CHECKPOINT": str(d / "checkpoint.pt")}
    monkeypatch.setenv("CDR_BENCH_CHECKPOINT", env["CDR_BENCH_CHECKPOINT"])
    a = agent_module("diffusion_ac").Agent(None, None)
    monkeypatch.undo()
    o = np.random.default_rng(0).uniform(-1, 1, (64, 42)).astype(np.float32)
    k = np.ones((64, 27), np.int8)
    k[:, 2::3] = 0
    a.reset(3)
    x = a.act_batch(o, k)
    a.reset(3)
    y = a.act_batch(o, k)
    assert (x == y).all() and (x % 3 != 2).all()
    assert isinstance(a.act({"observation": o[0], "action_mask": k[0]}), int)

    # the agent's process loads torch and the checkpoint, and the limits leave room for a loaded
    # machine: no time limit is under test here
    roomy = ["--load-timeout", "3600", "--decision-timeout", "3600"]

    r = cdr_bench(
        "latency",
        "agents/diffusion_ac",
        "--batch-sizes",
        "1,4",
        "--decisions",
        "8",
        "--min-calls",
        "3",
        *roomy,
        env=env,
    )
    assert r.returncode == 0, r.stderr
    assert "| 1 | 8 | 8 |" in r.stdout and "| 4 | 3 | 12 |" in r.stdout  # calls, decisions
    r = cdr_bench("latency", "agents/diffusion_ac", "--batch-sizes", "1,x", env=env)
    assert r.returncode == 2 and "--batch-sizes" in r.stdout + r.stderr

    out = tmp_path / "mm.json"
    r = cdr_bench(
        "multimodal",
        "agents/diffusion_ac",
        "--scenario",
        "curriculum/stage-01",
        "--episodes",
        "1",
        "--samples",
        "16",
        "--max-steps",
        "5",
        "--out",
        str(out),
        *roomy,
        env=env,
    )
    assert r.returncode == 0, r.stderr
    res = json.loads(out.read_text())
    assert sum(res["all"]) == 16 and 0 <= res["normalised_entropy"] <= 1
    assert out.with_suffix(".png").exists()


def test_bad_choices_are_user_errors(tmp_path):
    for name, flag, value in (
        ("diffusion-ac", "--ablation", "nope"),
        ("diffusion-ac", "--explore", "greedy"),
        ("safe-dqn-x", "--combine", "max"),
    ):
        r = cdr_bench("train", name, "--run-dir", str(tmp_path), flag, value, "--no-progress")
        assert r.returncode == 2 and flag.strip("-").replace("-", "_") in r.stdout + r.stderr
    assert not (tmp_path / "log.jsonl").exists()  # nothing written before the flags are checked


@pytest.mark.parametrize(
    ("flags", "words"),
    [
        (["--scenario", "nosuch"], "--scenario nosuch: nosuch: unknown scenario name"),
        (["--resume"], "--resume: {run}/state.pt does not exist: nothing to resume"),
        (["--run-dir", "{file}"], "--run-dir {file}: exists and is not a folder"),
    ],
)
def test_missing_scenario_state_or_folder_is_a_user_error(tmp_path, flags, words):
    run, file = tmp_path / "run", tmp_path / "file"
    file.write_text("x")
    flags = [f.format(run=run, file=file) for f in flags]
    r = cdr_bench("train", "td3", "--run-dir", str(run), *flags, "--no-progress")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert words.format(run=run, file=file) in r.stderr
    assert not run.exists()


def test_mode_summary():
    from cdr_bench.evaluate.analysis import mode_summary

    s = mode_summary([0] * 26 + [10])
    assert s == {"modes": 1, "normalised_entropy": 0.0}
    u = mode_summary([1] * 27, threshold=0.01)
    assert u["modes"] == 27 and abs(u["normalised_entropy"] - 1) < 1e-9
    assert np.isclose(mode_summary([5, 5] + [0] * 25)["normalised_entropy"], np.log(2) / np.log(27))
