"""``cdr-bench multimodal`` with classical agents: spaces of the scenario, one-line load errors,
atomic JSON and PNG, the documented keys."""

import json
from pathlib import Path

import numpy as np
import pytest

from cdr_bench.cli import main
from cdr_bench.evaluate import analysis

ROOT = Path(__file__).resolve().parents[2]


def test_classical_agent_writes_json_and_png(tmp_path, capsys):
    out = tmp_path / "sub" / "mm.json"
    args = ["--scenario", "tactical/head-on", "--samples", "20", "--out", str(out)]
    assert main(["multimodal", str(ROOT / "agents" / "random"), *args]) == 0
    res = json.loads(out.read_text())
    for key in ("all", "success", "success_rate", "modes", "normalised_entropy", "threshold"):
        assert key in res, key
    assert len(res["all"]) == len(res["success"]) == 27
    assert sum(res["all"]) == 20 and sum(res["success"]) <= 20
    assert all(0 <= s <= a for s, a in zip(res["success"], res["all"], strict=True))
    assert 0.0 <= res["normalised_entropy"] <= 1.0
    assert res["modes"] == analysis.mode_summary(res["success"], 0.05)["modes"]
    assert out.with_suffix(".png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in out.parent.iterdir()) == ["mm.json", "mm.png"]  # no temp files

    # mvp reads the observation space (it crashed with None spaces before).
    out2 = tmp_path / "mvp.json"
    assert main(["multimodal", str(ROOT / "agents" / "mvp"), *args[:4], "--out", str(out2)]) == 0
    assert sum(json.loads(out2.read_text())["all"]) == 20


def test_load_errors_are_one_line_exit_2(tmp_path, capsys):
    bad = tmp_path / "agent.py"
    bad.write_text(
        "class Agent:\n    def __init__(self, o, a):\n        raise RuntimeError('no')\n"
    )
    for agent in (str(tmp_path / "missing"), str(bad)):
        assert main(["multimodal", agent, "--samples", "5"]) == 2
        err = capsys.readouterr().err
        assert err.startswith("cdr-bench: error:") and err.count("\n") == 1, err
        assert "Traceback" not in err


def test_failing_run_leaves_no_partial_files(tmp_path, monkeypatch):
    out = tmp_path / "mm.json"
    out.write_text("old")

    def broken_savefig(self, fname, *a, **k):  # writes a part of the picture, then fails
        if hasattr(fname, "write"):
            fname.write(b"\x89PNG partial")
        else:
            Path(fname).write_bytes(b"\x89PNG partial")
        raise OSError("disk full")

    import matplotlib.figure

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", broken_savefig)
    args = ["multimodal", str(ROOT / "agents" / "random"), "--samples", "5", "--out", str(out)]
    with pytest.raises(OSError, match="disk full"):
        main(args)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mm.json"]
    assert out.read_text() == "old"  # the old result is untouched, no new JSON without its PNG


def test_mode_summary_counts_modes_at_threshold():
    counts = [0] * 27
    counts[3], counts[5], counts[7] = 90, 6, 4  # 90 %, 6 %, 4 %
    s = analysis.mode_summary(counts, 0.05)
    assert s["modes"] == 2
    p = np.array([0.9, 0.06, 0.04])
    assert s["normalised_entropy"] == pytest.approx(-(p * np.log(p)).sum() / np.log(27))
