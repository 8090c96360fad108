"""Which episodes fail for one agent, the other, or both (issue 16, "beating mvp").

    python sweeps/paired_failures.py leaderboard/results/mvp.jsonl X.jsonl [Y.jsonl ...] \
        [--scenario high]

Each file may be plain or gzip (``X.jsonl.gz``, as ``sweeps/seeds/ship.py --stage`` writes
it; a slimmed landed trial's comes back with ``python sweeps/landed.py restore``).

A failure is an ownship episode that is not a clean success (LoS, NMAC or no success). Episodes
are paired by seed; prints, per candidate, the failures of the first file only ("fixed"), of the
candidate only ("new") and of both. ``cdr-bench compare`` gives the paired intervals.
"""

from __future__ import annotations

import argparse
import sys

from cdr_bench.jsonl import read_jsonl


def failures(path: str, scenario: str) -> dict[int, bool]:
    out: dict[int, bool] = {}
    for r in read_jsonl(path):
        if r["scenario"] == scenario:
            a = r["aircraft"][0]
            out[r["seed"]] = bool(a["los"] or a["nmac"] or a["outcome"] != "success")
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("base")
    p.add_argument("candidates", nargs="+")
    p.add_argument("--scenario", default="high")
    a = p.parse_args(argv)
    try:
        base = failures(a.base, a.scenario)
        others = {c: failures(c, a.scenario) for c in a.candidates}
    except (OSError, ValueError, KeyError, IndexError, TypeError) as e:
        print(f"paired_failures: not a per-episode result file (.jsonl): {e!r}", file=sys.stderr)
        return 2
    for c, x in others.items():
        common = sorted(set(base) & set(x))
        if not common:
            print(f"{c}: no episodes of {a.scenario!r} in common with {a.base}", file=sys.stderr)
            return 2
        fixed = sum(base[s] and not x[s] for s in common)
        new = sum(x[s] and not base[s] for s in common)
        both = sum(x[s] and base[s] for s in common)
        print(f"{c}: {len(common)} episodes, fixed {fixed}, new {new}, both {both}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
