"""A careless input is a one-line error in bounded time and memory, never a traceback, a hang
or a silent wrong answer: a numeric flag out of its range (checked when the flags are parsed,
cdr_bench.checks.ranged), a device or named pipe given as a result, sweep or agent file, an
agent in a crowded folder, a limit above the host's, an environment stepped before ``reset``,
a metric that cannot be computed, an edited result. Commands run in this process
(:func:`cdr_bench.cli.main`) except where a regression would block the test (a named pipe)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cdr_bench.cli import build_parser, main

ROOT = Path(__file__).resolve().parents[2]
MVP = str(ROOT / "agents" / "mvp")
DIRECT = str(ROOT / "agents" / "direct")
FIFO = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes")


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, str]:
    """Results of mvp and direct on the same 4 episodes of ``low``: mvp has no LoS there."""
    from cdr_bench.evaluate.api import evaluate, resolve_jobs

    tmp = tmp_path_factory.mktemp("results")
    jobs, _ = resolve_jobs(["low"], None, 4)
    for agent, name in ((MVP, "mvp"), (DIRECT, "direct")):
        evaluate(agent, jobs, tmp / f"{name}.json", batch_size=4, progress=False)
    return str(tmp / "mvp.json"), str(tmp / "direct.json")


def cdr(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    """``cdr-bench ARGS`` in this process: (exit code, standard output, standard error)."""
    capsys.readouterr()
    code = main(list(args))
    out, err = capsys.readouterr()
    return code, out, err


def one_line(err: str) -> None:
    assert "Traceback" not in err and err.count("\n") == 1, err


# --- flags: every numeric flag has a range, checked when parsed -------------------------------

TIMEOUT = "--timeout: expected a value in (0, 604800]"
BAD_FLAGS = [
    ("evaluate mvp --episodes 1000000000000", "--episodes: expected a value in [1, 100000]"),
    ("evaluate mvp --batch-size 1000000000", "--batch-size: expected a value in [1, 10000]"),
    ("evaluate mvp --seed -1", "--seed: expected a value in [0, 9223372036854775807]"),
    ("evaluate mvp --workers 0", "--workers: expected a value in [1, 512], got 0"),
    ("evaluate mvp --decision-timeout nan", "--decision-timeout: expected a value in (0"),
    ("evaluate mvp --load-timeout inf", "--load-timeout: expected a value in (0"),
    ("render low --out x.gif --fps 0", "--fps: expected a value in [1, 100], got 0"),
    ("render low --out x.gif --seed -1", "--seed: expected a value in [0"),
    ("render low --out x.gif --max-frames -1", "--max-frames: expected a value in [1"),
    ("render low --out x.gif --zoom-km nan", "--zoom-km: expected a value in (0, inf]"),
    ("multimodal mvp --threshold nan", "--threshold: expected a value in [0, 1], got nan"),
    ("multimodal mvp --samples 0", "--samples: expected a value in [1, 10000], got 0"),
    ("multimodal mvp --seed -1", "--seed: expected a value in [0"),
    ("latency mvp --threads 0", "--threads: expected a value in [1, 1024], got 0"),
    ("latency mvp --batch-sizes 1,100000", "--batch-sizes: expected a value in [1, 10000]"),
    ("latency mvp --warmup -1", "--warmup: expected a value in [0"),
    ("scenarios certify low --episodes 0", "--episodes: expected a value in [1, 100000]"),
    ("scenarios certify low --enough 9", "--enough: expected a value in [1, 5], got 9"),
    ("sweep x.yaml --episodes 0", "--episodes: expected a value in [1, 100000], got 0"),
    ("sweep x.yaml --total-steps -5", "--total-steps: expected a value in [1"),
    ("leaderboard build --timeout nan", f"{TIMEOUT}, got nan"),
    ("leaderboard build --timeout inf", f"{TIMEOUT}, got inf"),
    ("leaderboard build --cpu-limit 1e20", "--cpu-limit: expected a whole number, got '1e20'"),
    (
        "leaderboard build --cpu-limit 100000000000000000000",
        "--cpu-limit: expected a value in [1, 2592000]",
    ),
    (
        "leaderboard build --memory-limit 1000000000000000",
        "--memory-limit: expected a value in [64, 4194304]",
    ),
    ("leaderboard build --memory-limit 10", "--memory-limit: expected a value in [64"),
    ("leaderboard build --workers 0", "--workers: expected a value in [1, 512], got 0"),
    ("leaderboard build --episodes -3", "--episodes: expected a value in [1, 100000]"),
]


@pytest.mark.parametrize(("argv", "words"), BAD_FLAGS, ids=[a for a, _ in BAD_FLAGS])
def test_a_flag_out_of_its_range_is_refused_when_parsed(capsys, argv, words) -> None:
    """Only the parser runs: a value that used to be accepted never reaches the command (an
    --episodes 1e12 run exhausted memory; --fps 0 divided by zero; nan lifted a limit)."""
    with pytest.raises(SystemExit) as e:
        build_parser().parse_args(argv.split())
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {words}" in err, err
    assert "Traceback" not in err and err.strip().splitlines()[-1].startswith("cdr-bench")


def test_the_defaults_and_the_caps_themselves_are_accepted() -> None:
    p = build_parser()
    for argv in (
        ["evaluate", "mvp", "--episodes", "100000", "--batch-size", "10000", "--seed", "0"],
        ["render", "low", "--out", "x.gif", "--fps", "100", "--zoom-km", "inf"],
        ["multimodal", "mvp", "--threshold", "0"],
        ["latency", "mvp", "--batch-sizes", "1,8,64,256", "--threads", "1"],
        ["leaderboard", "build", "--timeout", "604800", "--memory-limit", "64"],
    ):
        p.parse_args(argv)
    ns = p.parse_args(["leaderboard", "build"])
    assert (ns.cpu_limit, ns.memory_limit, ns.timeout) == (3600, 6144, 3600.0)


def test_a_limit_above_the_hosts_hard_limit_is_a_one_line_error(capsys, monkeypatch) -> None:
    """The scorer applies the limits in its children (setrlimit between fork and exec), which
    ended in a SubprocessError traceback when the host's hard limit was lower."""
    import resource

    real = resource.getrlimit
    hard = {resource.RLIMIT_CPU: 1000, resource.RLIMIT_AS: 2048 << 20}

    def low(which: int) -> tuple[int, int]:
        return (hard[which], hard[which]) if which in hard else real(which)

    monkeypatch.setattr(resource, "getrlimit", low)
    for flags, words in [
        (["--cpu-limit", "999"], "--cpu-limit 999: this host's hard limit allows at most 995 CPU"),
        (["--cpu-limit", "900", "--memory-limit", "4096"], "--memory-limit 4096: this host's hard "
         "limit allows at most 2048 MiB"),
    ]:  # fmt: skip
        code, _, err = cdr(capsys, "leaderboard", "build", "--dir", "/no/such/dir", *flags)
        assert code == 2 and words in err
        one_line(err)


