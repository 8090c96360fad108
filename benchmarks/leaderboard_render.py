"""Time to render the leaderboard from its result files (``cdr-bench leaderboard build``
without ``--evaluate``, and the rendering half of ``--check``) against a reference commit
measured in the same run.

Each measurement is a fresh process that imports the package of one checkout and calls
``render_all`` on that checkout's own ``leaderboard/`` (submissions, result files, the landed
Fig. 7 trials), writing nothing; the current checkout's pages are compared byte for byte with
its committed ones (every plot drawn, as ``--check`` does on a machine that has not drawn them
before: no plot cache; ``plots/manifest.json``, the record
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

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).parent))
from _checkout import PROBE_PRELUDE, probe_main  # noqa: E402

# Imports the package of the checkout at argv[1] (bypassing the editable install of the current
# one), renders its leaderboard, prints the seconds and whether the pages equal the committed.
_PROBE = (
    PROBE_PRELUDE
    + """
import os; os.environ['CDR_BENCH_PLOT_CACHE'] = ''  # every plot drawn
from cdr_bench.leaderboard.build import render_all
lb = code / 'leaderboard'
t0 = time.perf_counter()
files = render_all(lb, lb / 'results', 'diffusion-ac')
seconds = time.perf_counter() - t0
same = all((lb / k).read_bytes() == v for k, v in files.items() if k != 'plots/manifest.json')
print(json.dumps({'seconds': seconds, 'identical': same, 'files': len(files)}))
"""
)


def _identical(cur: dict[str, float], ref: dict[str, float] | None) -> None:
    if not cur["identical"]:
        raise SystemExit("the current checkout's pages differ from its committed ones")


def main() -> None:
    probe_main(__doc__, "5e4a965", _PROBE, "render", "render the leaderboard", check=_identical)


if __name__ == "__main__":
    main()
