"""A hostile submission against the trusted side and the sandbox's limits: code planted where
the scorer would import it, an agent module named like a real one, an agent that fills the
RAM-backed mounts, creates user namespaces, reads files its identity does not cover, or outlives
a killed evaluator, and a forged ``--resume`` checkpoint line. Each case held on the code
before the sandbox and scorer were tightened (it fails there) and is refused now."""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import cast

import pytest

from cdr_bench.evaluate.loader import AgentError
from cdr_bench.evaluate.remote import AgentOptions, AgentProcess
from cdr_bench.evaluate.results import PartialLog, canonical, resume_key_path, sha256_text
from cdr_bench.evaluate.sandbox import (
    CGROUP_PREFIX,
    PIDS_MAX,
    Confinement,
    Limits,
    cgroup_support,
    isolation,
    seccomp_filter,
)
from tests.leaderboard.conftest import make_repo, submission_yaml

pytestmark = pytest.mark.skipif(
    isolation()[0] != "bwrap", reason=f"needs bubblewrap: {isolation()[1]}"
)

ROOT = Path(__file__).resolve().parents[2]
DIRECT = (ROOT / "agents" / "direct" / "agent.py").read_text()


def build(root: Path, *args: object, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    """``cdr-bench leaderboard build ARGS`` in ``root``, started with ``-P`` so that the build
    process itself does not import from ``root`` (as the ``cdr-bench`` command does not)."""
    return subprocess.run(
        [sys.executable, "-P", "-m", "cdr_bench", "leaderboard", "build", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=root,
        timeout=timeout,
    )


def planted_json(marker: Path) -> str:
    """A ``json.py`` that records every process importing it, then stands in for the real
    ``json`` so that the importer carries on."""
    return textwrap.dedent(
        f"""
        import os, sys, sysconfig
        try:
            with open({str(marker)!r}, "a") as f:
                f.write(f"{{os.getpid()}} {{sys.argv}}\\n")
        except OSError:
            pass
        sys.modules.pop(__name__, None)
        sys.path[:] = [p for p in sys.path if p not in ("", os.getcwd())]
        import importlib
        sys.modules[__name__] = importlib.import_module("json")
        """
    )


def test_root_json_py_as_agent_is_refused_and_never_imported(tmp_path: Path) -> None:
    root = tmp_path / "repo"
    lb = make_repo(root)
    marker = tmp_path / "hijacked"
    (root / "json.py").write_text(planted_json(marker) + "\n" + DIRECT)
    (lb / "submissions" / "hijack.yaml").write_text(submission_yaml("json.py"))
    r = build(root, "--evaluate", "hijack", "--episodes", 4, "--reference", "weave")
    assert r.returncode != 0, r.stderr
    assert "repository root" in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert not marker.exists(), marker.read_text()


def test_module_planted_at_the_root_is_not_imported_by_the_scorer(tmp_path: Path) -> None:
    root = tmp_path / "repo"
    lb = make_repo(root)
    (lb / "submissions" / "weave.yaml").unlink()
    marker = tmp_path / "hijacked"
    (root / "json.py").write_text(planted_json(marker))
    r = build(root, "--evaluate", "--episodes", 4, "--reference", "direct")
    assert r.returncode == 0, r.stderr
    assert not marker.exists(), marker.read_text()


SCORER_TRIES = textwrap.dedent(
    """
    import os, socket, sys
    root, scratch = sys.argv[1], sys.argv[2]
    out = []
    for path in (os.path.join(root, "planted"), "/etc/planted", os.path.join(scratch, "ok")):
        try:
            open(path, "w").close()
            out.append("wrote " + path)
        except OSError as e:
            out.append("refused " + path)
    try:
        socket.create_connection(("1.1.1.1", 53), timeout=2)
        out.append("network")
    except OSError:
        out.append("no network")
    caps = [x for x in open("/proc/self/status") if x.startswith("CapEff")][0].split()[1]
    out.append("caps " + caps)
    print("|".join(out))
    """
)


def test_the_scorer_runs_confined_and_says_so(tmp_path: Path) -> None:
    """The scorer itself (trusted code reading submitted files) runs in a bubblewrap sandbox of
    its own: it can write its scratch folder only, has no network and no capability; the build
    says so, and what it wrote there is removed with the box."""
    import os

    from cdr_bench.leaderboard.scorer_box import scorer_box, scorer_isolation

    root = tmp_path / "repo"
    lb = make_repo(root)
    (lb / "submissions" / "weave.yaml").unlink()
    confined, why = scorer_isolation(str(root))
    assert confined, why
    box = scorer_box(dict(os.environ), root)
    assert box is not None
    try:
        r = subprocess.run(
            [*box.prefix, sys.executable, "-I", "-c", SCORER_TRIES, str(root), str(box.scratch)],
            capture_output=True,
            text=True,
            env=box.env,
            timeout=120,
        )
        assert r.returncode == 0, r.stderr
        assert r.stdout.strip().split("|") == [
            f"refused {root / 'planted'}",
            "refused /etc/planted",
            f"wrote {box.scratch / 'ok'}",
            "no network",
            "caps 0000000000000000",
        ]
    finally:
        box.close()
    assert not box.scratch.exists() and not (root / "planted").exists()
    r = build(root, "--evaluate", "--episodes", 2, "--reference", "direct")
    assert r.returncode == 0, r.stderr
    assert "scorer confined (bubblewrap" in r.stderr, r.stderr


@pytest.mark.parametrize("name", ["numpy.py", "json.py", "cdr_bench.py"])
def test_agent_module_shadowing_a_real_one_is_refused(tmp_path: Path, name: str) -> None:
    root = tmp_path / "repo"
    lb = make_repo(root)
    (root / "agents" / "evil").mkdir()
    (root / "agents" / "evil" / "agent.py").write_text(DIRECT)
    (root / "agents" / "evil" / name).write_text("raise SystemExit('shadowed')\n")
    (lb / "submissions" / "evil.yaml").write_text(submission_yaml("agents/evil"))
    r = build(root, "--evaluate", "evil", "--episodes", 4, "--reference", "weave")
    assert r.returncode != 0, r.stderr
    module = name.removesuffix(".py")
    assert f"would shadow the module `{module}`" in r.stderr, r.stderr


def test_reserved_names_cover_every_installed_top_level_module() -> None:
    """What the installed distributions' file lists give (``packages_distributions``, the
    slow way) is reserved, with the standard library, single-module distributions and
    ``cdr_bench``; an agent's own names are not."""
    from importlib import metadata

    from cdr_bench.evaluate.loader import reserved_module_names

    reserved = reserved_module_names()
    assert {n for n in metadata.packages_distributions() if n.isidentifier()} <= reserved
    assert {"json", "numpy", "torch", "yaml", "typing_extensions", "cdr_bench"} <= reserved
    assert not {"agent", "policy", "utils", "weights"} & reserved


# ----------------------------------------------------------------------------------------------
# Probes inside the sandbox: an agent that reports what it saw through its load error


def probe(folder: Path, code: str) -> dict[str, object]:
    """Run ``code`` (which sets ``out``, a dict) at import of an agent in ``folder``, confined
    as ``evaluate --sandbox`` run from ``folder.parent`` confines it; returns ``out``."""
    folder.mkdir(parents=True, exist_ok=True)
    agent = folder / "agent.py"
    agent.write_text(
        "import json\nout = {}\n"
        + textwrap.dedent(code)
        + "\nraise RuntimeError('PROBE ' + json.dumps(out))\n"
    )
    limits = Limits(cpu_s=60, memory_mb=2048)
    conf = Confinement(view=str(folder.parent), limits=limits)
    cwd = os.getcwd()
    os.chdir(folder.parent)
    try:
        with pytest.raises(AgentError) as e:
            AgentProcess(agent, AgentOptions(confinement=conf, limits=limits, load_timeout_s=60))
    finally:
        os.chdir(cwd)
    text = str(e.value)
    assert "PROBE " in text, text
    return dict(json.loads(text.rsplit("PROBE ", 1)[1].splitlines()[0]))


def test_writing_100_mb_to_tmp_hits_the_cap(tmp_path: Path) -> None:
    out = probe(
        tmp_path / "agents" / "filler",
        """
        import os
        for where in ("/tmp", "/dev/shm", os.environ["HOME"], "/", "/dev"):
            n = 0
            try:
                with open(os.path.join(where, "fill"), "wb") as f:
                    for _ in range(300 if where == os.environ["HOME"] else 100):
                        f.write(b"x" * 2**20)
                        f.flush()
                        n += 1
            except OSError as e:
                out[where] = [n, e.errno]
            else:
                out[where] = [n, 0]
        """,
    )
    for where, written in out.items():
        mib, err = cast("list[int]", written)
        assert mib < 100 or (mib < 300 and where not in ("/tmp", "/dev/shm")), (where, mib)
        assert err != 0, (where, mib, err)


@pytest.mark.skipif(
    cgroup_support() is None and os.getuid() == 0,
    reason="neither a writable control group nor RLIMIT_NPROC (not enforced for root) here",
)
def test_a_fork_bomb_stops_at_the_process_cap_and_leaves_no_group(tmp_path: Path) -> None:
    """The confined tree holds at most PIDS_MAX tasks (its control group's ``pids.max``; or,
    for an ordinary user without one, RLIMIT_NPROC), and its groups are gone afterwards."""
    before = _agent_groups()
    out = probe(
        tmp_path / "agents" / "forker",
        """
        import os, time
        n, err = 0, 0
        try:
            for _ in range(2000):
                if os.fork() == 0:
                    time.sleep(120)
                    os._exit(0)
                n += 1
        except OSError as e:
            err = e.errno
        out["forked"], out["errno"] = n, err
        """,
    )
    assert out["errno"] == errno.EAGAIN and int(cast(int, out["forked"])) < PIDS_MAX, out
    assert _agent_groups() == before  # removed with the tree


@pytest.mark.skipif(cgroup_support() is None, reason="no writable memory control group here")
def test_processes_that_each_fit_their_limit_cannot_exceed_the_trees_memory(tmp_path: Path) -> None:
    """RLIMIT_AS caps each process (2048 MiB in the probe); the control group caps the tree
    at that plus the tmpfs budget: of six children touching 600 MiB each, the kernel kills at
    least two."""
    out = probe(
        tmp_path / "agents" / "hog",
        """
        import os, select, signal
        ready_r, ready_w = os.pipe()
        kids = []
        for _ in range(6):
            pid = os.fork()
            if pid == 0:
                block = bytearray(600 * 2**20)
                for i in range(0, len(block), 4096):
                    block[i] = 1
                os.write(ready_w, b"x")  # holding 600 MiB now
                select.select([], [], [])  # until killed
            kids.append(pid)
        # until two children are killed: without the group's cap all six hold their block and
        # this never ends (the load timeout, 60 s, far above the work, then fails the probe)
        ready, killed, open_kids = 0, 0, set(kids)
        while killed < 2:
            if select.select([ready_r], [], [], 0.05)[0]:
                ready += len(os.read(ready_r, 64))
            for pid in list(open_kids):
                done, status = os.waitpid(pid, os.WNOHANG)
                if done:
                    open_kids.discard(pid)
                    killed += os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL
        out["killed"], out["ready"] = killed, ready
        """,
    )
    assert int(cast(int, out["killed"])) >= 2, out


def _agent_groups() -> set[str]:
    """The control groups of the agents this process confined that exist now (see
    sandbox.make_cgroup; other test workers' are theirs)."""
    mine = f"{CGROUP_PREFIX}{os.getpid()}-"
    found: set[str] = set()
    for parent in (Path("/sys/fs/cgroup/pids"), Path("/sys/fs/cgroup/unified")):
        if parent.is_dir():
            found |= {str(p) for p in parent.rglob(f"{mine}*")}
    return found


def test_no_user_namespace_no_unshare_unprivileged_uid(tmp_path: Path) -> None:
    out = probe(
        tmp_path / "agents" / "nested",
        """
        import ctypes, os
        libc = ctypes.CDLL(None, use_errno=True)
        out["uid"], out["gid"] = os.getuid(), os.getgid()
        for name, flag in (("user", 0x10000000), ("mount", 0x20000), ("net", 0x40000000)):
            out[name] = [libc.unshare(flag), ctypes.get_errno()]
        out["mount_call"] = [libc.mount(b"none", b"/tmp", b"tmpfs", 0, None), ctypes.get_errno()]
        """,
    )
    assert out["uid"] == 65534 and out["gid"] == 65534, out
    for name in ("user", "mount", "net", "mount_call"):
        assert out[name][0] == -1, (name, out)  # type: ignore[index]


def test_seccomp_filter_exists_for_this_machine() -> None:
    program = seccomp_filter()
    assert program is not None and len(program) % 8 == 0
    assert seccomp_filter("sparc") is None


def test_files_outside_the_identity_are_invisible(tmp_path: Path) -> None:
    base = tmp_path / "agents" / "curious"
    (base / "results").mkdir(parents=True)
    (base / "results" / "leak.py").write_text("ANSWER = 42\n")
    (base / "table.dat").write_text("secret\n")
    (base / "config.json").write_text("{}\n")
    (tmp_path / "leaderboard" / "results").mkdir(parents=True)
    (tmp_path / "leaderboard" / "results" / "mvp.json").write_text("{}\n")
    (tmp_path / "notes.txt").write_text("host file\n")
    out = probe(
        base,
        """
        import os
        here = os.path.dirname(os.path.abspath(__file__))
        for rel in ("results/leak.py", "table.dat", "config.json", "agent.py"):
            out[rel] = os.path.exists(os.path.join(here, rel))
        out["leaderboard"] = os.path.exists("leaderboard")
        out["notes"] = os.path.exists("notes.txt")
        out["listing"] = sorted(os.listdir(here))
        """,
    )
    assert out["agent.py"] and out["config.json"], out
    assert not out["results/leak.py"] and not out["table.dat"], out
    assert not out["leaderboard"] and not out["notes"], out
    assert out["listing"] == ["agent.py", "config.json"], out


# ----------------------------------------------------------------------------------------------
# Nothing outlives its parent


PARENT = """
import sys, time
from cdr_bench.evaluate.remote import AgentOptions, AgentProcess
from cdr_bench.evaluate.sandbox import Confinement, Limits
agent, sandbox = sys.argv[1], sys.argv[2] == "1"
limits = Limits(cpu_s=600, memory_mb=2048)
conf = Confinement(view=sys.argv[3], limits=limits) if sandbox else None
p = AgentProcess(agent, AgentOptions(confinement=conf, limits=limits if sandbox else None))
print("ready", flush=True)
time.sleep(600)
"""

SPAWNER = """
import subprocess, sys, threading, time
threading.Thread(target=time.sleep, args=(600,)).start()  # keeps the agent process alive
subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)", "{marker}"],
                 start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

class Agent:
    def __init__(self, observation_space, action_space):
        pass

    def act(self, observation):
        return 13
"""


def processes_with(marker: str) -> list[int]:
    found = []
    for pid in os.listdir("/proc"):
        if not pid.isdigit() or int(pid) == os.getpid():
            continue
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes()
        except OSError:
            continue
        if marker.encode() in cmd:
            found.append(int(pid))
    return found


@pytest.mark.parametrize("sandbox", [True, False])
def test_kill_9_of_the_evaluator_leaves_no_agent_process(tmp_path: Path, sandbox: bool) -> None:
    marker = f"cdr-bench-orphan-{os.getpid()}-{int(sandbox)}"
    folder = tmp_path / "agents" / marker  # the agent host's command line names it
    folder.mkdir(parents=True)
    (folder / "agent.py").write_text(SPAWNER.format(marker=marker))
    parent = subprocess.Popen(
        [sys.executable, "-P", "-c", PARENT, str(folder / "agent.py"), str(int(sandbox)),
         str(tmp_path)],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )  # fmt: skip
    try:
        assert parent.stdout is not None
        assert parent.stdout.readline().strip() == "ready", parent.stderr.read()  # type: ignore[union-attr]
        assert processes_with(marker), "the agent process did not start"
        parent.send_signal(signal.SIGKILL)
        parent.wait(timeout=10)
        deadline = time.monotonic() + 10
        left = processes_with(marker)
        while time.monotonic() < deadline:
            # plain mode: the agent host dies; a setsid grandchild may outlive it (documented)
            left = [p for p in processes_with(marker) if sandbox or "agent_host" in _cmdline(p)]
            if not left:
                break
            time.sleep(0.2)
        assert not left, [_cmdline(p) for p in left]
    finally:
        for pid in processes_with(marker):
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        if parent.poll() is None:
            parent.kill()


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


# ----------------------------------------------------------------------------------------------
# --resume


def test_forged_resume_line_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    run_key = sha256_text("a run")
    log = PartialLog(tmp_path / "r.partial.jsonl", run_key)
    log.start({"run_key": run_key})
    log.append({"scenario": "high", "batch": 0, "episodes": [{"outcome": "los"}]})
    assert len(PartialLog(log.path, run_key).load()) == 1
    key = resume_key_path(log.path).read_bytes()
    assert (
        key.hex() not in log.path.read_text()
        and oct(resume_key_path(log.path).stat().st_mode)[-3:] == "600"
    )
    # forged from what the file holds: the run key, the content, the old digest's recipe
    body = {"scenario": "high", "batch": 1, "episodes": [{"outcome": "success"}]}
    forged = {
        "kind": "batch",
        **body,
        "digest": sha256_text(run_key + "\n" + canonical(body)),
        "mac": sha256_text(run_key + "\n" + canonical(body)),
    }
    with open(log.path, "a") as f:
        f.write(json.dumps(forged) + "\n")
    with pytest.raises(ValueError, match="MAC does not match"):
        PartialLog(log.path, run_key).load()
    # and without its key (another user, machine or path), nothing is resumed
    resume_key_path(log.path).unlink()
    with pytest.raises(ValueError, match="key"):
        PartialLog(log.path, run_key).load()
