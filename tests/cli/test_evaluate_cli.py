"""Real subprocess runs of ``cdr-bench evaluate / compare / report`` on tiny budgets: result
files, resume after a kill, workers, and every misbehaving-agent case."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
AGENTS = ROOT / "agents"


def cli(*args, cwd=None, timeout=120):
    return subprocess.run(
        [sys.executable, "-m", "cdr_bench", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=timeout,
    )


def evaluate(agent, out, *extra, scenario="low", episodes=8, cwd=None):
    return cli(
        "evaluate",
        agent,
        "--scenario",
        scenario,
        "--episodes",
        episodes,
        "--out",
        out,
        "--no-progress",
        "--batch-size",
        4,
        *extra,
        cwd=cwd,
    )


def write_agent(tmp_path, body, name="agent_x.py"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(body))
    return p


def without_timing(path):
    d = json.loads(Path(path).read_text())
    d.pop("timing")
    return d


def no_results_left(tmp_path):
    return not [p for p in tmp_path.rglob("*") if p.suffix in (".json", ".jsonl")]


BASE = """
import time
import numpy as np

class Agent:
    def __init__(self, observation_space, action_space):
        pass
"""


def test_evaluate_writes_summary_and_result_files(tmp_path):
    out = tmp_path / "r" / "direct.json"
    r = evaluate(AGENTS / "direct" / "agent.py", out, scenario="marl/low-2")
    assert r.returncode == 0, r.stderr
    assert "ownship" in r.stdout and "intruders" in r.stdout and "success" in r.stdout
    res = json.loads(out.read_text())
    assert res["schema_version"] == 3 and res["agent"]["name"] == "direct"
    assert "agent.py" in res["agent"]["files"]
    sc = res["scenarios"][0]
    assert sc["id"] == "marl/low-2" and sc["config"]["id"] == "marl/low-2"
    assert set(sc["metrics"]) == {"ownship", "intruders"}
    assert sc["metrics"]["intruders"]["episodes"] == 16
    lines = out.with_suffix(".jsonl").read_text().splitlines()
    assert len(lines) == 8 and json.loads(lines[0])["scenario"] == "marl/low-2"
    assert not out.with_suffix(".partial.jsonl").exists()


def test_template_agent_and_default_output_path(tmp_path):
    mine = tmp_path / "my_agent"
    mine.mkdir()
    (mine / "agent.py").write_text((AGENTS / "template" / "agent.py").read_text())
    (mine / "policy.bin").write_bytes(b"weights")
    r = cli("evaluate", mine, "--scenario", "low", "--episodes", 3, "--no-progress", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    res = json.loads((tmp_path / "results" / "my_agent" / "low.json").read_text())
    assert set(res["agent"]["files"]) == {"agent.py", "policy.bin"}


@pytest.mark.slow
def test_workers_and_resume_give_identical_results(tmp_path):
    slow = write_agent(
        tmp_path,
        BASE
        + """
    def act_batch(self, obs, masks):
        time.sleep(0.004)
        return np.full(len(obs), 13)
    def act(self, o):
        return 13
