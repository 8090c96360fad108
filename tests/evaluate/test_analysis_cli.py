"""``cdr-bench multimodal`` with classical agents: spaces of the scenario, one-line load errors,
atomic JSON and PNG, the documented keys."""

import json
from pathlib import Path

import numpy as np
import pytest

from cdr_bench.cli import main
from cdr_bench.evaluate import analysis
from cdr_bench.evaluate.search import FAMILIES, rollout
from cdr_bench.scenarios import load_scenario

ROOT = Path(__file__).resolve().parents[2]


def test_classical_agent_writes_json_and_png(tmp_path, capsys):
    out = tmp_path / "sub" / "mm.json"
    args = ["--scenario", "tactical/head-on", "--samples", "20", "--episodes", "3"]
    assert main(["multimodal", str(ROOT / "agents" / "random"), *args, "--out", str(out)]) == 0
    res = json.loads(out.read_text())
    for key in ("all", "success", "success_rate", "modes", "normalised_entropy", "threshold"):
        assert key in res, key
    assert res["samples"] == 20 and res["episodes"] == 3
    assert len(res["all"]) == len(res["success"]) == 27
    assert sum(res["all"]) == 60 and sum(res["success"]) <= 60
    assert all(0 <= s <= a for s, a in zip(res["success"], res["all"], strict=True))
    assert 0.0 <= res["normalised_entropy"] <= 1.0
    assert res["modes"] == analysis.mode_summary(res["success"], 0.05)["modes"]
    # Per episode: its own counts, and the manoeuvre families its successful samples reach.
    eps = res["per_episode"]
    assert [e["episode"] for e in eps] == [0, 1, 2] and len({e["seed"] for e in eps}) == 3
    assert np.array_equal(np.sum([e["all"] for e in eps], axis=0), res["all"])
    assert np.array_equal(np.sum([e["success"] for e in eps], axis=0), res["success"])
    for e in eps:
        assert sum(e["family_successes"].values()) <= sum(e["success"])
        assert e["families"] == [f for f in FAMILIES if e["family_successes"][f]]
    assert res["families_per_episode"] == [len(e["families"]) for e in eps]
    assert sum(res["families_distribution"].values()) == 3
    assert res["families_mean"] == pytest.approx(np.mean(res["families_per_episode"]))
    assert out.with_suffix(".png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in out.parent.iterdir()) == ["mm.json", "mm.png"]  # no temp files
    assert "manoeuvre families reached per episode" in capsys.readouterr().out

    # mvp reads the observation space (it crashed with None spaces before); one episode by
    # --samples alone is still the command of earlier versions.
    out2 = tmp_path / "mvp.json"
    mvp = str(ROOT / "agents" / "mvp")
    assert main(["multimodal", mvp, *args[:4], "--episodes", "1", "--out", str(out2)]) == 0
    res2 = json.loads(out2.read_text())
    assert sum(res2["all"]) == 20 and len(res2["families_per_episode"]) == 1
    assert res2["families_per_episode"][0] <= 1  # deterministic: every sample the same


class _ClimbDescendOrWait:
    """First step: climb, descend or hold (its own random choice); a sample that held climbs at
    the second step; then it holds. Families reachable: climb and descend."""

    def __init__(self):
        self.rng = np.random.default_rng(0)

    def reset(self, seed):
        self.rng = np.random.default_rng(seed)

    def act_batch(self, obs, masks):
        step0 = obs[:, 11] == 0.0
        level1 = obs[:, 5] == 0.0
        first = self.rng.choice([14, 12, 13], size=len(obs))
        return np.where(step0, first, np.where(level1 & (obs[:, 11] < 0.02), 14, 13))


def test_families_per_episode_are_those_of_the_successful_first_manoeuvres():
    """The family of a sample is that of its first action other than hold; an episode reaches
    a family when one of its samples of that family succeeds: checked against fresh rollouts."""
    config = load_scenario("tactical/head-on")
    d = analysis.first_action_distribution(_ClimbDescendOrWait(), config, 30, episodes=6)
    assert len(d["per_episode"]) == 6 and sum(d["all"]) == 180
    for e in d["per_episode"]:
        climb = rollout(config, [14], seed=e["seed"]) == "success"
        wait_climb = rollout(config, [13, 14], seed=e["seed"]) == "success"
        descend = rollout(config, [12], seed=e["seed"]) == "success"
        n_climb, n_descend, n_wait = (e["all"][a] for a in (14, 12, 13))
        assert e["family_successes"] == {
            "left": 0,
            "right": 0,
            "climb": n_climb * climb + n_wait * wait_climb,
            "descend": n_descend * descend,
            "speed": 0,
        }
        assert e["success"][14] == n_climb * climb and e["success"][13] == n_wait * wait_climb


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


def test_failing_run_leaves_no_partial_files(tmp_path, monkeypatch, capsys):
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
    assert main(args) == 2  # one line naming the file, no traceback
    assert f"{tmp_path / 'mm.png'}: cannot write it (disk full)" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mm.json"]
    assert out.read_text() == "old"  # the old result is untouched, no new JSON without its PNG


def test_mode_summary_counts_modes_at_threshold():
    counts = [0] * 27
    counts[3], counts[5], counts[7] = 90, 6, 4  # 90 %, 6 %, 4 %
    s = analysis.mode_summary(counts, 0.05)
    assert s["modes"] == 2
    p = np.array([0.9, 0.06, 0.04])
    assert s["normalised_entropy"] == pytest.approx(-(p * np.log(p)).sum() / np.log(27))
