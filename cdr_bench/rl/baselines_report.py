"""Markdown results table of the learned baselines (agents/BASELINES.md) from result files only.

    python -m cdr_bench.rl.baselines_report \\
        PPO=agents/ppo/eval/paper.json MaskablePPO=agents/maskable_ppo/eval/paper.json ...

Each ``LABEL=PATH`` is a ``cdr-bench evaluate`` result JSON; one row per density scenario (low,
medium, high) with 95 % intervals, followed by the paper's Table 2 row of the same algorithm
(``--published LABEL=ROW``, e.g. ``PPO=PPO``), marked *published*: the paper's own simulator,
shown beside our measurements, never mixed with them.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

DENSITIES = ("low", "medium", "high")
RATES = ("success_rate", "los_rate", "nmac_rate", "timeout_rate")


def _pct(m: dict) -> str:
    lo, hi = m["ci95"]
    return f"{100 * m['value']:.1f} [{100 * lo:.1f}, {100 * hi:.1f}]"


def _mean(m: dict) -> str:
    if m["value"] is None:
        return "-"
    lo, hi = m["ci95"]
    return f"{m['value']:.2f} [{lo:.2f}, {hi:.2f}]"


def rows_of(label: str, path: str) -> list[str]:
    res = json.loads(Path(path).read_text())
    out = []
    by_id = {s["id"]: s for s in res["scenarios"]}
    for d in DENSITIES:
        if d not in by_id:
            continue
        m = by_id[d]["metrics"]["ownship"]
        cells = [_pct(m[k]) for k in RATES]
        cells += [_mean(m["avg_steps_success"]), _mean(m["goal_reward"]), _mean(m["safety_reward"])]
        cells += [_pct(m["clean_success_rate"]), f"{100 * m['invalid_action_rate']['value']:.2f}"]
        out.append(f"| {label} | {d} | {m['episodes']} | " + " | ".join(cells) + " |")
    return out


def published_rows(label: str, row: str, leaderboard_dir: str) -> list[str]:
    from cdr_bench.leaderboard.published import load_published

    pub = load_published(leaderboard_dir)
    out = []
    for d in DENSITIES:
        r = pub.lookup(row, d)
        if r is None:
            continue
        v = r.values
        cells = [f"{v[k]:g}" for k in RATES]
        cells += [f"{v['average_steps']:g}", f"{v['average_goal_reward']:g}"]
        cells += [f"{v['average_safety_reward']:g}", "-", "-"]
        out.append(f"| {label} (published) | {d} | 1000 | " + " | ".join(cells) + " |")
    return out


HEADER = (
    "| agent | density | episodes | success % | LoS % | NMAC % | timeout % | steps (success) "
    "| goal reward | safety reward | clean success % | invalid % |\n"
    "|---|---|---:|---|---|---|---|---|---|---|---|---:|"
)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("results", nargs="+", help="LABEL=result.json")
    p.add_argument("--published", action="append", default=[], help="LABEL=Table-2 row name")
    p.add_argument("--leaderboard-dir", default="leaderboard")
    p.add_argument(
        "--update",
        metavar="FILE",
        help="write the table between <!-- MARKER:start --> and <!-- MARKER:end --> in FILE",
    )
    p.add_argument("--marker", default="learned-agents")
    ns = p.parse_args(argv)
    pub = dict(x.split("=", 1) for x in ns.published)
    lines = [HEADER]
    for item in ns.results:
        label, path = item.split("=", 1)
        lines += rows_of(label, path)
        if label in pub:
            lines += published_rows(label, pub[label], ns.leaderboard_dir)
    table = "\n".join(lines) + "\n"
    if ns.update:
        from cdr_bench.evaluate.report import update_marked_block
        from cdr_bench.evaluate.results import atomic_write_text

        f = Path(ns.update)
        atomic_write_text(f, update_marked_block(f.read_text(), table, ns.marker))
    else:
        print(table, end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
