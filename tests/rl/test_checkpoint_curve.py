"""sweeps/checkpoint_curve.py: the fixed-evaluation-set curve of saved checkpoints."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

from cdr_bench.rl.common import CURVE_SCENARIO, CURVE_SEED
from cdr_bench.rl.quick_eval import quick_eval

ROOT = Path(__file__).resolve().parents[2]
AGENT = ROOT / "agents" / "safe_dqn_x"


def _module():
    spec = importlib.util.spec_from_file_location(
        "checkpoint_curve", ROOT / "sweeps" / "checkpoint_curve.py"
    )
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.artefacts
def test_one_line_per_checkpoint_as_the_agent_scores(capsys) -> None:
    mod = _module()
    cks = [AGENT / "seeds" / "2" / "checkpoint.pt", AGENT / "checkpoint.pt"]
    assert mod.main([str(AGENT), *map(str, cks), "--episodes", "6"]) == 0
    rows = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert [r["checkpoint"] for r in rows] == sorted(
        map(str, cks), key=lambda p: (mod.checkpoint_step(Path(p)), p)
    )
    agent = mod.load_agent_class(AGENT)(checkpoint=str(cks[1]))
    want = quick_eval(agent.act_batch, CURVE_SCENARIO, 6, seed=CURVE_SEED)
    got = next(r for r in rows if r["checkpoint"] == str(cks[1]))
    assert got["step"] > 0
    assert got["curve/clean_success"] == want["clean_success"]
    assert got["curve/los"] == want["los"]


def test_bad_paths_are_errors(tmp_path: Path, capsys) -> None:
    mod = _module()
    (tmp_path / "checkpoint.pt").write_bytes(b"weights")
    assert mod.main([str(tmp_path), str(tmp_path / "checkpoint.pt")]) == 2
    assert mod.main([str(AGENT), str(tmp_path / "none.pt")]) == 2
    err = capsys.readouterr().err
    assert "no agent.py" in err and "no such checkpoint" in err


def test_unreadable_checkpoint_is_a_one_line_error(tmp_path: Path) -> None:
    mod = _module()
    junk = tmp_path / "junk.pt"
    junk.write_text("not a checkpoint\n")
    with pytest.raises(SystemExit, match=r"junk\.pt: not a cdr-bench training checkpoint"):
        mod.main([str(AGENT), str(junk)])


@pytest.mark.artefacts
def test_foreign_checkpoint_is_a_one_line_error(capsys) -> None:
    mod = _module()
    foreign = ROOT / "agents" / "ppo" / "checkpoint.pt"  # another algorithm's weights
    assert mod.main([str(AGENT), str(foreign), "--episodes", "2"]) == 2
    assert "agents/safe_dqn_x/agent.py cannot load it" in capsys.readouterr().err
