"""``sweeps/landed.py``: ``slim`` keeps a landed run's settings, summary, compressed training
log and curve (its committed checkpoint and per-episode file go to the git history);
``restore`` writes the run back as the sweep wrote it, those two taken from the history and
checked against the SHA-256 its result recorded."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
from pathlib import Path

import pytest

from .helpers import sweep_script

GIT_ENV = {
    "GIT_AUTHOR_NAME": "t",
    "GIT_AUTHOR_EMAIL": "t@t",
    "GIT_COMMITTER_NAME": "t",
    "GIT_COMMITTER_EMAIL": "t@t",
}


def _git(root: Path, *args: str) -> None:
    subprocess.run(
        ["git", *args], cwd=root, check=True, capture_output=True, env={**os.environ, **GIT_ENV}
    )


def _trial(d: Path, weights: bytes, scored: bytes | None = None) -> dict[str, bytes]:
    """A trial as ``cdr-bench sweep`` writes it; returns its files' bytes."""
    d.mkdir(parents=True)
    sha = hashlib.sha256(scored if scored is not None else weights).hexdigest()
    episodes = b'{"scenario": "high", "episode": 0}\n' * 50
    result = {
        "agent": {"files": {"checkpoint.pt": sha}},
        "episodes_file": "result.jsonl",
        "episodes_sha256": hashlib.sha256(episodes).hexdigest(),
    }
    files = {
        "trial.json": json.dumps({"seed": 1, "result": "result.json"}).encode(),
        "args.json": b"{}\n",
        "result.json": json.dumps(result).encode(),
        "result.jsonl": episodes,
        "log.jsonl": b'{"step": 1}\n{"final": {"step": 1}}\n',
        "checkpoint.pt": weights,
    }
    for name, data in files.items():
        (d / name).write_bytes(data)
    return files


@pytest.fixture
def repo(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):  # type: ignore[no-untyped-def]
    landed = sweep_script("landed")
    monkeypatch.setattr(landed, "ROOT", tmp_path)
    _git(tmp_path, "init", "-q")
    return landed, tmp_path


def test_slim_then_restore_gives_the_sweep_output_back(repo, capsys) -> None:  # type: ignore[no-untyped-def]
    landed, root = repo
    sweep = root / "sweeps" / "landed" / "s"
    a = _trial(sweep / "a", b"weights a")
    _trial(sweep / "b", b"weights b")
    (sweep / "b" / "curve.png").write_bytes(b"png")
    # named by a committed script: kept; not committed as it is: kept
    _trial(sweep / "c", b"weights c")
    (root / "agents" / "x").mkdir(parents=True)
    (root / "agents" / "x" / "score.sh").write_text("ck=sweeps/landed/s/c/checkpoint.pt\n")
    _git(root, "add", ".")
    _git(root, "commit", "-qm", "landed")
    (sweep / "b" / "checkpoint.pt").write_bytes(b"weights b, edited")
    assert landed.main(["slim", str(sweep)]) == 0
    out = capsys.readouterr().out
    assert (
        "s/a: log.jsonl.gz; checkpoint.pt removed (in the git history); "
        "result.jsonl removed (in the git history)"
    ) in out
    assert "s/b: log.jsonl.gz; checkpoint.pt kept (not committed as it is" in out
    assert "s/c: log.jsonl.gz; checkpoint.pt kept (named by agents/x/score.sh)" in out
    assert sorted(p.name for p in (sweep / "a").iterdir()) == [
        "args.json", "log.jsonl.gz", "result.json", "trial.json"
    ]  # fmt: skip
    assert (sweep / "b" / "curve.png").is_file()
    gz = (sweep / "a" / "log.jsonl.gz").read_bytes()
    assert landed.main(["slim", str(sweep)]) == 0  # again: nothing changes
    assert (sweep / "a" / "log.jsonl.gz").read_bytes() == gz
    _git(root, "add", "-A")
    _git(root, "commit", "-qm", "slim")

    dest = root / "runs" / "sweeps" / "s"
    assert landed.main(["restore", str(sweep)]) == 0
    for name, data in a.items():
        assert (dest / "a" / name).read_bytes() == data, name
    assert not (dest / "a" / "log.jsonl.gz").exists()
    assert (dest / "b" / "curve.png").is_file()
    out = capsys.readouterr().out
    assert "a: restored, checkpoint.pt from the git history, result.jsonl from the git" in out


def test_restore_refuses_a_checkpoint_that_is_not_the_one_scored(repo, capsys) -> None:  # type: ignore[no-untyped-def]
    landed, root = repo
    sweep = root / "sweeps" / "landed" / "s"
    _trial(sweep / "a", b"weights a", scored=b"other weights")
    _git(root, "add", ".")
    _git(root, "commit", "-qm", "landed")
    assert landed.main(["slim", str(sweep)]) == 0
    _git(root, "add", "-A")
    _git(root, "commit", "-qm", "slim")
    assert landed.main(["restore", str(sweep), str(root / "out")]) == 1
    assert "without checkpoint.pt (the one in history is not the one its result names)" in (
        capsys.readouterr().out
    )
    assert not (root / "out" / "a" / "checkpoint.pt").exists()
    assert (root / "out" / "a" / "log.jsonl").is_file()
    assert (root / "out" / "a" / "result.jsonl").is_file()  # this one is the one it names


def test_not_a_landed_folder_is_a_clear_error(repo, capsys) -> None:  # type: ignore[no-untyped-def]
    landed, root = repo
    assert landed.main(["slim", str(root / "missing")]) == 2
    assert "missing: not a folder of landed runs" in capsys.readouterr().err


def test_a_staged_trial_is_slimmed_and_restored_from_its_compressed_files(repo, capsys) -> None:  # type: ignore[no-untyped-def]
    """``ship.py --stage`` commits the per-episode file and the log compressed; ``slim``
    removes the committed ``result.jsonl.gz`` and ``restore`` gives back the plain file."""
    from cdr_bench.jsonl import gzip_file

    landed, root = repo
    sweep = root / "sweeps" / "landed" / "s"
    files = _trial(sweep / "a", b"weights a")
    gzip_file(sweep / "a" / "result.jsonl")
    gzip_file(sweep / "a" / "log.jsonl")
    _git(root, "add", ".")
    _git(root, "commit", "-qm", "staged")
    assert landed.main(["slim", str(sweep)]) == 0
    assert "result.jsonl.gz removed (in the git history)" in capsys.readouterr().out
    assert not (sweep / "a" / "result.jsonl.gz").exists()
    _git(root, "add", "-A")
    _git(root, "commit", "-qm", "slim")
    assert landed.main(["restore", str(sweep), str(root / "out")]) == 0
    for name, data in files.items():
        assert (root / "out" / "a" / name).read_bytes() == data, name
