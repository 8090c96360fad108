"""``cdr-bench sweep`` on a local Ray and ``cdr-bench evaluate --backend ray``."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest

pytest.importorskip("ray")

import cdr_bench.scale.ray_eval  # noqa: E402, F401  (registers the evaluator's 'ray' backend)
from cdr_bench.errors import UserError  # noqa: E402
from cdr_bench.evaluate.api import evaluate, resolve_jobs  # noqa: E402
from cdr_bench.scale.config import load_sweep  # noqa: E402
from cdr_bench.scale.plot import plot_sweep  # noqa: E402
from cdr_bench.scale.sweep import ELSEWHERE, RESULT_FILE, TRIAL_FILE, run_sweep  # noqa: E402

from .helpers import REPO, tiny_sweep  # noqa: E402


@pytest.fixture(scope="module")
def local_ray():
    import ray

    from cdr_bench.scale.sweep import ray_init

    ray_init(ray, None, 2)
    yield ray
    ray.shutdown()


@pytest.mark.slow
def test_sweep_runs_and_resumes(local_ray, tmp_path):
    sweep = load_sweep(tiny_sweep(tmp_path, [1]))
    out = tmp_path / "out"
    summary = run_sweep(sweep, out, progress=False)
    assert [t["done"] for t in summary["trials"]] == [True]
    for t in sweep.trials:
        rec = json.loads((out / t.key / TRIAL_FILE).read_text())
        assert rec["seed"] == t.seed and rec["ray_node"]
        result = json.loads((out / t.key / RESULT_FILE).read_text())
        assert result["kind"] == "cdr-bench evaluation"
        assert result["agent"]["path"] == str(out.resolve() / t.key / "agent.py")
        assert (out / t.key / "result.jsonl.xz").is_file()
        assert not (out / t.key / "state.pt").exists()
    assert not (out / ".work").exists()
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [t.key for t in sweep.trials] + ["sweep.json", "sweep.yaml"]
    )

    with pytest.raises(UserError, match="--resume"):
        run_sweep(sweep, out, progress=False)
    # a second seed: --resume runs only it, the finished trial stays untouched
    stamps = {t.key: os.stat(out / t.key / TRIAL_FILE).st_mtime_ns for t in sweep.trials}
    bigger = load_sweep(tiny_sweep(tmp_path, [1, 2]))
    run_sweep(bigger, out, resume=True, progress=False)
    assert {t.key: os.stat(out / t.key / TRIAL_FILE).st_mtime_ns for t in sweep.trials} == stamps
    assert all((out / t.key / RESULT_FILE).is_file() for t in bigger.trials)

    data = plot_sweep(out, tmp_path / "fig.png", json_out=tmp_path / "fig.json")
    assert (tmp_path / "fig.png").stat().st_size > 0
    assert len(data["factors"]["default"]["default"]["success"]) == 2  # one per seed


@pytest.mark.slow
def test_failed_trial_is_reported_and_others_kept(local_ray, tmp_path):
    # a scenario that does not exist passes the sweep's flag checks (a name is a string); the
    # trainer refuses it at start-up
    sweep = load_sweep(tiny_sweep(tmp_path, [1], grid={"scenario": ["low", "no-such-scenario"]}))
    out = tmp_path / "out"
    with pytest.raises(UserError, match="1 of 2 trials failed"):
        run_sweep(sweep, out, progress=False)
    summary = json.loads((out / "sweep.json").read_text())
    good, bad = sweep.trials
    assert list(summary["failures"]) == [bad.key]
    assert "train exited with" in summary["failures"][bad.key]
    assert (out / good.key / RESULT_FILE).is_file()
    assert not (out / bad.key).exists() and not (out / ".work").exists()


def _strip(path: Path) -> dict:
    d = json.loads(path.read_text())
    d.pop("timing")
    d.pop("episodes_file")
    return d


def test_evaluate_ray_backend_equals_local(local_ray, tmp_path):
    jobs, _ = resolve_jobs(["tactical/head-on", "low"], None, 5)
    agent = REPO / "agents" / "random" / "agent.py"
    a = evaluate(agent, jobs, tmp_path / "local.json", batch_size=2, workers=1, progress=False)
    b = evaluate(
        agent, jobs, tmp_path / "ray.json", batch_size=2, workers=2, progress=False, backend="ray"
    )
    assert b["timing"]["backend"] == "ray" and a["timing"]["backend"] == "local"
    assert _strip(tmp_path / "local.json") == _strip(tmp_path / "ray.json")
    assert (tmp_path / "local.jsonl.xz").read_bytes() == (tmp_path / "ray.jsonl.xz").read_bytes()
    with pytest.raises(UserError, match="--address needs --backend ray"):
        evaluate(agent, jobs, tmp_path / "x.json", address="127.0.0.1:1", progress=False)


@pytest.mark.slow
def test_a_dead_attempt_is_resumed_not_restarted(tmp_path, capsys):
    """A sweep killed mid-training (e.g. at the end of a session) leaves its work folder with
    the trainer's saved state; the next attempt takes it over with ``cdr-bench train --resume``
    (log lines written after that state dropped), and never takes a live attempt's folder."""
    import fcntl

    from cdr_bench.cli import main
    from cdr_bench.scale.sweep import run_trial

    (trial,) = load_sweep(tiny_sweep(tmp_path, [1])).trials
    out = tmp_path / "out"
    dead = out / ".work" / f"{trial.key}-dead0001"
    argv = trial.train_argv(str(dead))
    argv[argv.index("--total-steps") + 1] = "60"  # the attempt "died" at its state of step 60
    assert main(["train", *argv]) == 0, capsys.readouterr().err[-2000:]
    assert (dead / "state.pt").is_file()
    with open(dead / "log.jsonl", "a") as f:
        f.write('{"step": 999999, "lost": true}\n{"step": 1000')  # written after the state

    live = out / ".work" / f"{trial.key}-live0002"  # a running attempt: locked, never taken
    live.mkdir()
    (live / "state.pt").write_bytes(b"x")
    fd = os.open(live / ".lock", os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX)
    try:  # while another process runs the trial, this one leaves it alone
        assert run_trial(trial, str(out)) == {"key": trial.key, ELSEWHERE: True}
    finally:
        os.close(fd)
    assert (live / "state.pt").read_bytes() == b"x"  # untouched
    shutil.rmtree(live)  # that process ended without a state worth resuming
    rec = run_trial(trial, str(out))
    assert rec["resumed"] == "train" and rec["attempt"] == dead.name
    rows = [json.loads(x) for x in (out / trial.key / "log.jsonl").read_text().splitlines()]
    steps = [r["step"] for r in rows if "step" in r]
    assert steps == sorted(steps) and 999999 not in steps and len(set(steps)) == len(steps)
    assert rows[-1]["final"]["step"] >= 120 and steps[0] <= 60 < steps[-1]
