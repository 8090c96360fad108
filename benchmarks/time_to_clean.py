"""Time to a clean success: read training runs' learning curves and print, per run, the wall
time and transitions at which the curve first reaches each threshold (benchmarks/README.md,
"Time to clean success").

A run is a ``--run-dir`` of ``cdr-bench train`` with ``--curve-every`` (its ``log.jsonl``), or a
stored training log (``training_log.jsonl.xz`` of a shipped agent). A curve point is the clean
success of ``--curve-episodes`` fresh episodes of ``high`` (``curve/clean_success``, at
``step`` transitions, ``wall_s`` seconds after the start); a threshold not reached is shown as
"-". Transitions/s is the last logged step over its wall time.

Run: ``python benchmarks/time_to_clean.py RUN_DIR_OR_LOG ... [--thresholds 0.8 0.85 0.9]``
"""

from __future__ import annotations

import argparse
import json
import lzma
from pathlib import Path
from typing import Any


def read_log(path: Path) -> list[dict[str, Any]]:
    """The log's JSON lines (``path`` a run directory, its ``log.jsonl``, or an ``.xz`` log); a
    last line cut short by a running trainer is skipped."""
    if path.is_dir():
        path = path / "log.jsonl"
    opener = lzma.open if path.suffix == ".xz" else open
    rows = []
    with opener(path, "rt") as f:
        for line in f:
            try:
                row = json.loads(line)
            except json.JSONDecodeError:
                continue
            if isinstance(row, dict):
                rows.append(row)
    return rows


def summary(rows: list[dict[str, Any]], thresholds: list[float]) -> dict[str, Any]:
    """First (wall s, transitions) at or above each threshold, the last step and its rate."""
    curve = [r for r in rows if "curve/clean_success" in r]
    steps = [r for r in rows if isinstance(r.get("step"), int) and "wall_s" in r]
    last = max(steps, key=lambda r: r["step"]) if steps else {"step": 0, "wall_s": 0.0}
    first = {}
    for t in thresholds:
        hit = next((r for r in curve if r["curve/clean_success"] >= t), None)
        first[t] = None if hit is None else (float(hit["wall_s"]), int(hit["step"]))
    rate = last["step"] / last["wall_s"] if last["wall_s"] else 0.0
    return {"first": first, "last_step": int(last["step"]), "rate": rate, "points": len(curve)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path, help="run directories or training logs")
    ap.add_argument("--thresholds", type=float, nargs="+", default=[0.8, 0.85, 0.9])
    args = ap.parse_args()
    logs = []
    for run in args.runs:
        log = run / "log.jsonl" if run.is_dir() else run
        if not log.is_file():
            ap.error(f"{run}: no training log there (a run directory with log.jsonl, or a log)")
        try:
            logs.append((run, read_log(run)))
        except (OSError, lzma.LZMAError, UnicodeDecodeError) as e:
            ap.error(f"{run}: cannot be read as a training log ({e})")
    head = " | ".join(f"first >= {t:g}: s (transitions)" for t in args.thresholds)
    print(f"| run | transitions logged | transitions/s | {head} |")
    print("|---|---:|---:|" + "---:|" * len(args.thresholds))
    for run, rows in logs:
        s = summary(rows, args.thresholds)
        cells = [
            "-" if s["first"][t] is None else f"{s['first'][t][0]:,.0f} ({s['first'][t][1]:,})"
            for t in args.thresholds
        ]
        print(f"| `{run}` | {s['last_step']:,} | {s['rate']:,.0f} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
