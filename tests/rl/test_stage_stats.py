"""sweeps/stage_stats.py: the numbers the Diffusion-AC README cites about stage 12."""

from __future__ import annotations

import json
from pathlib import Path

from .helpers import sweep_script


def _module():
    return sweep_script("stage_stats")


def test_windows_extremes_and_curve(tmp_path: Path) -> None:
    rolling = [0.8, 0.9, 0.4, 0.0, 0.3, 0.7, 0.45, 0.85]
    lines = [{"step": 10, "curriculum/stage": 11, "charts/success_rolling": 0.1}]
    for i, s in enumerate(rolling):
        lines.append(
            {
                "step": 100 * (i + 1),
                "curriculum/stage": 12,
                "charts/success_rolling": s,
                "charts/timeout": 0.5 if i == 3 else 0.0,
                "losses/loss_q": float(i),
                "losses/q_mean": -1.0 + (5.0 if i == 4 else 0.0),
            }
        )
    lines.append(
        {"step": 300, "curve/scenario": "high", "curve/episodes": 100, "curve/clean_success": 0.6}
    )
    lines.append({"final": {"step": 900}})
    log = tmp_path / "log.jsonl"
    log.write_text("\n".join(json.dumps(x) for x in lines) + "\n")
    out = _module().summarise(log, 12, 0.5)
    assert "stage 12 from 100 to 900 transitions (8 log lines)" in out
    assert "min 0.00  mean 0.55  max 0.90" in out
    assert "below 0.50: 300-500 (min 0.00); 700-700 (min 0.45)" in out
    assert "max TD loss +7.00 at 800" in out
    assert "max mean Q +4.00 at 500" in out
    assert "max Q -" in out  # absent key
    assert "max timeout share +0.50 at 400" in out
    assert "clean success min 0.60 mean 0.60 max 0.60 last 0.60" in out


def test_bad_input_is_one_line_error(tmp_path: Path, capsys) -> None:
    mod = _module()
    assert mod.main([str(tmp_path / "missing.jsonl")]) == 2
    bad = tmp_path / "bad.jsonl"
    bad.write_text("{not json\n")
    assert mod.main([str(bad)]) == 2
    err = capsys.readouterr().err
    assert "no such file" in err and "not a training log" in err


def test_overestimation_windows(tmp_path: Path) -> None:
    """Stretches of lines whose largest Q exceeds ``--q-above``: peak, lowest rolling success
    and largest timeout share of each; "never" when the critic stays bounded."""
    q = [1.1, 2.0, 9.0, 1.2, 1.0, 4.0]
    lines = [
        {
            "step": 100 * (i + 1),
            "curriculum/stage": 12,
            "charts/success_rolling": 0.9 - 0.1 * i,
            "charts/timeout": 0.01 * i,
            "losses/q_max": v,
        }
        for i, v in enumerate(q)
    ]
    log = tmp_path / "log.jsonl"
    log.write_text("\n".join(json.dumps(x) for x in lines) + "\n")
    mod = _module()
    out = mod.summarise(log, 12, 0.5, 1.5)
    assert (
        "largest Q above +1.50: 200-300 (peak +9.00 at 300, rolling success min 0.70, "
        "timeout share max 0.02); 600-600 (peak +4.00 at 600, rolling success min 0.40, "
        "timeout share max 0.05)"
    ) in out
    assert "largest Q above +10.00: never" in mod.summarise(log, 12, 0.5, 10.0)


def test_min_after_promotion_line(tmp_path: Path) -> None:
    """The rolling window restarts at promotion, so the stage's first line can read 0.00 on a
    run that never faltered: the minimum without it is printed beside the plain one."""
    rolling = [0.0, 0.8, 0.75, 0.9]
    lines = [
        {"step": 100 * (i + 1), "curriculum/stage": 12, "charts/success_rolling": s}
        for i, s in enumerate(rolling)
    ]
    log = tmp_path / "log.jsonl"
    log.write_text("\n".join(json.dumps(x) for x in lines) + "\n")
    out = _module().summarise(log, 12, 0.5)
    assert "rolling success min 0.00  mean 0.61  max 0.90" in out
    assert "window at promotion: 0.75)" in out


def test_a_compressed_log_reads_as_the_plain_one(tmp_path: Path) -> None:
    """Logs kept in sweeps/landed/ and agents/*/analysis/ are ``.jsonl.gz``."""
    import gzip

    lines = [
        {"step": 100 * (i + 1), "curriculum/stage": 12, "charts/success_rolling": s}
        for i, s in enumerate([0.2, 0.9])
    ]
    text = "\n".join(json.dumps(x) for x in lines) + "\n"
    (tmp_path / "log.jsonl").write_text(text)
    (tmp_path / "log.jsonl.gz").write_bytes(gzip.compress(text.encode()))
    mod = _module()
    plain = mod.summarise(tmp_path / "log.jsonl", 12, 0.5)
    packed = mod.summarise(tmp_path / "log.jsonl.gz", 12, 0.5)
    assert plain.splitlines()[1:] == packed.splitlines()[1:]
    assert mod.main([str(tmp_path / "log.jsonl.gz")]) == 0
