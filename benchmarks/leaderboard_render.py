"""Time to render the leaderboard from its result files (``cdr-bench leaderboard build``
without ``--evaluate``, and the rendering half of ``--check``) against a reference commit
measured in the same run.

Each measurement is a fresh process that imports the package of one checkout and calls
``render_all`` on that checkout's own ``leaderboard/`` (submissions, result files, the landed
Fig. 7 trials), writing nothing; the current checkout's pages are compared byte for byte with
its committed ones (every plot drawn, as ``--check`` does; ``plots/manifest.json``, the record
of what the plots were drawn from, is not compared), so a speed-up that changed a page would
fail here. Rounds alternate current and reference; the table gives the median seconds and the
median of the per-round ratios reference/current (above 1: the current checkout is faster).

The default reference, ``5e4a965``, is the last commit before the bootstrap's resampling draws
were cached (one draw per sample size instead of one per interval) and gathered from contiguous
columns. Its leaderboard had 41 of the 45 Fig. 7 trials and the same 24 entries, so both render
about the same work.

Run: ``python benchmarks/leaderboard_render.py [--reference 5e4a965] [--rounds 3] [--cpu 1]``;
``--reference none`` measures the current checkout only. The reference is checked out with
``git worktree`` into ``.bench/<commit>`` (ignored).
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

# Imports the package of the checkout at argv[1] (bypassing the editable install of the current
# one), renders its leaderboard, prints the seconds and whether the pages equal the committed.
_PROBE = """
import json, sys, time
from pathlib import Path
code = Path(sys.argv[1])
sys.meta_path[:] = [f for f in sys.meta_path if 'editable' not in repr(f).lower()]
sys.path.insert(0, str(code))
from cdr_bench.leaderboard.build import render_all
lb = code / 'leaderboard'
t0 = time.perf_counter()
files = render_all(lb, lb / 'results', 'diffusion-ac')
seconds = time.perf_counter() - t0
same = all((lb / k).read_bytes() == v for k, v in files.items() if k != 'plots/manifest.json')
print(json.dumps({'seconds': seconds, 'identical': same, 'files': len(files)}))
"""


def _render(code: Path, cpu: int | None) -> dict[str, float]:
    cmd = [sys.executable, "-c", _PROBE, str(code)]
    if cpu is not None:
        cmd = ["taskset", "-c", str(cpu), *cmd]
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONHASHSEED="0")
    env.pop("PYTHONPATH", None)
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=code)
    if r.returncode != 0:
        raise SystemExit(f"render failed in {code}:\n{r.stderr[-3000:]}")
    out: dict[str, float] = json.loads(r.stdout.strip().splitlines()[-1])
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reference", default="5e4a965", help="commit, or 'none'")
    ap.add_argument("--rounds", type=positive_int, default=3)
    ap.add_argument("--cpu", type=int, default=None, help="pin every process to this CPU")
    args = ap.parse_args()
    ref = None if args.reference == "none" else Path(_checkout(args.reference))
    cur, old, ratios = [], [], []
    for _ in range(args.rounds):
        c = _render(ROOT, args.cpu)
        if not c["identical"]:
            raise SystemExit("the current checkout's pages differ from its committed ones")
        cur.append(c["seconds"])
        if ref is not None:
            r = _render(ref, args.cpu)
            old.append(r["seconds"])
            ratios.append(r["seconds"] / c["seconds"])
    head = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    print(
        f"# python {sys.version.split()[0]}, {args.rounds} rounds, load average at the end "
        f"{os.getloadavg()[0]:.1f}"
    )
    print("| measure | current (" + head + ") median s | reference median s | ratio ref/cur |")
    print("|---|---:|---:|---:|")
    tail = f"{statistics.median(old):.1f} | {statistics.median(ratios):.2f} |" if old else "- | - |"
    print(f"| render the leaderboard | {statistics.median(cur):.1f} | {tail}")


if __name__ == "__main__":
    main()
