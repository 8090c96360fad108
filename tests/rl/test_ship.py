"""``sweeps/seeds/ship.py --stage``: finished trials are staged once; a trial whose checkpoint
is already shipped into an agent folder is not staged again (one copy of each checkpoint)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

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
    out = capsys.readouterr().out
    assert "skip bbb: already shipped as agents/x/seeds/2/checkpoint.pt" in out
    assert "skip ccc: not finished" in out
