"""``sweeps/seeds/ship.py --stage``: finished trials are staged once; a trial whose checkpoint
is already shipped into an agent folder is not staged again (one copy of each checkpoint)."""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import pytest

from cdr_bench.evaluate.results import compress_log, log_text

from .helpers import sweep_script


def _trial(sweep: Path, key: str, seed: int, weights: bytes, finished: bool = True) -> None:
    d = sweep / key
    d.mkdir(parents=True)
    (d / "trial.json").write_text(json.dumps({"seed": seed}))
    for f in ("result.json", "result.jsonl", "log.jsonl", "args.json"):
        (d / f).write_text("{}\n")
    if finished:
        (d / "checkpoint.pt").write_bytes(weights)


def test_stage_skips_shipped_and_unfinished_trials(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    ship = sweep_script("seeds/ship")
    monkeypatch.setattr(ship, "ROOT", tmp_path)
    agent = tmp_path / "agents" / "x" / "seeds" / "2"
    agent.mkdir(parents=True)
    (agent / "checkpoint.pt").write_bytes(b"seed-2 weights")
    sweep = tmp_path / "runs" / "sweeps" / "seeds-x"
    _trial(sweep, "aaa", 1, b"seed-1 weights")
    _trial(sweep, "bbb", 2, b"seed-2 weights")  # shipped already
    _trial(sweep, "ccc", 3, b"", finished=False)
    assert ship.main([str(sweep), "--stage"]) == 0
    landed = tmp_path / "sweeps" / "landed" / "seeds-x"
    assert sorted(p.name for p in landed.iterdir()) == ["aaa"]
    assert (landed / "aaa" / "checkpoint.pt").read_bytes() == b"seed-1 weights"
    # the per-episode file and the log compressed (deterministic gzip), the rest as written
    assert sorted(p.name for p in (landed / "aaa").iterdir()) == [
        "args.json", "checkpoint.pt", "log.jsonl.gz", "result.json", "result.jsonl.gz",
        "trial.json",
    ]  # fmt: skip
    assert gzip.decompress((landed / "aaa" / "log.jsonl.gz").read_bytes()) == b"{}\n"
    out = capsys.readouterr().out
    assert "skip bbb: already shipped as agents/x/seeds/2/checkpoint.pt" in out
    assert "skip ccc: not finished" in out


def test_stage_skips_a_trial_whose_shipped_checkpoint_was_edited(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    ship = sweep_script("seeds/ship")
    monkeypatch.setattr(ship, "ROOT", tmp_path)
    agent = tmp_path / "agents" / "x"
    agent.mkdir(parents=True)
    (agent / "checkpoint.pt").write_bytes(b"weights, margin 0.25")  # edited after shipping
    (agent / "training_log.jsonl").write_text('{"step": 1, "seed": 1}\n')
    sweep = tmp_path / "runs" / "sweeps" / "x"
    _trial(sweep, "aaa", 1, b"weights, margin 0.5")
    (sweep / "aaa" / "log.jsonl").write_text('{"step": 1, "seed": 1}\n')
    assert ship.main([str(sweep), "--stage"]) == 0
    assert not (tmp_path / "sweeps" / "landed" / "x" / "aaa").exists()
    assert "skip aaa: already shipped as agents/x/training_log.jsonl" in capsys.readouterr().out


def test_ship_one_setting_into_a_subfolder_keeps_the_other_settings_staged(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    ship = sweep_script("seeds/ship")
    monkeypatch.setattr(ship, "ROOT", tmp_path)
    agent = tmp_path / "agents" / "x"
    agent.mkdir(parents=True)
    (agent / "agent.py").write_text("class Agent: pass\n")
    sweep = tmp_path / "runs" / "sweeps" / "table3"
    for key, seed, ablation in (("a1", 1, "no-dpsc"), ("a2", 2, "no-dpsc"), ("b1", 1, "no-q")):
        _trial(sweep, key, seed, f"{ablation} {seed}".encode())
        t = sweep / key / "trial.json"
        t.write_text(json.dumps({"seed": seed, "train_flags": {"ablation": ablation}}))
    assert ship.main([str(sweep), "--stage"]) == 0
    landed = tmp_path / "sweeps" / "landed" / "table3"
    args = [str(sweep), str(agent), "--where", "ablation=no-dpsc", "--into", "ablations/no-dpsc"]
    assert ship.main(args) == 0
    dest = agent / "ablations" / "no-dpsc"
    assert (dest / "checkpoint.pt").read_bytes() == b"no-dpsc 1"
    assert (dest / "seeds" / "2" / "checkpoint.pt").read_bytes() == b"no-dpsc 2"
    assert not (agent / "checkpoint.pt").exists()  # the agent's own run untouched
    assert sorted(p.name for p in landed.iterdir()) == ["b1"]  # the other setting stays staged
    # without --where both settings match seed 1: refused, nothing written
    assert ship.main([str(sweep), str(agent), "--into", "ablations/all"]) == 2
    assert not (agent / "ablations" / "all").exists()
    assert ship.main([str(sweep), str(agent), "--into", "../elsewhere"]) == 2
    assert ship.main([str(sweep), str(agent), "--where", "ablation"]) == 2


def test_bad_arguments_are_clear_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    ship = sweep_script("seeds/ship")
    assert ship.main([str(tmp_path / "missing"), "--stage"]) == 2
    assert "missing: not a folder (expected a `cdr-bench sweep` output folder)" in (
        capsys.readouterr().err
    )
    assert ship.main([str(tmp_path)]) == 2
    assert "agent_dir: expected an agent folder holding agent.py" in capsys.readouterr().err
    assert ship.main([str(tmp_path), str(tmp_path)]) == 2
    assert f"{tmp_path}: expected an agent folder holding agent.py" in capsys.readouterr().err


def test_ship_from_a_folder_with_compressed_logs_writes_an_xz_training_log(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A staged trial keeps its log as ``log.jsonl.gz``; shipped, the agent gets the
    ``training_log.jsonl.xz`` its submission names (deterministic xz, read as the plain log),
    which replaces a plain log of an earlier run; the shipped log is recognised as shipped."""
    ship = sweep_script("seeds/ship")
    monkeypatch.setattr(ship, "ROOT", tmp_path)
    agent = tmp_path / "agents" / "x"
    agent.mkdir(parents=True)
    (agent / "agent.py").write_text("class Agent: pass\n")
    sweep = tmp_path / "runs" / "sweeps" / "x"
    _trial(sweep, "aaa", 1, b"weights")
    log = b'{"step": 1}\n{"final": {"step": 1}}\n'
    (sweep / "aaa" / "log.jsonl").unlink()
    (sweep / "aaa" / "log.jsonl.gz").write_bytes(gzip.compress(log))
    (agent / "training_log.jsonl").write_text('{"step": 0}\n')  # an earlier run's
    assert ship.main([str(sweep), str(agent)]) == 0
    assert (agent / "training_log.jsonl.xz").read_bytes() == compress_log(log.decode())
    assert log_text(agent / "training_log.jsonl.xz") == log.decode()
    assert not (agent / "training_log.jsonl").exists()
    assert (agent / "checkpoint.pt").read_bytes() == b"weights"
    assert "training_log: agents/x/training_log.jsonl.xz}" in capsys.readouterr().out
    (agent / "checkpoint.pt").write_bytes(b"weights, edited after shipping")
    (sweep / "aaa" / "log.jsonl").write_bytes(log)  # as the sweep wrote it
    assert ship.main([str(sweep), "--stage"]) == 0
    assert "skip aaa: already shipped as agents/x/training_log.jsonl.xz" in (
        capsys.readouterr().out
    )