""",
    )
    ref = tmp_path / "ref.json"
    assert evaluate(slow, ref, episodes=16).returncode == 0
    par = tmp_path / "par.json"
    r = evaluate(slow, par, "--workers", 2, episodes=16)
    assert r.returncode == 0, r.stderr
    assert without_timing(par) == {**without_timing(ref), "episodes_file": "par.jsonl"}
    assert par.with_suffix(".jsonl").read_bytes() == ref.with_suffix(".jsonl").read_bytes()

    out = tmp_path / "res.json"
    partial = out.with_suffix(".partial.jsonl")
    cmd = [
        sys.executable,
        "-m",
        "cdr_bench",
        "evaluate",
        str(slow),
        "--scenario",
        "low",
        "--episodes",
        "16",
        "--out",
        str(out),
        "--no-progress",
        "--batch-size",
        "4",
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 30
    while time.time() < deadline:
        if partial.exists() and len(partial.read_text().splitlines()) >= 2:
            break
        time.sleep(0.01)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not out.exists(), "killed too late to test resume"
    with open(partial, "a") as f:
        f.write('{"kind": "batch", "scenario": "low", "bat')  # a torn write
    r = subprocess.run(cmd + ["--resume"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    res = json.loads(out.read_text())
    assert res["timing"]["resumed"] is True
    assert without_timing(out) == {**without_timing(ref), "episodes_file": "res.jsonl"}
    assert out.with_suffix(".jsonl").read_bytes() == ref.with_suffix(".jsonl").read_bytes()
    assert not partial.exists()


def test_compare_paired_and_refuses_other_episodes(tmp_path):
    a, b, c = tmp_path / "a.json", tmp_path / "b.json", tmp_path / "c.json"
    assert evaluate(AGENTS / "direct", a, episodes=12).returncode == 0
    assert evaluate(AGENTS / "mvp", b, episodes=12).returncode == 0
    assert evaluate(AGENTS / "mvp", c, "--seed", 1, episodes=12).returncode == 0
    r = cli("compare", a, b, "--json", tmp_path / "cmp.json")
    assert r.returncode == 0, r.stderr
    assert "los_rate" in r.stdout and "B-A" in r.stdout
    rows = json.loads((tmp_path / "cmp.json").read_text())["rows"]
    los = next(x for x in rows if x["metric"] == "los_rate")
    assert los["diff"] == pytest.approx(los["b"] - los["a"])
    assert los["ci95"][0] <= los["diff"] <= los["ci95"][1]
    r = cli("compare", a, c)
    assert r.returncode == 2 and "not the same episodes" in r.stderr
    assert "Traceback" not in r.stderr
    r = cli("report", a, b, "--out", tmp_path / "README.md")
    assert r.returncode == 0, r.stderr
    text = (tmp_path / "README.md").read_text()
    assert "| direct | low | ownship | 12 |" in text and "| mvp | low |" in text


# ---------------------------------------------------------------------------------------------
# Misbehaving agents: exit code 2, one line, no traceback, no result file left behind

CASES = {
    "missing": (None, "not found"),
    "syntax": ("class Agent:\n    def act(self, o)\n        return 13\n", "syntax error"),
    "no_agent": ("class Policy:\n    pass\n", "defines no `Agent`"),
    "ctor_raises": (
        BASE.replace("pass", "raise RuntimeError('checkpoint policy.pt missing')")
        + "    def act(self, o):\n        return 13\n",
        "checkpoint policy.pt missing",
    ),
    "act_raises": (
        BASE
        + """
    def act(self, o):
        if o["observation"][11] > 0.004:
            x = {}["boom"]
        return 13
""",
        "KeyError",
    ),
    "out_of_range": (
        BASE + "    def act_batch(self, o, m):\n        return np.full(len(o), 27)\n"
        "    def act(self, o):\n        return 27\n",
        "got 27",
    ),
    "float_action": (
        BASE + "    def act_batch(self, o, m):\n        return np.full(len(o), 13.0)\n"
        "    def act(self, o):\n        return 13\n",
        "got 13.0",
    ),
    "nan_action": (BASE + "    def act(self, o):\n        return float('nan')\n", "got nan"),
    "bool_action": (BASE + "    def act(self, o):\n        return True\n", "got True"),
    "hang": (
        BASE + "    def act_batch(self, o, m):\n        while True:\n            pass\n"
        "    def act(self, o):\n        return 13\n",
        "time limit",
    ),
}


ACT13 = "    def act(self, o):\n        return 13\n"
CASES.update(
    {
        # the limit is enforced from outside the agent's process: nothing inside can stop it
        "swallows_timeout": (
            "import signal\n"
            + BASE
            + """
    def act_batch(self, o, m):
        signal.signal(signal.SIGALRM, signal.SIG_IGN)
        while True:
            try:
                while True:
                    pass
            except BaseException:
                continue
