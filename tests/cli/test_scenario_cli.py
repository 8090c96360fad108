"""The scenario and render commands, run by :func:`cdr_bench.cli.main` in this process."""

from __future__ import annotations

from dataclasses import dataclass

import pytest
from PIL import Image

from cdr_bench.cli import main


@dataclass
class Run:
    returncode: int
    stdout: str
    stderr: str


@pytest.fixture
def cli(capsys):
    """``cli(*args)``: ``cdr-bench ARGS``; its exit code and output."""

    def run(*args: str) -> Run:
        capsys.readouterr()
        code = main(list(args))
        out, err = capsys.readouterr()
        return Run(code, out, err)

    return run


def test_scenarios_list_show_validate(cli, tmp_path):
    r = cli("scenarios", "list")
    assert r.returncode == 0 and "curriculum/stage-12" in r.stdout and "high" in r.stdout
    r = cli("scenarios", "show", "high")
    assert r.returncode == 0 and "per_route: 4" in r.stdout
    good = tmp_path / "good.yaml"
    good.write_text("extends: low\nseparation: {los_km: 9.0}\n")
    r = cli("scenarios", "validate", str(good))
    assert r.returncode == 0 and r.stdout.startswith("ok")


def test_validate_bad_file_exit_2_one_line(cli, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("extends: low\ntraffic: {per_route: 0}\n")
    r = cli("scenarios", "validate", str(bad))
    assert r.returncode == 2
    assert "traffic.per_route" in r.stderr and str(bad) in r.stderr
    assert "Traceback" not in r.stderr
    r = cli("scenarios", "show", "no-such-scenario")
    assert r.returncode == 2 and "unknown scenario name" in r.stderr and "Traceback" not in r.stderr


def test_render_gif(cli, tmp_path):
    out = tmp_path / "ep.gif"
    r = cli("render", "curriculum/stage-02", "--out", str(out), "--max-frames", "30")
    assert r.returncode == 0, r.stderr
    im = Image.open(out)
    assert im.n_frames >= 2 and im.size == (512, 512)
    assert not list(tmp_path.glob(".*tmp"))
    r = cli("render", "low", "--out", str(tmp_path / "x.png"))
    assert r.returncode == 2 and ".gif" in r.stderr
    (tmp_path / "file").write_text("x")
    for bad, words in [
        (tmp_path / "file" / "x.gif", f"{tmp_path / 'file'} is a file, not a folder"),
        (tmp_path / "dir.gif", "is a folder; expected a file path"),
    ]:
        (tmp_path / "dir.gif").mkdir(exist_ok=True)
        r = cli("render", "low", "--out", str(bad))
        assert r.returncode == 2 and "Traceback" not in r.stderr
        assert f"--out {bad}: {words}" in r.stderr
    assert not list(tmp_path.glob(".*tmp"))


def test_scenarios_certify(cli, tmp_path):
    """docs/model.md §8.3: a family passes (exit 0) and its JSON report holds the three parts;
    an encounter that holding survives fails (exit 1); a missing agent is a user error."""
    import json
    from pathlib import Path

    mvp = Path(__file__).resolve().parents[2] / "agents" / "mvp"
    out = tmp_path / "cert.json"
    r = cli(
        "scenarios", "certify", "tactical/crossing", "--episodes", "60", "--search-episodes",
        "4", "--enough", "2", "--agent", str(mvp), "--out", str(out),
    )  # fmt: skip
    assert r.returncode == 0, r.stdout + r.stderr
    last = r.stdout.rstrip().splitlines()[-1]
    assert "(a) holding fails in 60 / 60" in r.stdout and last.startswith("certified")
    rep = json.loads(out.read_text())
    assert rep["ok"] and rep["hold"]["failures"] == 60 and rep["agent"]["episodes"] == 60
    assert len(rep["families"]["per_episode"]) == 4
    assert all(len(e["families"]) >= 2 for e in rep["families"]["per_episode"])

    easy = tmp_path / "easy.yaml"
    easy.write_text("extends: tactical/head-on\nid: easy\naircraft: []\n")
    r = cli("scenarios", "certify", str(easy), "--episodes", "5", "--search-episodes", "1",
            "--agent", "none")  # fmt: skip
    assert r.returncode == 1 and "FAIL (a) holding fails in 0 / 5" in r.stdout
    assert "NOT certified" in r.stdout

    r = cli("scenarios", "certify", "tactical/crossing", "--agent", str(tmp_path / "nope"))
    assert r.returncode == 2 and "no such file" in r.stderr and "Traceback" not in r.stderr
