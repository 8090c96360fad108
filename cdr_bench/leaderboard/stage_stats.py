"""What a Diffusion-AC training log says about one curriculum stage (the last, 12, by default):
the statistics behind agents/diffusion_ac/README.md's table "Training: the last curriculum
stage" (rendered by ``cdr-bench leaderboard render-docs``) and ``sweeps/stage_stats.py``.

A log is the trainer's JSON lines (plain, ``.gz`` or ``.xz``). Over the lines logged at the
stage (``curriculum/stage``): when it was reached, the rolling training success
(``charts/success_rolling``), the critic's extremes (TD loss ``losses/loss_q``, mean Q of the
sampled actions ``losses/q_mean``, largest Q ``losses/q_max`` and largest TD target
``losses/target_max``, the last two only in logs that carry them) and the largest share of
training episodes cut by the step limit (``charts/timeout``); and the fixed-evaluation points
(``curve/clean_success``: the same 100 episodes of ``high``) logged from the stage on. The reward
bounds every return by 1.0 (the goal term, docs/model.md §6), so a Q above 1 is an overestimate.
"""

from __future__ import annotations

from typing import Any


def _extreme(rows: list[dict[str, Any]], key: str) -> tuple[float, int] | None:
    """The largest value of ``key`` and the step where it occurs (None if never logged)."""
    vals = [(r[key], r["step"]) for r in rows if isinstance(r.get(key), int | float)]
    return max(vals) if vals else None


def stage_summary(rows: list[dict[str, Any]], stage: int = 12) -> dict[str, Any] | None:
    """The stage's statistics of one log's lines (None if no line is at that stage)."""
    train = [r for r in rows if "step" in r and r.get("curriculum/stage") == stage]
    if not train:
        return None
    succ = [float(r["charts/success_rolling"]) for r in train]
    first = int(train[0]["step"])
    curve = [
        float(r["curve/clean_success"])
        for r in rows
        if "curve/clean_success" in r and r["step"] >= first
    ]
    final = rows[-1].get("final", {}) if rows else {}
    return {
        "from": first,
        "to": int(final.get("step", train[-1]["step"])),
        "lines": len(train),
        "success": {
            "min": min(succ),
            "mean": sum(succ) / len(succ),
            "max": max(succ),
            # the stage's first line is the window at promotion (often low)
            "min_after_first": min(succ[1:] or succ),
        },
        "td_loss": _extreme(train, "losses/loss_q"),
        "q_mean": _extreme(train, "losses/q_mean"),
        "q_max": _extreme(train, "losses/q_max"),
        "target_max": _extreme(train, "losses/target_max"),
        "timeout": _extreme(train, "charts/timeout"),
        "curve": (
            {
                "points": len(curve),
                "min": min(curve),
                "mean": sum(curve) / len(curve),
                "max": max(curve),
                "last": curve[-1],
            }
            if curve
            else None
        ),
    }