# --- input files: regular files, capped -------------------------------------------------------


@pytest.mark.skipif(not Path("/dev/zero").exists(), reason="needs /dev/zero")
@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["report", "/dev/zero"], "/dev/zero: is a character device, not a result file"),
        (["compare", "/dev/zero", "/dev/zero"], "/dev/zero: is a character device, not a result"),
        (["sweep", "/dev/zero"], "/dev/zero: is a character device, not a sweep file"),
    ],
)
def test_a_device_as_an_input_file_is_a_one_line_error(capsys, argv, words) -> None:
    """`report /dev/zero` read until MemoryError."""
    t0 = time.monotonic()
    code, _, err = cdr(capsys, *argv)
    assert code == 2 and words in err
    one_line(err)
    assert time.monotonic() - t0 < 10


def test_an_oversized_input_is_refused_unread(tmp_path) -> None:
    from cdr_bench.checks import read_input
    from cdr_bench.errors import UserError

    big = tmp_path / "big.json"
    with open(big, "wb") as f:
        f.truncate(2000)  # sparse
    with pytest.raises(UserError, match="2000 bytes, larger than a result file may be"):
        read_input(big, 1000, "result file")
    assert read_input(big, 2000, "result file") == bytes(2000)


@FIFO
@pytest.mark.parametrize("what", ["result", "agent", "agent folder"])
def test_a_named_pipe_as_an_input_does_not_block(tmp_path, what) -> None:
    """A named pipe as result or agent waited for a writer for ever: run in a child process
    with a time limit, so a regression fails instead of hanging the suite."""
    if what == "result":
        os.mkfifo(tmp_path / "r.json")
        argv, words = ["report", "r.json"], "r.json: is a named pipe (FIFO), not a result file"
    elif what == "agent":
        os.mkfifo(tmp_path / "agent.py")
        argv = ["evaluate", "agent.py", "--scenario", "low", "--episodes", "1"]
        words = "agent file agent.py: is a named pipe (FIFO), not a Python file"
    else:  # a pipe among the files hashed into the agent's identity
        (tmp_path / "agent.py").write_text((ROOT / "agents" / "mvp" / "agent.py").read_text())
        os.mkfifo(tmp_path / "weights.pt")
        argv = ["evaluate", ".", "--scenario", "low", "--episodes", "1", "--out", "o.json"]
        words = "weights.pt: is a named pipe (FIFO), not a file an agent may be made of"
    r = subprocess.run(
        [sys.executable, "-m", "cdr_bench.cli", *argv],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2 and words in r.stderr, r.stderr
    one_line(r.stderr)


def test_an_agent_in_a_crowded_folder_is_refused_at_once(capsys, tmp_path, monkeypatch) -> None:
    """`evaluate /tmp/x/agent.py` hashed every file beside it (18,890: 150 s, no output)."""
    from cdr_bench.evaluate import loader

    (tmp_path / "agent.py").write_text("class Agent: ...\n")
    (tmp_path / "lib").mkdir()
    for i in range(loader.MAX_AGENT_FILES + 1):
        (tmp_path / "lib" / f"m{i}.py").touch()
    t0 = time.monotonic()
    code, _, err = cdr(capsys, "evaluate", str(tmp_path), "--scenario", "low", "--episodes", "1")
    assert code == 2 and f"more than {loader.MAX_AGENT_FILES} files to hash" in err
    one_line(err)
    assert time.monotonic() - t0 < 10
    monkeypatch.setattr(loader, "MAX_AGENT_ENTRIES", 100)  # folders and other files count too
    code, _, err = cdr(capsys, "evaluate", str(tmp_path), "--scenario", "low", "--episodes", "1")
    assert code == 2 and "more than 100 files and folders" in err


# --- environments: no step before reset ---------------------------------------------------------


def test_the_vector_env_refuses_step_before_reset_and_a_bad_slot() -> None:
    from cdr_bench.errors import ArgumentError, ResetNeeded
    from cdr_bench.vector_env import VectorEnv

    env = VectorEnv("low", num_envs=3)
    hold = np.full((3, env.n_agents), 13)
    with pytest.raises(ResetNeeded, match=r"step\(\) before reset\(\).*\[0, 1, 2\] of 3"):
        env.step(hold)  # returned zeros
    env.reset(episodes=[0, 1])
    with pytest.raises(ResetNeeded, match=r"slot\(s\) \[2\] of 3 never started"):
        env.step(hold)
    env.reset(episodes=[2])
    env.step(hold)
    before = env.outcomes.copy()
    for bad in ([-1], [3], [0, 0], [0.5]):  # [-1] ended the last episode
        with pytest.raises(ArgumentError, match=r"end_episodes\(episodes=...\) expects distinct"):
            env.end_episodes(bad)
    assert np.array_equal(env.outcomes, before)
    env.end_episodes([2])
    assert (env.outcomes[2] != before[2]).any()


def test_the_gymnasium_vector_env_refuses_step_before_reset() -> None:
    import gymnasium as gym

    import cdr_bench  # noqa: F401  (registers the ids)
    from cdr_bench.errors import ResetNeeded

    env = gym.make_vec("cdr_bench/Ownship-v0", num_envs=2, vectorization_mode="vector_entry_point")
    with pytest.raises(ResetNeeded, match=r"step\(\) before reset\(\)"):
        env.step(np.full(2, 13))
    env.reset(seed=1)
    env.step(np.full(2, 13))


# --- results: a metric that cannot be computed, an edited value ---------------------------------


def test_compare_explains_a_metric_it_cannot_compute(capsys, tmp_path, results) -> None:
    """mvp has no LoS in these episodes: its intrusion severity (a mean over the flights with
    a LoS) has no value. compare printed `nan` without a word."""
    mvp, direct = results
    out = tmp_path / "cmp.json"
    code, table, err = cdr(capsys, "compare", mvp, direct, "--json", str(out))
    assert code == 0, err
    assert "nan" not in table
    row = next(ln for ln in table.splitlines() if "intrusion_severity" in ln)
    assert row.split()[3] == "n/a" and row.split()[5] == "n/a"
    assert (
        "note: intrusion_severity cannot be computed for A on low/ownship: no episode it is "
        "averaged over (1 - min separation / LoS threshold, over the flights with a LoS)" in err
    )
    rows = json.loads(out.read_text())["rows"]
    assert next(r for r in rows if r["metric"] == "intrusion_severity")["undefined"] == ["A"]
    assert all("undefined" not in r for r in rows if r["metric"] == "success_rate")


def test_report_refuses_a_result_with_edited_metrics(capsys, tmp_path, results) -> None:
    """Metrics are computed from the per-episode log when a result is read; a result that
    carries stored metrics (an edited value, outside its own interval) is refused."""
    mvp, _ = results
    data = json.loads(Path(mvp).read_text())
    data["scenarios"][0]["metrics"] = {"ownship": {"success_rate": {"value": 1.5}}}
    edited = tmp_path / "mvp.json"
    edited.write_text(json.dumps(data))
    log = Path(mvp).with_suffix(".jsonl.xz")
    (tmp_path / log.name).write_bytes(log.read_bytes())
    code, _, err = cdr(capsys, "report", str(edited))
    assert code == 2 and "scenario low carries stored metrics" in err
    one_line(err)
    code, text, err = cdr(capsys, "report", mvp)
    assert code == 0 and "150" not in text
