"""The analysis runs that the documentation shows beside the leaderboard entries
(``tables.SAMPLE_TARGET``: the reference-budget run of ``--diffusion-target sample``). They are
not leaderboard entries, so the leaderboard check does not re-score them; these tests tie each
to the checkpoint it scored and to the episodes of the entry it is compared with."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from cdr_bench.errors import UserError
from cdr_bench.evaluate.loader import file_sha256
from cdr_bench.leaderboard import tables
from tests.leaderboard.conftest import ROOT

LB = ROOT / "leaderboard"
# the staging folder of a `leaderboard build --check` running beside the tests (.ci/run)
SCRATCH = shutil.ignore_patterns(".build-*")


def test_sample_target_scored_the_staged_sample_target_checkpoint() -> None:
    res, mm = tables.Repo(LB).analysis(*tables.SAMPLE_TARGET, tables.TACTICAL)
    ck = res["agent"]["checkpoint_override"]
    path = ROOT / ck["path"]
    assert path.parent.parent == ROOT / "sweeps" / "landed" / "dac-sample", ck["path"]
    assert file_sha256(path) == ck["sha256"]
    trial = json.loads((path.parent / "trial.json").read_text(encoding="utf-8"))
    assert trial["train_flags"]["diffusion-target"] == "sample"
    assert trial["train_flags"]["total-steps"] == 1374560  # the reference budget
    # the same agent code as the entry it is compared with, on the same episodes
    entry = json.loads((LB / "results" / "diffusion-ac.json").read_text(encoding="utf-8"))
    code = [
        {k: v for k, v in r["agent"]["files"].items() if k.endswith(".py")} for r in (res, entry)
    ]
    assert code[0] == code[1]
    assert (res["suite"], res["base_seed"], res["batch_size"]) == (
        entry["suite"],
        entry["base_seed"],
        entry["batch_size"],
    )
    assert [s["id"] for s in res["scenarios"]] == [s["id"] for s in entry["scenarios"]]
    assert [m["scenario"] for _, m in mm] == list(tables.TACTICAL)
    for _, m in mm:
        base = json.loads(
            tables.multimodal_path(LB / "results", "diffusion-ac", m["scenario"]).read_text()
        )
        assert (m["episodes"], m["samples"], m["seed"]) == (
            base["episodes"],
            base["samples"],
            base["seed"],
        )
        assert "feasible_families_mean" in m  # searched, as the entry's


def test_a_missing_analysis_file_is_an_error_naming_it(tmp_path: Path) -> None:
    folder = "agents/diffusion_ac/analysis/sample-target"
    repo = tmp_path / "repo"
    shutil.copytree(LB, repo / "leaderboard", ignore=SCRATCH)
    (repo / folder).mkdir(parents=True)
    r = tables.Repo(repo / "leaderboard")
    with pytest.raises(UserError, match="sample-target/result.json: no such result file"):
        r.analysis(folder, "x", tables.TACTICAL)
    src = ROOT / folder
    for name in ("result.json", "result.jsonl.xz"):  # the per-episode file kept compressed
        shutil.copy(src / name, repo / folder / name)
    with pytest.raises(UserError, match="multimodal-tactical_head-on.json: cannot read"):
        r.analysis(folder, "x", tables.TACTICAL)


def test_the_per_episode_file_is_read_compressed_or_plain_and_checked(tmp_path: Path) -> None:
    """The analysis run keeps its per-episode file as ``result.jsonl.xz``: read, and checked
    against the SHA-256 its ``result.json`` recorded (an error names the file in the
    repository, not the temporary copy)."""
    from cdr_bench.evaluate.results import compress_log
    from cdr_bench.jsonl import read_bytes

    folder = "agents/diffusion_ac/analysis/sample-target"
    src = ROOT / folder
    packed = tmp_path / "packed" / folder
    packed.mkdir(parents=True)
    shutil.copytree(LB, tmp_path / "packed" / "leaderboard", ignore=SCRATCH)
    shutil.copy(src / "result.json", packed / "result.json")
    shutil.copy(src / "result.jsonl.xz", packed / "result.jsonl.xz")
    got, _ = tables.Repo(tmp_path / "packed" / "leaderboard").analysis(folder, "x", ())
    n = sum(s["episodes"] for s in got["scenarios"])
    assert n == len(read_bytes(src / "result.jsonl.xz").splitlines()) == 6000
    edited = read_bytes(src / "result.jsonl.xz").replace(b'"success"', b'"timeout"', 1)
    (packed / "result.jsonl.xz").write_bytes(compress_log(edited.decode()))
    with pytest.raises(UserError, match="does not match it") as e:
        tables.Repo(tmp_path / "packed" / "leaderboard").analysis(folder, "y", ())
    assert str(packed) in str(e.value) and "cdr-bench-result-" not in str(e.value)
