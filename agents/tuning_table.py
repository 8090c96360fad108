"""Print the baselines' tuning table from the logs in agents/<name>/tuning/ (never typed by hand).

Each row is one tuning run (its arguments beside its log); the quick evaluation is the trainer's
own (100 episodes per density, seeds 10000..). Runs cut before their budget show the last
logged rolling training success instead.

Run: python agents/tuning_table.py [--update]   (--update: rewrite the table in BASELINES.md)
"""

from __future__ import annotations

import contextlib
import io
import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
KEYS = ("ent_coef", "combine", "lr", "n_envs", "curriculum", "scenario", "total_steps")


def main() -> None:
    print(
        "| agent | run | key flags | transitions | DPSC stage "
        "| success low / medium / high | LoS low / medium / high |"
    )
    print("|---|---|---|---:|---:|---|---|")
    for log in sorted(HERE.glob("*/tuning/*.log.jsonl")):
        run = log.name.removesuffix(".log.jsonl")
        args = json.loads(log.with_name(f"{run}.args.json").read_text())
        rows = [json.loads(x) for x in log.read_text().splitlines() if x.strip()]
        finals = [r["final"] for r in rows if "final" in r]
        flags = ", ".join(f"{k}={args[k]}" for k in KEYS if k in args)
        if finals:
            f = finals[-1]
            ev = [f[f"eval/{d}"] for d in ("low", "medium", "high")]
            succ = " / ".join(f"{e['success']:.2f}" for e in ev)
            los = " / ".join(f"{e['los']:.2f}" for e in ev)
            print(
                f"| {log.parent.parent.name} | {run} | {flags} | {f['step']:,} | {f['stage']} "
                f"| {succ} | {los} |"
            )
        else:
            last = rows[-1]
            print(
                f"| {log.parent.parent.name} | {run} | {flags} | {last['step']:,} (cut) "
                f"| {last.get('curriculum/stage', '—')} "
                f"| rolling training success {last.get('charts/success_rolling', 0):.2f} | — |"
            )


if __name__ == "__main__":
    if "--update" in sys.argv[1:]:
        from cdr_bench.evaluate.report import update_marked_block

        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            main()
        doc = HERE / "BASELINES.md"
        doc.write_text(update_marked_block(doc.read_text(), buf.getvalue(), "tuning"))
    else:
        main()
