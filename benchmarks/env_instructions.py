"""CPU instructions per PettingZoo step, counted by valgrind: a machine-load-independent measure.

Wall-clock steps/s on a shared virtual machine scatter by tens of percent from minute to minute;
the number of instructions executed does not. The script runs the stepping loop of
``env_throughput.py`` (random feasible actions, auto-reset) under ``valgrind --tool=cachegrind
--cache-sim=no`` for two step counts and reports the difference per step, so start-up and
imports cancel out. Counts still vary by a few percent between runs (memory layout changes
which code paths numpy's vector loops take), so the median of ``--runs`` measurements is shown.

Run: python benchmarks/env_instructions.py [--scenarios high] [--steps 500 2500]
Needs valgrind (apt install valgrind); each run takes about a minute.
Compare two versions of the package with ``PYTHONPATH=/path/to/checkout``.
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import shutil
import subprocess
import sys


def _worker(scenario: str, steps: int) -> None:
    import numpy as np

    import cdr_bench

    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from env_throughput import random_steps  # the loop env_throughput.py times

    env = cdr_bench.parallel_env(scenario)
    obs, _ = env.reset(seed=0)
    random_steps(env, obs, np.random.default_rng(0), steps)


def _instructions(scenario: str, steps: int) -> int:
    cmd = [
        *(["setarch", platform.machine(), "-R"] if shutil.which("setarch") else []),  # no ASLR
        "valgrind",
        "--tool=cachegrind",
        "--cache-sim=no",
        "--cachegrind-out-file=/dev/null",
        sys.executable,
        __file__,
        "--worker",
        scenario,
        str(steps),
    ]
    env = dict(os.environ, PYTHONHASHSEED="0")  # string hashing is randomised per process
    out = subprocess.run(cmd, capture_output=True, text=True, check=True, env=env).stderr
    m = re.search(r"I\s+refs:\s+([\d,]+)", out)
    if m is None:
        raise RuntimeError(f"no instruction count in valgrind's output:\n{out[-2000:]}")
    return int(m.group(1).replace(",", ""))


def main() -> None:
    if len(sys.argv) == 4 and sys.argv[1] == "--worker":
        _worker(sys.argv[2], int(sys.argv[3]))
        return
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--scenarios", nargs="+", default=["high"])
    ap.add_argument("--steps", nargs=2, type=int, default=[500, 2500], metavar=("N1", "N2"))
    ap.add_argument("--runs", type=int, default=3, help="measurements per scenario (median)")
    args = ap.parse_args()
    if shutil.which("valgrind") is None:
        sys.exit("valgrind is not installed (apt install valgrind)")
    n1, n2 = args.steps
    if not 0 < n1 < n2:
        sys.exit(f"--steps: expected 0 < N1 < N2, got {n1} {n2}")
    import cdr_bench

    print(f"# cdr_bench from {os.path.dirname(cdr_bench.__file__)}")
    print(f"| scenario | instructions per PettingZoo step, median of {args.runs} | range |")
    print("|---|---:|---|")
    for sc in args.scenarios:
        runs = sorted(
            (_instructions(sc, n2) - _instructions(sc, n1)) / (n2 - n1) for _ in range(args.runs)
        )
        median = runs[len(runs) // 2]
        print(f"| {sc} | {median:,.0f} | {runs[0]:,.0f} - {runs[-1]:,.0f} |")


if __name__ == "__main__":
    main()
