"""Compile the numba kernels of the shipped learned agents (and the simulator's) into the
package's cache before the leaderboard check starts (CI only).

A confined agent cannot write the package's cache; it starts from a copy of it
(``cdr_bench.evaluate.sandbox.seed_numba_cache``) and compiles what is missing in its own
scratch folder, which is then thrown away. On a fresh clone the copy is empty, so every
re-run of a learned entry compiled the fixed numeric runtime (``cdr_bench.inference``) again:
10-20 s of CPU each, a hundred seconds or more per check. Here each shipped submission's
agent is built once, unconfined, from the repository's committed files (what the test suite
also runs in-process), and asked for one batch of decisions: its kernels land in the package's
cache, and every confined re-run afterwards loads them. It changes no result: a cache entry is
the compiled form of the package's own source, checked against that source by numba.

It also compiles the trainers' kernels (``cdr_bench.rl.kernels``: a few hundred steps of
Diffusion-AC and of Rainbow-DQN, which use all of them) and the bootstrap's
(``cdr_bench.evaluate.metrics``): on a fresh clone the test processes and the training runs they
start compiled them side by side, each its own copy (15-20 s of CPU each), before the first had
written the cache. For this machine's CPU only: run with ``NUMBA_CPU_NAME=generic`` it compiles
the agents' and the simulator's for numba's generic CPU (never beside a run for another CPU:
numba adds an entry to a kernel's cache index by reading the index and writing it back).

Having compiled the simulator's and the agents' kernels afresh (CI's clone has no cache), it
reads their machine code for fused multiply-adds and libm calls (``tests/kernel_code.py``) and
fails if it finds one; it prints ``machine code inspected`` when it has read all of them, and
CI then tells the two tests that would compile them again for the same reading to skip it.
Kernels loaded from the cache cannot be read: it says so, and the tests do it themselves.

``--part agents`` compiles the agents' and the simulator's kernels only (they need the base
dependencies and torch: CI runs it while the dev extra installs), ``--part trainers`` the
trainers' and the bootstrap's.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", choices=("agents", "trainers", "all"), default="all")
    part = ap.parse_args().part
    host = not os.environ.get("NUMBA_CPU_NAME")  # trainers and intervals: the host CPU only
    t0 = time.perf_counter()
    if part != "trainers":
        n = warm_agents()
        inspected = inspect() if host else "not inspected (another CPU's code)"
        print(f"warm_kernels: the kernels of {n} agents and of the simulator compiled; {inspected}")
    if part != "agents" and host:
        warm_trainers()
        print("warm_kernels: the trainers' and the bootstrap's kernels compiled")
    print(f"warm_kernels: {time.perf_counter() - t0:.0f} s")
    return 0


def inspect() -> str:
    """Read the machine code of the simulator's and the inference path's kernels; exit 1 on a
    fused multiply-add or a libm call."""
    sys.path.insert(0, str(ROOT))
    import cdr_bench.inference
    from cdr_bench.sim import kernels
    from tests.kernel_code import CachedCode, inspect_module

    try:
        found = {**inspect_module(kernels), **inspect_module(cdr_bench.inference)}
    except CachedCode as e:
        return f"not inspected (loaded from the cache: {e})"
    bad = {k: v for k, v in found.items() if v}
    if bad:
        print("warm_kernels: in the machine code:", file=sys.stderr)
        for k, v in bad.items():
            print(f"  {k}: {', '.join(sorted(set(v)))}", file=sys.stderr)
        raise SystemExit(1)
    need = ("step_episodes", "observe_episodes", "reset_episodes", "accumulate_step")
    missing = [f for f in need if not any(f"kernels.{f}(" in k for k in found)]
    if missing or not any(k.startswith("cdr_bench.inference.") for k in found):
        raise SystemExit(f"warm_kernels: not compiled here: {missing or 'cdr_bench.inference'}")
    return (
        f"machine code inspected: {len(found)} kernel signatures, no fused multiply-add, "
        "no libm call"
    )


def warm_agents() -> int:
    from gymnasium import spaces

    from cdr_bench.scenarios import load_scenario
    from cdr_bench.vector_env import observation_space

    obs_space = observation_space(load_scenario("high"))
    act_space = spaces.Discrete(27)
    width = obs_space["observation"].shape[0]
    seen = set()
    for sub in sorted((ROOT / "leaderboard" / "submissions").glob("*.yaml")):
        doc = yaml.safe_load(sub.read_text())
        agent = ROOT / doc["agent"]
        path = agent / "agent.py" if agent.is_dir() else agent
        if "cdr_bench.inference" not in path.read_text() or (path, doc.get("checkpoint")) in seen:
            continue
        seen.add((path, doc.get("checkpoint")))
        if doc.get("checkpoint"):
            os.environ["CDR_BENCH_CHECKPOINT"] = str(ROOT / doc["checkpoint"])
        spec = importlib.util.spec_from_file_location(f"warm_{sub.stem}", path)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.path.insert(0, str(path.parent))
        try:
            spec.loader.exec_module(module)
            a = module.Agent(obs_space, act_space)
            a.reset(0)
            a.act_batch(np.zeros((4, width), np.float32), np.ones((4, 27), np.int8))
        finally:
            sys.path.remove(str(path.parent))
            os.environ.pop("CDR_BENCH_CHECKPOINT", None)
    # the simulator's kernels too (replay and the batched env), before the test processes and
    # the check start compiling the same ones side by side
    from cdr_bench.leaderboard.verify import replay_result

    for name in ("mvp", "mvp-reciprocal"):
        replay_result(ROOT / "leaderboard" / "results" / f"{name}.json", first=1)
    return len(seen)


def warm_trainers() -> None:
    import tempfile

    from cdr_bench.cli import main as cdr_bench
    from cdr_bench.evaluate.metrics import bootstrap_mean_interval, ratio_interval

    bootstrap_mean_interval(np.arange(3.0))
    ratio_interval(np.ones((3, 2)))
    tiny = ["--total-steps", "200", "--n-envs", "4", "--eval-episodes", "0", "--no-progress"]
    tiny += ["--width", "16", "--learning-starts", "64", "--batch-size", "16"]
    with tempfile.TemporaryDirectory() as d:
        for name in ("diffusion-ac", "rainbow"):
            code = cdr_bench(["train", name, "--run-dir", f"{d}/{name}", *tiny])
            assert code == 0, f"train {name} exited with {code}"


if __name__ == "__main__":
    sys.exit(main())
