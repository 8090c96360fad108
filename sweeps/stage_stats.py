"""What a Diffusion-AC training log says about its last curriculum stage (issue 16, item 5).

    python sweeps/stage_stats.py agents/diffusion_ac/training_log.jsonl.xz \\
        agents/diffusion_ac/seeds/*/training_log.jsonl.xz [--stage 12] [--below 0.5] \\
        [--q-above 1.5]

A log may be plain, gzip (``log.jsonl.gz``, as kept in ``sweeps/landed/`` and
``agents/*/analysis/``) or xz (``training_log.jsonl.xz``, as shipped into an agent folder).

For each log, over the lines logged at ``--stage`` (12, the last DPSC stage), it prints:

* when the stage was reached (transitions);
* the rolling training success (``charts/success_rolling``): minimum, mean, and maximum;
* the collapse windows, the stretches of lines whose rolling success is below ``--below``;
* the overestimation windows, the stretches of lines whose largest Q is above ``--q-above``
  (1.5), each with its peak, the lowest rolling success and the largest timeout share in it;
* the critic's extremes with the step where each occurs: the TD loss (``losses/loss_q``), the
  mean Q of the sampled actions (``losses/q_mean``), the largest Q (``losses/q_max``) and the
  largest TD target (``losses/target_max``; the last two only in logs that carry them);
* the largest share of training episodes cut by the step limit (``charts/timeout``);
* the fixed-evaluation points (``curve/clean_success``, same 100 episodes of ``high``) logged
  at that stage, when the log has them.

The statistics are :func:`cdr_bench.leaderboard.stage_stats.stage_summary`'s, which also renders
agents/diffusion_ac/README.md's stage-12 table; the windows are this script's. The reward bounds
every return by 1.0 (the goal term, docs/model.md §6), so a Q above 1 is an overestimate.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from cdr_bench.jsonl import existing, read_jsonl
from cdr_bench.leaderboard.stage_stats import stage_summary


def _lines(path: Path) -> list[dict]:
    return read_jsonl(path)


def _at(x: tuple[float, int] | None) -> str:
    return "-" if x is None else f"{x[0]:+.2f} at {x[1]:,}"


def _windows(rows: list[dict], inside) -> list[list[dict]]:
    """The maximal stretches of consecutive ``rows`` for which ``inside(row)`` holds."""
    out: list[list[dict]] = []
    run: list[dict] = []
    for r in rows:
        if inside(r):
            run.append(r)
        elif run:
            out.append(run)
            run = []
    if run:
        out.append(run)
    return out


def summarise(path: Path, stage: int, below: float, q_above: float = 1.5) -> str:
    rows = _lines(path)
    s = stage_summary(rows, stage)  # the numbers of agents/diffusion_ac/README.md's table
    if s is None:
        return f"{path}: no line at stage {stage}"
    train = [r for r in rows if "step" in r and r.get("curriculum/stage") == stage]
    windows = [
        (w[0]["step"], w[-1]["step"], min(r["charts/success_rolling"] for r in w))
        for w in _windows(train, lambda r: r["charts/success_rolling"] < below)
    ]
    over = []
    for w in _windows(train, lambda r: r.get("losses/q_max", float("-inf")) > q_above):
        peak = max(w, key=lambda r: r["losses/q_max"])
        over.append(
            f"{w[0]['step']:,}-{w[-1]['step']:,} (peak {peak['losses/q_max']:+.2f} at "
            f"{peak['step']:,}, rolling success min "
            f"{min(r['charts/success_rolling'] for r in w):.2f}, timeout share max "
            f"{max(r.get('charts/timeout', 0.0) for r in w):.2f})"
        )
    sc = s["success"]
    out = [
        f"{path}",
        f"  stage {stage} from {s['from']:,} to {s['to']:,} transitions ({s['lines']} log lines)",
        f"  rolling success min {sc['min']:.2f}  mean {sc['mean']:.2f}  max {sc['max']:.2f}  "
        f"(min after the stage's first line, the window at promotion: "
        f"{sc['min_after_first']:.2f})",
        "  below {:.2f}: {}".format(
            below,
            "; ".join(f"{a:,}-{b:,} (min {m:.2f})" for a, b, m in windows) or "never",
        ),
        f"  max TD loss {_at(s['td_loss'])}; max mean Q {_at(s['q_mean'])}; max Q "
        f"{_at(s['q_max'])}; max TD target {_at(s['target_max'])}",
        f"  max timeout share {_at(s['timeout'])}",
        f"  largest Q above {q_above:+.2f}: {'; '.join(over) or 'never'}",
    ]
    curve = [r for r in rows if "curve/clean_success" in r and r["step"] >= s["from"]]
    if s["curve"] is not None:
        c = s["curve"]
        out.append(
            f"  fixed evaluation ({curve[0]['curve/episodes']} episodes of "
            f"{curve[0]['curve/scenario']}, {c['points']} points): clean success min "
            f"{c['min']:.2f} mean {c['mean']:.2f} max {c['max']:.2f} "
            f"last {c['last']:.2f}"
        )
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("logs", nargs="+", type=Path, help="training_log.jsonl[.xz] / log.jsonl files")
    ap.add_argument("--stage", type=int, default=12, help="curriculum stage (12)")
    ap.add_argument("--below", type=float, default=0.5, help="collapse threshold (0.5)")
    ap.add_argument(
        "--q-above", type=float, default=1.5, help="overestimation threshold of the largest Q (1.5)"
    )
    a = ap.parse_args(argv)
    for p in a.logs:
        if not existing(p).is_file():
            print(f"error: {p}: no such file", file=sys.stderr)
            return 2
        try:
            print(summarise(p, a.stage, a.below, a.q_above))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError, KeyError, TypeError) as e:
            print(f"error: {p}: not a training log ({e})", file=sys.stderr)
            return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
