"""A sweep across a two-node Ray cluster on loopback survives the loss of a worker node."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

pytest.importorskip("ray")

from cdr_bench.evaluate.results import log_text  # noqa: E402
from cdr_bench.scale.config import load_sweep  # noqa: E402
from cdr_bench.scale.sweep import RESULT_FILE, TRIAL_FILE  # noqa: E402

from .helpers import REPO, tiny_sweep  # noqa: E402

RAY = str(Path(sys.executable).with_name("ray"))
# detect a dead node within a few seconds instead of the default half minute: a killed node
# refuses the check at once, 3 checks a second apart; a live node on a loaded machine has 10 s
# to answer each (a 1 s answer limit could declare the head dead)
FAST_HEALTH = {
    "RAY_health_check_initial_delay_ms": "1000",
    "RAY_health_check_period_ms": "1000",
    "RAY_health_check_timeout_ms": "10000",
    "RAY_health_check_failure_threshold": "3",
    "RAY_USAGE_STATS_ENABLED": "0",
}
HANG_S = 600
"""Waits for nodes, trials and the driver give up after this long: a guard against a hung test
only (starting Ray nodes takes seconds here, a minute or more on a loaded machine)."""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _start(args: list[str], log: Path) -> subprocess.Popen:
    """``ray start ... --block`` in its own process group (so the node can be killed whole)."""
    return subprocess.Popen(
        [RAY, "start", *args, "--block", "--disable-usage-stats"],
        stdout=log.open("w"),
        stderr=subprocess.STDOUT,
        env={**os.environ, **FAST_HEALTH},
        start_new_session=True,
    )


def _kill(p: subprocess.Popen) -> None:
    try:
        os.killpg(p.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    p.wait(timeout=30)


_WAIT_NODES = """
import sys, time
import ray
address, n, deadline = sys.argv[1], int(sys.argv[2]), time.monotonic() + float(sys.argv[3])
while True:
    try:
        ray.init(address=address, logging_level="ERROR")
        break
    except Exception:
        if time.monotonic() > deadline:
            sys.exit(1)
        time.sleep(1)
while sum(x["Alive"] for x in ray.nodes()) != n:
    if time.monotonic() > deadline:
        sys.exit(1)
    time.sleep(0.5)
"""


def _wait_nodes(address: str, n: int, timeout_s: float = HANG_S) -> None:
    """Until ``n`` nodes of the cluster at ``address`` are alive: one process that connects
    once the head answers and then asks for the nodes every half second (a process per try
    imported Ray each time, a second or two of CPU)."""
    r = subprocess.run(
        [sys.executable, "-c", _WAIT_NODES, address, str(n), str(timeout_s)],
        capture_output=True,
        text=True,
        timeout=timeout_s + 60,
    )
    if r.returncode != 0:
        raise TimeoutError(f"{n} Ray nodes did not come up at {address}:\n{r.stderr[-2000:]}")


@pytest.fixture
def cluster(tmp_path):
    """A head node (1 CPU) on loopback; ``add_worker()`` joins a second node (1 CPU).

    Both nodes share this machine's IP, and a driver attaches to the raylet of a node with its
    own IP, the newest one if several: the test starts the sweep's driver while the head is the
    only node, so that it is the worker node, not the driver's own, that dies."""
    temp = tempfile.mkdtemp(prefix="rt", dir="/tmp")  # short: unix socket paths live here
    port = _free_port()
    address = f"127.0.0.1:{port}"
    nodes: dict[str, subprocess.Popen] = {}

    def add_worker() -> subprocess.Popen:
        nodes["worker"] = _start(["--address", address, "--num-cpus", "1"], tmp_path / "worker.log")
        return nodes["worker"]

    try:
        nodes["head"] = _start(
            [
                "--head",
                "--port",
                str(port),
                "--num-cpus",
                "1",
                "--include-dashboard=false",
                "--temp-dir",
                temp,
            ],
            tmp_path / "head.log",
        )
        _wait_nodes(address, 1)
        yield address, nodes, add_worker
    finally:
        for p in nodes.values():
            _kill(p)
        shutil.rmtree(temp, ignore_errors=True)


def _wait_work_dirs(out: Path, n: int, driver: subprocess.Popen, timeout_s: float = HANG_S) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        work = out / ".work"
        if work.is_dir() and len([p for p in work.iterdir() if p.is_dir()]) >= n:
            return
        if driver.poll() is not None:
            break
        time.sleep(0.2)
    driver.kill()
    pytest.fail(f"{n} trials never ran at once:\n" + (driver.communicate()[0] or ""))


@pytest.mark.slow
def test_sweep_survives_a_dead_worker_node(cluster, tmp_path):
    address, nodes, add_worker = cluster
    # three trials: one on the head from the start, one on the worker when it joins (the one
    # that dies with it), and one more in case the first lands before the worker is up
    sweep = load_sweep(tiny_sweep(tmp_path, [1, 2, 3]))
    out = tmp_path / "out"
    env = {**os.environ, **FAST_HEALTH}
    driver = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "cdr_bench",
            "sweep",
            str(tmp_path / "tiny.yaml"),
            "--out",
            str(out),
            "--address",
            address,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
        cwd=REPO,
    )
    _wait_work_dirs(out, 1, driver)  # the driver is attached to the head
    add_worker()
    _wait_nodes(address, 2)
    _wait_work_dirs(out, 2, driver)  # both nodes (1 CPU each) busy: the worker dies mid-trial
    time.sleep(1)
    running = {p.name for p in (out / ".work").iterdir() if p.is_dir()}  # not the trial locks
    _kill(nodes["worker"])
    stdout, _ = driver.communicate(timeout=HANG_S)
    assert driver.returncode == 0, stdout

    keys = sorted(t.key for t in sweep.trials)
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith("sweep.")) == keys
    for k in keys:
        rec = json.loads((out / k / TRIAL_FILE).read_text())
        assert rec["key"] == k
        res = json.loads((out / k / RESULT_FILE).read_text())
        assert len(res["scenarios"]) == 1 and res["scenarios"][0]["episodes"] == 2
        assert len(log_text(out / k / "result.jsonl.xz").splitlines()) == 2
    summary = json.loads((out / "sweep.json").read_text())
    assert summary["failures"] == {} and all(t["done"] for t in summary["trials"])
    # the attempt that died with the worker node did not land; a retry did
    landed = {json.loads((out / k / TRIAL_FILE).read_text())["attempt"] for k in keys}
    lost = running - landed
    assert len(lost) == 1, (running, landed, stdout)
    retried = next(iter(lost)).rsplit("-", 1)[0]
    assert retried in keys

    # the surviving cluster also serves `evaluate --backend ray --address`, same JSONL as local
    agent = str(REPO / "agents" / "random" / "agent.py")
    common = ["--scenario", "tactical/head-on", "--episodes", "4", "--batch-size", "2"]
    for name, extra in (("local", []), ("ray", ["--backend", "ray", "--address", address])):
        r = subprocess.run(
            [
                sys.executable,
                "-m",
                "cdr_bench",
                "evaluate",
                agent,
                *common,
                *extra,
                "--out",
                str(tmp_path / f"{name}.json"),
                "--no-progress",
            ],
            capture_output=True,
            text=True,
            env=env,
        )
        assert r.returncode == 0, r.stderr
    assert (tmp_path / "local.jsonl.xz").read_bytes() == (tmp_path / "ray.jsonl.xz").read_bytes()
