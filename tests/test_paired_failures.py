"""sweeps/paired_failures.py counts the failures of each side on paired episodes."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _mod():
    spec = importlib.util.spec_from_file_location("pf", ROOT / "sweeps" / "paired_failures.py")
    m = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(m)
    return m


def _write(path: Path, outcomes: list[tuple[int, bool, str]]) -> None:
    rows = [
        {"scenario": "high", "seed": s, "aircraft": [{"los": los, "nmac": False, "outcome": o}]}
        for s, los, o in outcomes
    ]
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))


def test_counts_fixed_new_and_both(tmp_path, capsys) -> None:
    ok, los = (False, "success"), (True, "success")
    _write(tmp_path / "a.jsonl", [(1, *los), (2, *ok), (3, *los)])
    _write(tmp_path / "b.jsonl", [(1, *ok), (2, False, "timeout"), (3, *los)])
    assert _mod().main([str(tmp_path / "a.jsonl"), str(tmp_path / "b.jsonl")]) == 0
    assert "3 episodes, fixed 1, new 1, both 1" in capsys.readouterr().out


def test_bad_file_is_a_clear_error(tmp_path, capsys) -> None:
    (tmp_path / "bad.jsonl").write_text("{not json\n")
    assert _mod().main([str(tmp_path / "missing.jsonl"), str(tmp_path / "bad.jsonl")]) == 2
    assert "not a per-episode result file" in capsys.readouterr().err


def test_a_compressed_candidate_is_read_as_it_is(tmp_path, capsys) -> None:
    """A staged trial keeps its per-episode file as ``result.jsonl.gz``."""
    import gzip

    ok, los = (False, "success"), (True, "success")
    _write(tmp_path / "a.jsonl", [(1, *los), (2, *ok)])
    _write(tmp_path / "b.jsonl", [(1, *ok), (2, *ok)])
    (tmp_path / "b.jsonl.gz").write_bytes(gzip.compress((tmp_path / "b.jsonl").read_bytes()))
    (tmp_path / "b.jsonl").unlink()
    assert _mod().main([str(tmp_path / "a.jsonl"), str(tmp_path / "b.jsonl.gz")]) == 0
    assert "2 episodes, fixed 1, new 0, both 0" in capsys.readouterr().out
