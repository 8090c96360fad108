"""Cold start: the first ``env.reset()`` and ``env.step()`` in a fresh process, before and after
numba's cache of the compiled simulator exists.

Run: ``python benchmarks/cold_start.py [--runs 3]``

Each measurement is a new Python process with ``NUMBA_CACHE_DIR`` set to a folder of its own:
an empty folder (numba compiles the kernels: the cost a user pays once, at the first use after
an install or an upgrade) and then the same folder again (the kernels load from the cache:
every later process). Times are wall-clock seconds, median of ``--runs`` processes each.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile

from _checkout import positive_int

_PROBE = """
import json, time
t0 = time.perf_counter()
import cdr_bench
t1 = time.perf_counter()
env = cdr_bench.parallel_env("high")
obs, _ = env.reset(seed=0)
t2 = time.perf_counter()
env.step({a: 13 for a in env.agents})
t3 = time.perf_counter()
print(json.dumps({"import": t1 - t0, "first_reset": t2 - t1, "first_step": t3 - t2}))
"""


def _probe(cache_dir: str) -> dict[str, float]:
    env = dict(os.environ, NUMBA_CACHE_DIR=cache_dir)
    out = subprocess.run(
        [sys.executable, "-c", _PROBE], capture_output=True, text=True, env=env, check=True
    )
    result: dict[str, float] = json.loads(out.stdout.strip().splitlines()[-1])
    return result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=positive_int, default=3)
    args = ap.parse_args()
    cold, warm = [], []
    for _ in range(args.runs):
        with tempfile.TemporaryDirectory() as cache:
            cold.append(_probe(cache))
            warm.append(_probe(cache))
    print(f"# python {sys.version.split()[0]}, median of {args.runs} fresh processes, seconds")
    print("| cache | import cdr_bench | first reset | first step | total |")
    print("|---|---:|---:|---:|---:|")
    for label, rows in (("empty (first use)", cold), ("present (every later use)", warm)):
        med = {k: statistics.median(r[k] for r in rows) for k in rows[0]}
        total = sum(med.values())
        print(
            f"| {label} | {med['import']:.2f} | {med['first_reset']:.2f} | "
            f"{med['first_step']:.2f} | {total:.2f} |"
        )


if __name__ == "__main__":
    main()
