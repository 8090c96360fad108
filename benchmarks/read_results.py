"""Time to read every committed result with its per-episode records (``read_result`` and
``read_episodes``, what ``compare``, ``report``, the leaderboard and ``--check`` do first)
against a reference commit measured in the same run.

Each measurement is a fresh process that imports the package of one checkout and reads that
checkout's own ``leaderboard/results``: the records are the same facts in both (the stored form
of :mod:`cdr_bench.evaluate.logcodec` gives the full lines back), so the ratio is what storing
the logs without their derivable fields costs a reader. Rounds alternate current and reference;
the table gives the median seconds and the median of the per-round ratios reference/current
(below 1: the current checkout is slower).

The default reference, ``ef57f64``, is the last commit whose logs held every field.

Run: ``python benchmarks/read_results.py [--reference ef57f64] [--rounds 3] [--cpu 1]``;
``--reference none`` measures the current checkout only.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).parent))
from _checkout import checkout as _checkout  # noqa: E402
from _checkout import positive_int  # noqa: E402

_PROBE = """
import json, sys, time
from pathlib import Path
code = Path(sys.argv[1])
sys.meta_path[:] = [f for f in sys.meta_path if 'editable' not in repr(f).lower()]
sys.path.insert(0, str(code))
from cdr_bench.evaluate.results import read_episodes, read_result
paths = [p for p in sorted((code / 'leaderboard' / 'results').glob('*.json'))
         if json.loads(p.read_text()).get('kind') == 'cdr-bench evaluation']
t0 = time.perf_counter()
n = sum(len(read_episodes(p, read_result(p, metrics=False))) for p in paths)
print(json.dumps({'seconds': time.perf_counter() - t0, 'episodes': n, 'results': len(paths)}))
"""


def _read(code: Path, cpu: int | None) -> dict[str, float]:
    cmd = [sys.executable, "-c", _PROBE, str(code)]
    if cpu is not None:
        cmd = ["taskset", "-c", str(cpu), *cmd]
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONHASHSEED="0")
    env.pop("PYTHONPATH", None)
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=code)
    if r.returncode != 0:
        raise SystemExit(f"reading failed in {code}:\n{r.stderr[-3000:]}")
    out: dict[str, float] = json.loads(r.stdout.strip().splitlines()[-1])
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reference", default="ef57f64", help="commit, or 'none'")
    ap.add_argument("--rounds", type=positive_int, default=3)
    ap.add_argument("--cpu", type=int, default=None, help="pin every process to this CPU")
    args = ap.parse_args()
    ref = None if args.reference == "none" else Path(_checkout(args.reference))
    cur, old, ratios, n = [], [], [], 0
    for _ in range(args.rounds):
        c = _read(ROOT, args.cpu)
        cur.append(c["seconds"])
        n = int(c["episodes"])
        if ref is not None:
            r = _read(ref, args.cpu)
            if int(r["episodes"]) != n:
                raise SystemExit(f"the reference holds {r['episodes']} episodes, this one {n}")
            old.append(r["seconds"])
            ratios.append(r["seconds"] / c["seconds"])
    head = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    print(
        f"# python {sys.version.split()[0]}, {args.rounds} rounds, {n} episodes, load average "
        f"at the end {os.getloadavg()[0]:.1f}"
    )
    print("| measure | current (" + head + ") median s | reference median s | ratio ref/cur |")
    print("|---|---:|---:|---:|")
    tail = f"{statistics.median(old):.1f} | {statistics.median(ratios):.2f} |" if old else "- | - |"
    print(f"| read every committed result | {statistics.median(cur):.1f} | {tail}")


if __name__ == "__main__":
    main()
