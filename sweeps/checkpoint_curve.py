"""The learning curve of saved checkpoints on the trainers' fixed evaluation set.

    python sweeps/checkpoint_curve.py agents/rainbow RUN/ck_*.pt [--episodes 100]

Every trainer of cdr-bench >= 0.3 logs its greedy policy on the fixed evaluation set (100
episodes of ``high``, episode seeds 20000..; ``curve/*`` lines of its log). Runs of older
trainers (the round-1 runs, or a trainer checked out at an earlier commit to look for a
regression) did not; this script evaluates their checkpoints, each through the agent's own
``agent.py`` (``Agent(checkpoint=PATH).act_batch``), on the same episodes with the same quick
evaluator, so the numbers are comparable with the ``curve/*`` lines. One JSON line per
checkpoint, ordered by the step recorded in it (``meta.step``).

Used for the Rainbow-DQN check of sweeps/CAMPAIGN.md.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
from pathlib import Path

from cdr_bench.rl.common import CURVE_SCENARIO, CURVE_SEED
from cdr_bench.rl.quick_eval import quick_eval


def load_agent_class(agent_dir: Path):
    spec = importlib.util.spec_from_file_location("_curve_agent", agent_dir / "agent.py")
    if spec is None or spec.loader is None:
        raise SystemExit(f"error: {agent_dir}/agent.py: not a Python file")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.Agent


def checkpoint_step(path: Path) -> int:
    """The step recorded in a trainer's checkpoint; anything else is a one-line error."""
    import torch

    try:
        ck = torch.load(path, map_location="cpu", weights_only=True)
        meta = ck.get("meta", {}) if isinstance(ck, dict) else None
        if not isinstance(meta, dict):
            raise ValueError("no 'meta' mapping")
        return int(meta.get("step", -1))
    except Exception as e:  # noqa: BLE001 - any unreadable file is the same user error
        msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise SystemExit(f"error: {path}: not a cdr-bench training checkpoint ({msg})") from None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("agent_dir", type=Path, help="the agent's folder, e.g. agents/rainbow")
    ap.add_argument("checkpoints", type=Path, nargs="+", help="checkpoint files")
    ap.add_argument("--episodes", type=int, default=100)
    a = ap.parse_args(argv)
    if not (a.agent_dir / "agent.py").is_file():
        print(f"error: {a.agent_dir}: no agent.py", file=sys.stderr)
        return 2
    missing = [str(p) for p in a.checkpoints if not p.is_file()]
    if missing:
        print(f"error: no such checkpoint: {', '.join(missing)}", file=sys.stderr)
        return 2
    agent_cls = load_agent_class(a.agent_dir)
    for step, path in sorted((checkpoint_step(p), p) for p in a.checkpoints):
        try:
            agent = agent_cls(checkpoint=str(path))
        except Exception as e:  # noqa: BLE001 - e.g. another algorithm's checkpoint
            print(f"error: {path}: {a.agent_dir}/agent.py cannot load it ({e})", file=sys.stderr)
            return 2
        r = quick_eval(agent.act_batch, CURVE_SCENARIO, a.episodes, seed=CURVE_SEED)
        row = {"step": step, "checkpoint": str(path)}
        row.update({f"curve/{k}": v for k, v in r.items() if k not in ("scenario", "episodes")})
        print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