"""
            + ACT13,
            "exceeded the time limit of 0.5 s",
        ),
        "import_hang": ("while True:\n    pass\n" + BASE + ACT13, "loading did not finish"),
        "ctor_hang": (BASE.replace("pass", "while True: pass") + ACT13, "loading did not finish"),
        "endless_iterator": (
            "import itertools\n"
            + BASE
            + "    def act_batch(self, o, m):\n        return itertools.count(13, 0)\n"
            + ACT13,
            "expected 4 action indices, got more",
        ),
        "reset_raises": (
            BASE
            + "    def reset(self, seed):\n        raise ValueError('no seed for you')\n"
            + ACT13,
            "reset(seed) before episodes 0..3",
        ),
        "os_exit": (
            "import os\n" + BASE + "    def act(self, o):\n        os._exit(0)\n",
            "exited (exit code 0",
        ),
        "sys_exit": (
            "import sys\n" + BASE + "    def act(self, o):\n        sys.exit(3)\n",
            "exited with code 3",
        ),
        "kills_itself": (
            "import os, signal\n"
            + BASE
            + "    def act(self, o):\n        os.kill(os.getpid(), signal.SIGKILL)\n",
            "was killed (SIGKILL",
        ),
    }
)


@pytest.mark.parametrize("case", sorted(CASES))
def test_misbehaving_agent_is_reported(tmp_path, case):
    body, expected = CASES[case]
    path = tmp_path / "missing.py" if body is None else write_agent(tmp_path, body)
    r = evaluate(
        path,
        tmp_path / "out" / "r.json",
        "--decision-timeout",
        0.5,
        "--load-timeout",
        3,
        cwd=tmp_path,
    )
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert expected in r.stderr, r.stderr
    assert "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert no_results_left(tmp_path)
    if case == "act_raises":  # the episode, the step and the agent's own line
        assert "episode 0" in r.stderr and "step 5," in r.stderr  # time 5/1000 > 0.004
        assert 'agent_x.py:11: `x = {}["boom"]`' in r.stderr
    if case in ("out_of_range", "float_action", "nan_action", "os_exit", "swallows_timeout"):
        assert "episode 0" in r.stderr and "step 0" in r.stderr and "ownship_0" in r.stderr
    if case == "reset_raises":
        assert "agent_x.py:" in r.stderr and "no seed for you" in r.stderr


def test_agent_that_exits_in_a_worker_is_reported(tmp_path):
    path = write_agent(
        tmp_path, "import os\n" + BASE + "    def act(self, o):\n        os._exit(0)\n"
    )
    r = evaluate(path, tmp_path / "r.json", "--workers", 2, episodes=8)
    assert r.returncode == 2 and "exited (exit code 0" in r.stderr, r.stderr
    assert "Traceback" not in r.stderr and "BrokenProcessPool" not in r.stderr
    assert no_results_left(tmp_path)


@pytest.mark.parametrize("flag", ["--decision-timeout", "--load-timeout"])
@pytest.mark.parametrize("value", ["0", "nan", "-1", "inf", "1e9"])
def test_a_time_limit_cannot_be_disabled(tmp_path, flag, value):
    r = evaluate(AGENTS / "direct", tmp_path / "r.json", flag, value, episodes=4)
    assert r.returncode == 2, r.stderr
    assert flag in r.stderr and "Traceback" not in r.stderr
    assert "expected a number of seconds > 0" in r.stderr or "at most" in r.stderr


@pytest.mark.parametrize("kind", ["directory", "bare_batch", "edited", "binary"])
def test_resume_refuses_a_bad_checkpoint(tmp_path, kind):
    out = tmp_path / "r.json"
    partial = out.with_suffix(".partial.jsonl")
    slow = write_agent(
        tmp_path,
        BASE + "    def act_batch(self, o, m):\n        time.sleep(0.01)\n"
        "        return np.full(len(o), 13)\n" + ACT13,
    )
    cmd = [sys.executable, "-m", "cdr_bench", "evaluate", str(slow), "--scenario", "low"]
    cmd += ["--episodes", "16", "--out", str(out), "--no-progress", "--batch-size", "4"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 60
    while time.time() < deadline:
        if partial.exists() and len(partial.read_text().splitlines()) >= 3:
            break
        time.sleep(0.01)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not out.exists(), "killed too late to test resume"
    lines = partial.read_text().splitlines()[:3]
    if kind == "directory":
        partial.unlink()
        partial.mkdir()
        expected = "not a file"
    elif kind == "bare_batch":
        lines.append('{"kind":"batch"}')
        expected = "changed after it was written"
    elif kind == "edited":
        lines[1] = (
            lines[1]
            .replace('"outcome":"los"', '"outcome":"success"')
            .replace('"los":true', '"los":false')
        )
        lines[1] = lines[1].replace('"steps":', '"steps":1', 1)  # an edit in any case
        expected = "changed after it was written"
    else:
        partial.write_bytes(b"\xff\xfe\x00garbage\n")
        expected = "unreadable checkpoint"
    if kind not in ("directory", "binary"):
        partial.write_text("\n".join(lines) + "\n")
    r = subprocess.run(cmd + ["--resume"], capture_output=True, text=True)
    assert r.returncode == 2, r.stderr
    assert expected in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert not out.exists()


def test_report_refuses_a_result_whose_episode_log_differs(tmp_path):
    out = tmp_path / "r.json"
    assert evaluate(AGENTS / "direct", out, episodes=4).returncode == 0
    assert cli("report", out).returncode == 0
    # a disk that filled up between the two renames: a new JSONL beside the old JSON
    ep = out.with_suffix(".jsonl")
    ep.write_text(ep.read_text().replace('"outcome":"los"', '"outcome":"success"') + "\n")
    for cmd in (("report", out), ("compare", out, out)):
        r = cli(*cmd)
        assert r.returncode == 2, r.stderr
        assert "does not match it" in r.stderr and "Traceback" not in r.stderr
    ep.unlink()
    r = cli("report", out)
    assert r.returncode == 2 and "is missing" in r.stderr


def test_masked_action_is_counted_not_fatal(tmp_path):
    climber = write_agent(tmp_path, BASE + "    def act(self, o):\n        return 14\n")
    out = tmp_path / "r.json"
    r = evaluate(climber, out, episodes=4)  # 14 = climb: masked at level 2
    assert r.returncode == 0, r.stderr
    m = json.loads(out.read_text())["scenarios"][0]["metrics"]["ownship"]
    assert m["invalid_action_rate"]["count"] > 0


def test_summary_fits_100_columns_and_existing_results_are_kept(tmp_path):
    out = tmp_path / "r.json"
    r = evaluate(AGENTS / "direct", out, scenario="curriculum/stage-12", episodes=4)
    assert r.returncode == 0, r.stderr
    table = [line for line in r.stdout.splitlines() if not line.startswith("wrote ")]
    assert max(len(line) for line in table) <= 100, r.stdout
    assert "success" in r.stdout and "clean" in r.stdout
    before = out.read_bytes()
    r = evaluate(AGENTS / "mvp", out, scenario="curriculum/stage-12", episodes=4)
    assert r.returncode == 2 and "--force" in r.stderr and "Traceback" not in r.stderr
    assert out.read_bytes() == before
    r = evaluate(
        AGENTS / "mvp", out, "--force", "--wide", scenario="curriculum/stage-12", episodes=4
    )
    assert r.returncode == 0, r.stderr
    assert "R_G" in r.stdout and "latency" in r.stdout and out.read_bytes() != before


def test_compare_on_the_scenarios_both_results_hold(tmp_path):
    one, two = tmp_path / "one.json", tmp_path / "two.json"
    assert evaluate(AGENTS / "direct", one, scenario="medium", episodes=4).returncode == 0
    r = cli(
        "evaluate",
        AGENTS / "mvp",
        "--scenario",
        "low",
        "--scenario",
        "medium",
        "--episodes",
        4,
        "--out",
        two,
        "--no-progress",
    )
    assert r.returncode == 0, r.stderr
    r = cli("compare", one, two)
    assert r.returncode == 0, r.stderr
    assert "compared on medium only" in r.stderr and "medium" in r.stdout and "low" not in r.stdout
    r = cli("compare", one, two, "--scenario", "low")
    assert r.returncode == 2 and "--scenario low: not in" in r.stderr


@pytest.mark.parametrize(
    ("flag", "value", "words"),
    [
        ("--batch-size", "0", "--batch-size must be >= 1, got 0"),  # was silently the default
        ("--workers", "0", "--workers must be >= 1, got 0"),
        ("--episodes", "-1", "--episodes must be >= 1, got -1"),
    ],
)
def test_counts_below_one_are_refused(tmp_path, flag, value, words):
    out = tmp_path / "r.json"
    r = evaluate(AGENTS / "mvp", out, flag, value)
    assert r.returncode == 2 and words in r.stderr and "Traceback" not in r.stderr
    assert list(tmp_path.iterdir()) == []
