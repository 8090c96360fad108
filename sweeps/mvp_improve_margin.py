"""Choose the margin of an ``mvp-improve`` checkpoint on validation episodes (issue 16).

    python sweeps/mvp_improve_margin.py RUN/checkpoint.pt --slack 0 0.05 0.1 0.2 0.5

The rule of agents/mvp_improve deviates from ``mvp`` only where some action's safety Q beats
``mvp``'s by more than the margin (``slack`` in the checkpoint's config). For each margin this
writes a copy of the checkpoint with that margin (``<checkpoint folder>/slack-<x>/checkpoint.pt``;
its bytes, so its identity, differ) and scores it and ``mvp`` on the same ``--episodes`` of
``high`` drawn from ``--seed`` (default 500000: neither the leaderboard's test episodes, base
seed 20261127, nor the validation sets, base seeds 1 and 0), then prints clean success, LoS
and NMAC of each beside ``mvp``'s. Pick the margin here, then score the chosen copy on the
leaderboard's episodes.

    python sweeps/mvp_improve_margin.py --set 0.25 agents/mvp_improve/checkpoint.pt ...

writes the chosen margin into shipped checkpoints in place (the networks are unchanged: a
checkpoint's own margin plays no part in its training, whose behaviour and targets are those of
the policy it evaluates: ``mvp``, or the earlier steps of ``--base-policy``, each with the margin
it had when the step was trained). The earlier steps are kept as they are.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _load(checkpoint: Path) -> dict:
    import torch

    if not checkpoint.is_file():
        raise SystemExit(f"{checkpoint}: no such checkpoint")
    try:
        ck = torch.load(checkpoint, map_location="cpu", weights_only=True)
    except Exception as e:  # noqa: BLE001 - any unreadable file is the same user error
        raise SystemExit(f"{checkpoint}: not a training checkpoint ({type(e).__name__})") from None
    config = ck.get("config") if isinstance(ck, dict) else None
    if not isinstance(config, dict) or config.get("rule") != "mvp-improve":
        raise SystemExit(f"{checkpoint}: not trained with --combine mvp-improve")
    return ck


def _save(ck: dict, slack: float, path: Path) -> None:
    import torch

    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save({**ck, "config": {**ck["config"], "slack": float(slack)}}, str(path) + ".tmp")
    os.replace(str(path) + ".tmp", path)


def with_slack(checkpoint: Path, out_dir: Path, slacks: list[float]) -> list[Path]:
    """Copies of ``checkpoint`` with each margin; returns their paths."""
    ck = _load(checkpoint)
    paths = [out_dir / f"slack-{x:g}" / "checkpoint.pt" for x in slacks]
    for x, path in zip(slacks, paths, strict=True):
        _save(ck, x, path)
    return paths


def evaluate(agent: str, out: Path, episodes: int, seed: int, checkpoint: Path | None) -> dict:
    if not out.exists():
        env = dict(os.environ)
        env.pop("CDR_BENCH_CHECKPOINT", None)
        if checkpoint is not None:
            env["CDR_BENCH_CHECKPOINT"] = str(checkpoint.resolve())
        cmd = [sys.executable, "-m", "cdr_bench", "evaluate", agent, "--scenario", "high"]
        cmd += ["--episodes", str(episodes), "--seed", str(seed), "--out", str(out.resolve())]
        if subprocess.run([*cmd, "--no-progress"], env=env, cwd=ROOT).returncode:
            raise SystemExit(f"scoring {agent} stopped with the error above")
    own = json.loads(out.read_text())["scenarios"][0]["metrics"]["ownship"]
    return {k: own[k]["value"] for k in ("clean_success_rate", "los_rate", "nmac_rate")}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("checkpoint", type=Path, nargs="+")
    p.add_argument("--slack", type=float, nargs="+", help="margins to compare")
    p.add_argument("--set", type=float, help="write this margin into the checkpoints in place")
    p.add_argument("--episodes", type=int, default=500)
    p.add_argument("--seed", type=int, default=500_000)
    a = p.parse_args(argv)
    if (a.slack is None) == (a.set is None):
        p.error("give either --slack (compare margins) or --set (write one)")
    if a.episodes < 1 or a.seed < 0:
        p.error("--episodes must be >= 1 and --seed >= 0")
    margins = [*(a.slack or []), *([] if a.set is None else [a.set])]
    if any(not math.isfinite(x) or x < 0 for x in margins):
        p.error("margins (--slack, --set) must be finite and >= 0")
    if a.set is not None:
        loaded = [(path, _load(path)) for path in a.checkpoint]  # all checked before any write
        for path, ck in loaded:
            _save(ck, a.set, path)
            print(f"{path}: slack {a.set:g}")
        return 0
    if len(a.checkpoint) != 1:
        p.error("--slack compares the margins of one checkpoint")
    checkpoint = a.checkpoint[0]
    _load(checkpoint)
    folder = checkpoint.parent
    tag = f"high-{a.episodes}-seed{a.seed}.json"
    rows = [("mvp", evaluate("agents/mvp", folder / f"mvp-{tag}", a.episodes, a.seed, None))]
    for x, path in zip(a.slack, with_slack(checkpoint, folder, a.slack), strict=True):
        m = evaluate("agents/mvp_improve", path.parent / tag, a.episodes, a.seed, path)
        rows.append((f"slack {x:g}", m))
    print(f"{'':12} clean success    LoS   NMAC   ({a.episodes} episodes of high, seed {a.seed})")
    for name, m in rows:
        c, los, nmac = (100 * m[k] for k in ("clean_success_rate", "los_rate", "nmac_rate"))
        print(f"{name:12} {c:12.1f} % {los:5.1f} % {nmac:5.1f} %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
