"""``cdr-bench evaluate / compare / report`` on tiny budgets: result files, resume after a
kill, workers, and every misbehaving-agent case. The commands run in this process
(:func:`cdr_bench.cli.main`, its output captured at the file descriptors, so the agent process's
output counts too); only the runs that are killed are processes of their own."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

from cdr_bench.cli import main
from cdr_bench.evaluate.results import compress_log, log_text, read_result, resume_key_path

ROOT = Path(__file__).resolve().parents[2]
AGENTS = ROOT / "agents"
HANG_S = 600
"""Only a guard against a hung test: no result depends on it (never reached on any machine)."""


@dataclass
class Run:
    returncode: int
    stdout: str
    stderr: str


@pytest.fixture
def cdr(capfd):
    """``cdr(*args, cwd=None)``: ``cdr-bench ARGS`` run by :func:`cdr_bench.cli.main` in this
    process; its exit code and what it (and the agent's process) wrote."""

    def run(*args, cwd=None) -> Run:
        capfd.readouterr()
        before = os.getcwd()
        try:
            if cwd is not None:
                os.chdir(cwd)
            code = main([str(a) for a in args])
        except SystemExit as e:  # argparse's own errors and --help
            code = e.code if isinstance(e.code, int) else 1
        finally:
            os.chdir(before)
        out, err = capfd.readouterr()
        return Run(code, out, err)

    return run


def evaluate(cdr, agent, out, *extra, scenario="low", episodes=8, cwd=None):
    return cdr(
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
    return not [p for p in tmp_path.rglob("*") if p.suffix in (".json", ".jsonl", ".gz", ".xz")]


BASE = """
import time
import numpy as np

class Agent:
    def __init__(self, observation_space, action_space):
        pass
"""


# An agent that stands still before batch K + 1 when its process has CDR_TEST_STALL="K MARKER":
# it creates MARKER and waits until the evaluator is killed (its process is then re-parented,
# and it exits). The evaluator is killed after exactly K finished batches on any machine, however
# slow; without the variable the agent is an ordinary one.
STALLING = """
import os
import time
import numpy as np

BATCHES = [0]

class Agent:
    def __init__(self, observation_space, action_space):
        pass

    def reset(self, seed):
        BATCHES[0] += 1
        stall = os.environ.get("CDR_TEST_STALL")
        if stall and BATCHES[0] > int(stall.split()[0]):
            parent = os.getppid()
            open(stall.split(maxsplit=1)[1], "w").close()
            while os.getppid() == parent:
                time.sleep(0.05)
            os._exit(0)

    def act_batch(self, obs, masks):
        return np.full(len(obs), 13)

    def act(self, o):
        return 13
"""


def killed_after(agent, out, batches, tmp_path):
    """``cdr-bench evaluate`` of ``agent`` (16 low episodes in batches of 4) in a process of its
    own, SIGKILLed once ``batches`` batches are in its checkpoint; the command (for --resume)."""
    cmd = [sys.executable, "-m", "cdr_bench", "evaluate", str(agent), "--scenario", "low"]
    cmd += ["--episodes", "16", "--out", str(out), "--no-progress", "--batch-size", "4"]
    marker = tmp_path / f"stalled-{out.stem}"
    env = {**os.environ, "CDR_TEST_STALL": f"{batches} {marker}"}
    # the agent stands still in reset(seed), a request under the decision limit
    proc = subprocess.Popen(
        [*cmd, "--decision-timeout", "86400"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        env=env,
    )
    deadline = time.monotonic() + HANG_S
    while not marker.exists():
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            pytest.fail(f"the run ended before batch {batches + 1}: {proc.communicate()[1]!r}")
        time.sleep(0.01)
    os.kill(proc.pid, signal.SIGKILL)
    proc.communicate()
    assert not out.exists()
    partial = out.with_suffix(".partial.jsonl")
    assert len(partial.read_text().splitlines()) == 1 + batches  # the header and the batches
    return cmd


def test_evaluate_writes_summary_and_result_files(cdr, tmp_path):
    out = tmp_path / "r" / "direct.json"
    r = evaluate(cdr, AGENTS / "direct" / "agent.py", out, scenario="marl/low-2")
    assert r.returncode == 0, r.stderr
    assert "ownship" in r.stdout and "intruders" in r.stdout and "success" in r.stdout
    res = json.loads(out.read_text())
    assert res["schema_version"] == 4 and res["agent"]["name"] == "direct"
    assert "agent.py" in res["agent"]["files"]
    assert "metrics" not in res["scenarios"][0]  # facts in files, metrics at read time
    sc = read_result(out)["scenarios"][0]
    assert sc["id"] == "marl/low-2" and sc["config"]["id"] == "marl/low-2"
    assert set(sc["metrics"]) == {"ownship", "intruders"}
    assert sc["metrics"]["intruders"]["episodes"] == 16
    lines = log_text(out.with_suffix(".jsonl.xz")).splitlines()
    assert len(lines) == 8 and json.loads(lines[0])["scenario"] == "marl/low-2"
    first = json.loads(lines[0])["aircraft"]
    assert all(len(a["actions"]) == a["steps"] for a in first)  # one decision per step flown
    assert not out.with_suffix(".partial.jsonl").exists()


THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")


def test_agent_process_runs_one_thread_unless_told(cdr, tmp_path, monkeypatch):
    """The agent's process gets one thread per library by default; a caller's setting wins."""
    agent = write_agent(
        tmp_path,
        f"""
        import os, sys
        class Agent:
            def __init__(self, observation_space, action_space):
                got = [os.environ.get(k) for k in {THREAD_VARS!r}]
                print("threads", *got, file=sys.stderr, flush=True)
            def act(self, observation):
                mask = observation["action_mask"]
                return 13 if mask[13] else int(mask.argmax())
        """,
    )
    for var in THREAD_VARS:
        monkeypatch.delenv(var, raising=False)
    r = evaluate(cdr, agent, tmp_path / "one.json", episodes=1)
    assert r.returncode == 0 and "threads 1 1 1" in r.stderr, r.stderr
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    r = evaluate(cdr, agent, tmp_path / "three.json", episodes=1)
    assert r.returncode == 0 and "threads 3 1 1" in r.stderr, r.stderr


def test_template_agent_and_default_output_path(cdr, tmp_path):
    mine = tmp_path / "my_agent"
    mine.mkdir()
    (mine / "agent.py").write_text((AGENTS / "template" / "agent.py").read_text())
    (mine / "policy.bin").write_bytes(b"weights")
    r = cdr("evaluate", mine, "--scenario", "low", "--episodes", 3, "--no-progress", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    res = json.loads((tmp_path / "results" / "my_agent" / "low.json").read_text())
    assert set(res["agent"]["files"]) == {"agent.py", "policy.bin"}


@pytest.mark.slow
def test_workers_and_resume_give_identical_results(cdr, tmp_path):
    agent = write_agent(tmp_path, STALLING)
    ref = tmp_path / "ref.json"
    assert evaluate(cdr, agent, ref, episodes=16).returncode == 0
    par = tmp_path / "par.json"
    r = evaluate(cdr, agent, par, "--workers", 2, episodes=16)
    assert r.returncode == 0, r.stderr
    assert without_timing(par) == {**without_timing(ref), "episodes_file": "par.jsonl.xz"}
    assert par.with_suffix(".jsonl.xz").read_bytes() == ref.with_suffix(".jsonl.xz").read_bytes()

    out = tmp_path / "res.json"
    partial = out.with_suffix(".partial.jsonl")
    cmd = killed_after(agent, out, 1, tmp_path)
    with open(partial, "a") as f:
        f.write('{"kind": "batch", "scenario": "low", "bat')  # a torn write
    r = cdr(*cmd[3:], "--resume")
    assert r.returncode == 0, r.stderr
    res = json.loads(out.read_text())
    assert res["timing"]["resumed"] is True
    assert without_timing(out) == {**without_timing(ref), "episodes_file": "res.jsonl.xz"}
    assert out.with_suffix(".jsonl.xz").read_bytes() == ref.with_suffix(".jsonl.xz").read_bytes()
    assert not partial.exists()


def test_compare_paired_and_refuses_other_episodes(cdr, tmp_path):
    a, b, c = tmp_path / "a.json", tmp_path / "b.json", tmp_path / "c.json"
    assert evaluate(cdr, AGENTS / "direct", a, episodes=12).returncode == 0
    assert evaluate(cdr, AGENTS / "mvp", b, episodes=12).returncode == 0
    assert evaluate(cdr, AGENTS / "mvp", c, "--seed", 2, episodes=12).returncode == 0
    r = cdr("compare", a, b, "--json", tmp_path / "cmp.json")
    assert r.returncode == 0, r.stderr
    assert "los_rate" in r.stdout and "B-A" in r.stdout
    rows = json.loads((tmp_path / "cmp.json").read_text())["rows"]
    los = next(x for x in rows if x["metric"] == "los_rate")
    assert los["diff"] == pytest.approx(los["b"] - los["a"])
    assert los["ci95"][0] <= los["diff"] <= los["ci95"][1]
    r = cdr("compare", a, c)
    assert r.returncode == 2 and "not the same episodes" in r.stderr
    assert "Traceback" not in r.stderr
    r = cdr("report", a, b, "--out", tmp_path / "README.md")
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


# The time limits: small only where the agent never finishes (a hang fails against a 0.5 s or 1 s
# limit the same way on any machine); every other case runs far below its limits, which leaves
# room for a loaded machine to start the agent's process (Python, numpy: seconds) and decide.
ROOMY = ["--decision-timeout", HANG_S, "--load-timeout", HANG_S]
LIMITS = {
    "hang": ["--decision-timeout", 0.5, "--load-timeout", HANG_S],
    "swallows_timeout": ["--decision-timeout", 0.5, "--load-timeout", HANG_S],
    "import_hang": ["--decision-timeout", HANG_S, "--load-timeout", 1],
    "ctor_hang": ["--decision-timeout", HANG_S, "--load-timeout", 1],
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_misbehaving_agent_is_reported(cdr, tmp_path, case):
    body, expected = CASES[case]
    path = tmp_path / "missing.py" if body is None else write_agent(tmp_path, body)
    limits = LIMITS.get(case, ROOMY)
    r = evaluate(cdr, path, tmp_path / "out" / "r.json", *limits, cwd=tmp_path)
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


def test_agent_that_exits_in_a_worker_is_reported(cdr, tmp_path):
    path = write_agent(
        tmp_path, "import os\n" + BASE + "    def act(self, o):\n        os._exit(0)\n"
    )
    r = evaluate(cdr, path, tmp_path / "r.json", "--workers", 2, episodes=8)
    assert r.returncode == 2 and "exited (exit code 0" in r.stderr, r.stderr
    assert "Traceback" not in r.stderr and "BrokenProcessPool" not in r.stderr
    assert no_results_left(tmp_path)


@pytest.mark.parametrize("flag", ["--decision-timeout", "--load-timeout"])
@pytest.mark.parametrize("value", ["0", "nan", "-1", "inf", "1e9"])
def test_a_time_limit_cannot_be_disabled(cdr, tmp_path, flag, value):
    r = evaluate(cdr, AGENTS / "direct", tmp_path / "r.json", flag, value, episodes=4)
    assert r.returncode == 2, r.stderr
    assert flag in r.stderr and "Traceback" not in r.stderr
    assert f"{flag}: expected a value in (0, 86400], got {value}" in r.stderr


@pytest.fixture(scope="module")
def killed_checkpoint(tmp_path_factory):
    """The agent and the first three lines (header, batches 0 and 1) of the checkpoint of a
    run killed after two batches."""
    tmp = tmp_path_factory.mktemp("killed")
    agent = write_agent(tmp, STALLING)
    out = tmp / "r.json"
    killed_after(agent, out, 2, tmp)
    partial = out.with_suffix(".partial.jsonl")
    return agent, partial.read_text().splitlines(), resume_key_path(partial).read_bytes()


@pytest.mark.parametrize("kind", ["directory", "bare_batch", "edited", "binary"])
def test_resume_refuses_a_bad_checkpoint(cdr, tmp_path, killed_checkpoint, kind):
    agent, lines, key = killed_checkpoint
    lines = list(lines)
    out = tmp_path / "r.json"
    partial = out.with_suffix(".partial.jsonl")
    partial.write_text("\n".join(lines) + "\n")
    resume_key_path(partial).write_bytes(key)  # the run's secret, as if it had run here
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
    r = cdr("evaluate", agent, "--scenario", "low", "--episodes", 16, "--out", out,
            "--no-progress", "--batch-size", 4, "--resume")  # fmt: skip
    assert r.returncode == 2, r.stderr
    assert expected in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert not out.exists()


def test_report_refuses_a_result_whose_episode_log_differs(cdr, tmp_path):
    out = tmp_path / "r.json"
    assert evaluate(cdr, AGENTS / "direct", out, episodes=4).returncode == 0
    assert cdr("report", out).returncode == 0
    # a disk that filled up between the two renames: a new JSONL beside the old JSON
    ep = out.with_suffix(".jsonl.xz")
    text = log_text(ep)
    ep.write_bytes(compress_log(text.replace('"outcome":"los"', '"outcome":"success"') + "\n"))
    for cmd in (("report", out), ("compare", out, out)):
        r = cdr(*cmd)
        assert r.returncode == 2, r.stderr
        assert "does not match it" in r.stderr and "Traceback" not in r.stderr
    ep.unlink()
    r = cdr("report", out)
    assert r.returncode == 2 and "is missing" in r.stderr


def test_masked_action_is_counted_not_fatal(cdr, tmp_path):
    climber = write_agent(tmp_path, BASE + "    def act(self, o):\n        return 14\n")
    out = tmp_path / "r.json"
    r = evaluate(cdr, climber, out, episodes=4)  # 14 = climb: masked at level 2
    assert r.returncode == 0, r.stderr
    m = read_result(out)["scenarios"][0]["metrics"]["ownship"]
    assert m["invalid_action_rate"]["count"] > 0


def test_summary_fits_100_columns_and_existing_results_are_kept(cdr, tmp_path):
    out = tmp_path / "r.json"
    r = evaluate(cdr, AGENTS / "direct", out, scenario="curriculum/stage-12", episodes=4)
    assert r.returncode == 0, r.stderr
    table = [line for line in r.stdout.splitlines() if not line.startswith("wrote ")]
    assert max(len(line) for line in table) <= 100, r.stdout
    assert "success" in r.stdout and "clean" in r.stdout
    before = out.read_bytes()
    r = evaluate(cdr, AGENTS / "mvp", out, scenario="curriculum/stage-12", episodes=4)
    assert r.returncode == 2 and "--force" in r.stderr and "Traceback" not in r.stderr
    assert out.read_bytes() == before
    r = evaluate(
        cdr, AGENTS / "mvp", out, "--force", "--wide", scenario="curriculum/stage-12", episodes=4
    )
    assert r.returncode == 0, r.stderr
    assert "R_G" in r.stdout and "latency" in r.stdout and out.read_bytes() != before


def test_compare_on_the_scenarios_both_results_hold(cdr, tmp_path):
    one, two = tmp_path / "one.json", tmp_path / "two.json"
    assert evaluate(cdr, AGENTS / "direct", one, scenario="medium", episodes=4).returncode == 0
    r = cdr(
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
    r = cdr("compare", one, two)
    assert r.returncode == 0, r.stderr
    assert "compared on medium only" in r.stderr and "medium" in r.stdout and "low" not in r.stdout
    r = cdr("compare", one, two, "--scenario", "low")
    assert r.returncode == 2 and "--scenario low: not in" in r.stderr


def test_compare_interval_does_not_depend_on_the_other_scenarios(cdr, tmp_path):
    """A scenario's resampled episodes are seeded from its id: compare on {medium} and on
    {low, medium} give identical medium rows (the leaderboard compares other subsets)."""
    from cdr_bench.evaluate.compare import compare, mcnemar_exact

    a, b = tmp_path / "a.json", tmp_path / "b.json"
    for agent, out in (("direct", a), ("random", b)):
        r = cdr(
            "evaluate", AGENTS / agent, "--scenario", "low", "--scenario", "medium",
            "--episodes", 12, "--out", out, "--no-progress",
        )  # fmt: skip
        assert r.returncode == 0, r.stderr
    one = compare(a, b, ["medium"])["rows"]
    both = [r for r in compare(a, b, ["low", "medium"])["rows"] if r["scenario"] == "medium"]
    rev = [r for r in compare(a, b, ["medium", "low"])["rows"] if r["scenario"] == "medium"]
    assert one == both == rev
    clean = next(
        r for r in one if r["metric"] == "clean_success_rate" and r["aircraft"] == "ownship"
    )
    mc = clean["mcnemar"]
    assert mc["p"] == mcnemar_exact(mc["b"], mc["c"])
    assert (mc["c"] - mc["b"]) / 12 == pytest.approx(clean["diff"])
    r = cdr("compare", a, b, "--scenario", "medium")
    assert r.returncode == 0 and "McNemar p" in r.stdout


@pytest.mark.parametrize(
    ("flag", "value", "words"),
    [
        # --batch-size 0 was silently the default
        ("--batch-size", "0", "argument --batch-size: expected a value in [1, 10000], got 0"),
        ("--workers", "0", "argument --workers: expected a value in [1, 512], got 0"),
        ("--episodes", "-1", "argument --episodes: expected a value in [1, 100000], got -1"),
    ],
)
def test_counts_below_one_are_refused(cdr, tmp_path, flag, value, words):
    out = tmp_path / "r.json"
    r = evaluate(cdr, AGENTS / "mvp", out, flag, value)
    assert r.returncode == 2 and words in r.stderr and "Traceback" not in r.stderr
    assert list(tmp_path.iterdir()) == []
