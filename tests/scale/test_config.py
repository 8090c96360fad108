"""Sweep files: strict validation, trial keys, the shipped sweeps. Commands run in this process
(:func:`cdr_bench.cli.main`); the import check has a process of its own."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from cdr_bench.cli import main
from cdr_bench.errors import UserError
from cdr_bench.scale.config import load_sweep

from .helpers import REPO, tiny_sweep


@pytest.fixture
def cdr(capsys):
    """``cdr(*args, cwd=None)``: ``cdr-bench ARGS`` in ``cwd``; a CompletedProcess with its exit
    code and output."""

    def run(*args: object, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
        capsys.readouterr()
        before = os.getcwd()
        try:
            if cwd is not None:
                os.chdir(cwd)
            code = main([str(a) for a in args])
        except SystemExit as e:  # argparse's own errors
            code = e.code if isinstance(e.code, int) else 1
        finally:
            os.chdir(before)
        out, err = capsys.readouterr()
        return subprocess.CompletedProcess(list(args), code, out, err)

    return run


def _edit(path: Path, **changes) -> Path:
    doc = yaml.safe_load(path.read_text())
    for k, v in changes.items():
        if v is None:
            doc.pop(k, None)
        else:
            doc[k] = v
    path.write_text(yaml.safe_dump(doc))
    return path


@pytest.mark.parametrize(
    "changes, words",
    [
        ({"sedes": [1]}, ["tiny.yaml", "sedes", "unknown field"]),
        ({"budget": {"total_step": 5}}, ["budget.total_step", "unknown field"]),
        ({"evaluation": {"scenarios": ["low"], "episode": 3}}, ["evaluation.episode"]),
        ({"grid": {"T-steps": [8]}}, ["grid.T-steps", "not a flag"]),
        ({"grid": {"T": ["eight"]}}, ["expected a whole number, got 'eight'"]),
        ({"fixed": {"seed": 3}}, ["fixed.seed", "set by the sweep"]),
        ({"agent": "nope"}, ["agent", "unknown trainer"]),
        ({"seeds": [1, 1]}, ["seeds", "twice"]),
        ({"seeds": None}, ["seeds", "missing"]),
        ({"evaluation": {"scenarios": ["no/such"]}}, ["evaluation.scenarios[0]"]),
        ({"grid": {"T": [8]}, "settings": [{"T": 8}]}, ["only one of"]),
    ],
)
def test_rejects_with_file_and_field(tmp_path, changes, words):
    path = _edit(tiny_sweep(tmp_path, [1]), **changes)
    with pytest.raises(UserError) as e:
        load_sweep(path)
    msg = str(e.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg


def test_trials_and_keys(tmp_path):
    sweep = load_sweep(tiny_sweep(tmp_path, [1, 2], grid={"T": [8, 10], "polyak": [0.01]}))
    assert [(t.label, t.seed) for t in sweep.trials] == [
        ("T=8,polyak=0.01", 1),
        ("T=8,polyak=0.01", 2),
        ("T=10,polyak=0.01", 1),
        ("T=10,polyak=0.01", 2),
    ]
    assert len({t.key for t in sweep.trials}) == 4
    again = load_sweep(tiny_sweep(tmp_path, [2, 1], grid={"T": [8, 10], "polyak": [0.01]}))
    assert {t.key for t in again.trials} == {t.key for t in sweep.trials}  # order-free keys
    argv = sweep.trials[0].train_argv("RUN")
    assert argv[:3] == ["diffusion-ac", "--run-dir", "RUN"]
    assert "--no-curriculum" in argv and "--no-progress" in argv
    assert argv[argv.index("--total-steps") + 1] == "120"


def test_sensitivity_grid_is_fig7():
    sweep = load_sweep(REPO / "sweeps" / "sensitivity.yaml")
    by_factor: dict[str, set[str]] = {}
    for t in sweep.trials:
        by_factor.setdefault(t.factor, set()).add(t.label)
    assert by_factor["default"] == {"default"}
    # the centre value of each factor is the default trial, not a duplicate
    assert by_factor["T"] | {"10"} == {"8", "10", "20", "40", "80"}
    assert by_factor["temperature"] == {"0.1", "1", "5", "10"}
    assert by_factor["polyak"] | {"0.005"} == {"0.001", "0.005", "0.01", "0.05"}
    assert by_factor["critic-width"] | {"128"} == {"64", "128", "256", "512"}
    seeds = {t.seed for t in sweep.trials}
    assert len(seeds) == 3  # issue 16: three seeds at >= 100k transitions
    assert len(sweep.trials) == 3 * (1 + 4 + 4 + 3 + 3)


def test_smoke_sweep_dry_run(cdr):
    r = cdr("sweep", REPO / "sweeps" / "smoke.yaml", "--dry-run", cwd=REPO)
    assert r.returncode == 0, r.stderr
    assert "4 trials" in r.stdout


@pytest.mark.parametrize(
    ("cpus", "words"),
    [
        ("0", "argument --num-cpus: expected a value in [1, 4096], got 0"),
        ("1", "--num-cpus 1: fewer than the 2 CPUs each trial"),
    ],
)
def test_num_cpus_that_could_never_run_a_trial_is_refused(cdr, tmp_path, cpus, words):
    """A local Ray with no CPU, or fewer than a trial asks for, would wait for ever."""
    path = _edit(tiny_sweep(tmp_path, [1]), num_cpus_per_trial=2)
    r = cdr("sweep", path, "--num-cpus", cpus, cwd=tmp_path)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert words in r.stderr
    assert not (tmp_path / "runs").exists()


def test_cli_error_is_one_line(cdr, tmp_path):
    path = _edit(tiny_sweep(tmp_path, [1]), bogus=1)
    r = cdr("sweep", path)
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0
    assert "bogus" in r.stderr


def test_core_package_does_not_import_ray():
    code = (
        "import sys, cdr_bench, cdr_bench.env, cdr_bench.evaluate.api, cdr_bench.scale.sweep, "
        "cdr_bench.scale.config, cdr_bench.scale.ray_eval\n"
        "from cdr_bench.cli import build_parser\n"
        "build_parser()\n"
        "assert 'ray' not in sys.modules, 'ray imported'\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO)
    assert r.returncode == 0, r.stderr


def test_reduced_run_overrides(tmp_path):
    path = tiny_sweep(tmp_path, [1, 2, 3])
    base = load_sweep(path)
    small = load_sweep(
        path,
        total_steps=50,
        episodes=1,
        overrides={"learning-starts": 10},
        seeds=[7],
        scenarios=["low"],
    )
    (t,) = small.trials
    assert t.seed == 7 and t.train_flags["total-steps"] == 50
    assert t.train_flags["learning-starts"] == 10
    assert t.evaluation == {"scenarios": ["low"], "episodes": 1, "seed": 0}
    assert t.key not in {b.key for b in base.trials}
    with pytest.raises(UserError, match="fixed.nope"):
        load_sweep(path, overrides={"nope": 1})


def test_scenario_yaml_relative_to_sweep_file_and_empty_fixed(cdr, tmp_path):
    r = cdr("scenarios", "show", "low")
    (tmp_path / "scen").mkdir()
    (tmp_path / "scen" / "mine.yaml").write_text(r.stdout)
    path = _edit(
        tiny_sweep(tmp_path, [1]),
        evaluation={"scenarios": ["scen/mine.yaml"], "episodes": 1},
        fixed={},
    )
    (t,) = load_sweep(path).trials
    assert t.evaluation["scenarios"] == [str((tmp_path / "scen" / "mine.yaml").resolve())]
    with pytest.raises(UserError, match="fixed: expected a mapping"):
        load_sweep(_edit(path, fixed=[1]))
    (tmp_path / "list.yaml").write_text("- 1\n- 2\n")
    with pytest.raises(UserError, match=r"list\.yaml: top level: expected a mapping, got list"):
        load_sweep(tmp_path / "list.yaml")


def test_where_selects_trials_with_the_whole_sweeps_keys():
    """``--where`` runs a part of a sweep (one setting per core): the same trials, the same
    keys, so ``--resume`` of the whole sweep later skips what the part landed."""
    whole = load_sweep(REPO / "sweeps" / "table3.yaml")
    part = load_sweep(REPO / "sweeps" / "table3.yaml", where={"ablation": "no-dpsc"})
    assert [t.key for t in part.trials] == [
        t.key for t in whole.trials if t.train_flags["ablation"] == "no-dpsc"
    ]
    assert len(part.trials) == 3
    two = load_sweep(REPO / "sweeps" / "table3.yaml", where={"ablation": "no-dpsc", "seed": 2})
    assert [t.seed for t in two.trials] == [2]
    with pytest.raises(UserError, match="no trial has this value.*'no-diffusion'"):
        load_sweep(REPO / "sweeps" / "table3.yaml", where={"ablation": "nope"})
    with pytest.raises(UserError, match="no trial of the sweep sets widht"):
        load_sweep(REPO / "sweeps" / "table3.yaml", where={"widht": 3})


@pytest.mark.parametrize("arg", ["ablation", "ablation=[1", "ablation=nope"])
def test_where_errors_from_the_cli(cdr, arg):
    r = cdr("sweep", REPO / "sweeps" / "table3.yaml", "--dry-run", "--where", arg, cwd=REPO)
    assert r.returncode == 2 and "--where" in r.stderr
    assert r.stderr.strip().count("\n") == 0 and "Traceback" not in r.stderr
