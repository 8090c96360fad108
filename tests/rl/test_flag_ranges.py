"""Every numeric training flag has a range (cdr_bench.rl.common.FLAG_RANGES), checked when the
flags are parsed: a value a trainer cannot use is a one-line error (exit 2) before anything
runs, and nothing a shipped recipe uses is refused."""

from __future__ import annotations

import argparse
import importlib
import math
from pathlib import Path

import pytest

from cdr_bench.errors import UserError
from cdr_bench.rl.cli import TRAINERS, args_class
from cdr_bench.rl.common import FLAG_RANGES, from_namespace
from cdr_bench.scale.config import load_sweep

from .helpers import cdr_bench

ROOT = Path(__file__).resolve().parents[2]
SWEEPS = sorted([*ROOT.glob("sweeps/*.yaml"), *ROOT.glob("sweeps/seeds/*.yaml")])


def _parser(name: str) -> tuple[argparse.ArgumentParser, type]:
    p = argparse.ArgumentParser(prog=f"train {name}")
    importlib.import_module(TRAINERS[name]).add_arguments(p, name)
    return p, args_class(name)


@pytest.mark.parametrize("name", list(TRAINERS))
def test_defaults_are_in_range_and_every_numeric_flag_has_one(name: str) -> None:
    p, args_cls = _parser(name)  # building the parser fails on a numeric flag without a range
    ns = p.parse_args([])
    numeric = [a for a in p._actions if a.dest in FLAG_RANGES]
    assert numeric, name
    for action in numeric:  # each default, given as text, parses back to itself
        value = getattr(ns, action.dest)
        text = "inf" if value == math.inf else repr(value)
        assert p.parse_args([action.option_strings[0], text]).__dict__[action.dest] == value
    from_namespace(args_cls, ns)  # and the cross-field checks accept the defaults


@pytest.mark.parametrize("sweep", SWEEPS, ids=lambda p: p.relative_to(ROOT / "sweeps").as_posix())
def test_every_shipped_recipe_is_accepted(sweep: Path) -> None:
    for trial in load_sweep(sweep).trials:
        argv = trial.train_argv("runs/x")
        p, args_cls = _parser(argv[0])
        from_namespace(args_cls, p.parse_args(argv[1:]))


@pytest.mark.parametrize(
    ("name", "flag", "value", "words"),
    [
        ("diffusion-ac", "--T", "0", "expected a value in [1, inf), got 0"),
        ("diffusion-ac", "--gamma", "1.5", "expected a value in [0, 1], got 1.5"),
        ("diffusion-ac", "--lr-critic", "0", "expected a value in (0, inf), got 0"),
        ("diffusion-ac", "--q-target-max", "nan", "expected a value in [-inf, inf], got nan"),
        ("diffusion-ac", "--tau-end", "inf", "expected a value in (0, inf), got inf"),
        ("rainbow", "--batch-size", "-3", "expected a value in [1, inf), got -3"),
        ("rainbow", "--seed", "-1", "expected a value in [0, inf), got -1"),
        ("ppo", "--total-steps", "2.5", "expected a whole number, got '2.5'"),
        ("td3", "--action-noise", "-0.1", "expected a value in [0, inf), got -0.1"),
        ("safe-dqn-x", "--slack", "nan", "expected a value in [0, inf), got nan"),
    ],
)
def test_out_of_range_values_are_refused_when_parsed(name, flag, value, words, capsys) -> None:
    p, _ = _parser(name)
    with pytest.raises(SystemExit) as e:
        p.parse_args([flag, value])
    assert e.value.code == 2
    assert f"argument {flag}: {words}" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("name", "flags", "words"),
    [
        ("diffusion-ac", ["--width", "12"], "--width 12: must be divisible by the 8 attention"),
        ("rainbow", ["--v-min", "5", "--v-max", "1"], "--v-min 5 must be below --v-max 1"),
    ],
)
def test_inconsistent_flags_are_one_line_errors_before_the_run_dir(tmp_path, name, flags, words):
    run = tmp_path / "run"
    r = cdr_bench("train", name, "--run-dir", str(run), *flags)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert words in r.stderr
    assert not run.exists()


def test_a_sweep_with_a_bad_value_is_refused_when_loaded(tmp_path) -> None:
    text = (ROOT / "sweeps" / "smoke.yaml").read_text()
    text = text.replace("agent_file: ../agents", f"agent_file: {ROOT}/agents")
    for old, new, words in [
        ("T: [8, 10]", "T: [0, 10]", "grid T=0: argument --T: expected a value in [1, inf)"),
        ("width: 32", "width: 12", "grid T=8: --width 12: must be divisible by the 8"),
    ]:
        path = tmp_path / "bad.yaml"
        path.write_text(text.replace(old, new))
        with pytest.raises(UserError) as e:
            load_sweep(path)
        assert f"bad.yaml: {words}" in str(e.value)
