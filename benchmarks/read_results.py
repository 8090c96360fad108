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

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).parent))
from _checkout import PROBE_PRELUDE, probe_main  # noqa: E402

_PROBE = (
    PROBE_PRELUDE
    + """
from cdr_bench.evaluate.results import read_episodes, read_result
paths = [p for p in sorted((code / 'leaderboard' / 'results').glob('*.json'))
         if json.loads(p.read_text()).get('kind') == 'cdr-bench evaluation']
t0 = time.perf_counter()
n = sum(len(read_episodes(p, read_result(p, metrics=False))) for p in paths)
print(json.dumps({'seconds': time.perf_counter() - t0, 'episodes': n, 'results': len(paths)}))
"""
)


def _same_episodes(cur: dict[str, float], ref: dict[str, float] | None) -> None:
    if ref is not None and ref["episodes"] != cur["episodes"]:
        raise SystemExit(
            f"the reference holds {ref['episodes']} episodes, this one {cur['episodes']}"
        )


def main() -> None:
    probe_main(
        __doc__,
        "ef57f64",
        _PROBE,
        "reading",
        "read every committed result",
        check=_same_episodes,
        extra=lambda c: f"{int(c['episodes'])} episodes, ",
    )


if __name__ == "__main__":
    main()
