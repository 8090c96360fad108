"""Does emptying Rainbow-DQN's replay mid-run let it leave `direct`'s level? (issue 16)

The round-1 Rainbow-DQN run (85.6 % clean success on ``high``, cdr-bench 0.1) was stopped at
500,800 transitions and again at 1,109,504, and each time resumed with an empty replay: that
trainer did not save it (``git show b3e3efe:cdr_bench/rl/train_rainbow.py``, its docstring and
``learn_from = step + learning_starts``). Three uninterrupted seeds of the same recipe with the
current trainer stay at `direct`'s level (about 53 %). This script repeats the round-1 schedule
with the current trainer and the recipe of ``sweeps/seeds/rainbow.yaml``:

1. train to 500,800 transitions (``--stop-at``: the schedules still span the full budget);
2. empty the replay in ``state.pt`` (networks, optimiser, counters, environments and random
   state are kept) and, as the round-1 trainer did, wait ``learning_starts`` transitions before
   the next update;
3. resume to 1,109,504, empty again, resume to 1,374,560;
4. score the checkpoint on the leaderboard's 1000 episodes of ``high``
   (``RUN/result.json``; compare with ``cdr-bench compare leaderboard/results/rainbow.json
   RUN/result.json --scenario high``).

The learning curve on the fixed evaluation set (``curve/`` lines of ``RUN/log.jsonl``, every
50,000 transitions) shows whether and when it leaves `direct`'s level (0.51 on that set).

    python sweeps/rainbow_replay_reset.py runs/rainbow-replay-reset [--seed 1]

Re-running the command continues where it stopped (the trainer's ``--resume``); the resets
already done are recorded in ``RUN/resets.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

RESETS = (500_800, 1_109_504)
TOTAL = 1_374_560
RECIPE = ["--no-curriculum", "--scenario", "medium", "--eval-episodes", "0", "--no-progress"]


def saved_step(run: Path) -> int:
    import torch

    if not (run / "state.pt").exists():
        return 0
    return int(torch.load(run / "state.pt", map_location="cpu", weights_only=False)["loop"]["step"])


def empty_replay(run: Path) -> int:
    """Empty the replay of ``run/state.pt`` in place (atomically); returns the step."""
    import torch

    path = run / "state.pt"
    state = torch.load(path, map_location="cpu", weights_only=False)
    buf = state["replay"]["buffer"]
    buf["data"] = {k: np.ascontiguousarray(v[:0]) for k, v in buf["data"].items()}
    buf["pos"] = 0
    if "tree" in buf:  # prioritised: a fresh sum tree, priorities start again at 1
        buf["tree"] = np.zeros_like(buf["tree"])
        buf["max_priority"] = 1.0
    loop = state["loop"]
    args = json.loads((run / "args.json").read_text())
    loop["learn_from"] = loop["step"] + int(args["learning_starts"])
    torch.save(state, str(path) + ".tmp")
    os.replace(str(path) + ".tmp", path)
    return int(loop["step"])


def train(run: Path, seed: int, total: int, stop_at: int, extra: list[str]) -> None:
    cmd = [sys.executable, "-m", "cdr_bench", "train", "rainbow", "--run-dir", str(run), *RECIPE]
    cmd += ["--total-steps", str(total), "--seed", str(seed), *extra]
    if stop_at:
        cmd += ["--stop-at", str(stop_at)]
    if (run / "state.pt").exists():
        cmd.append("--resume")
    print("+", " ".join(cmd[1:]), flush=True)
    if subprocess.run(cmd).returncode != 0:
        raise SystemExit(f"{run}: training stopped with the error above; fix it and re-run")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("run_dir", type=Path)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--resets", type=int, nargs="*", default=list(RESETS), help="%(default)s")
    p.add_argument("--total-steps", type=int, default=TOTAL, help="%(default)s")
    p.add_argument("--no-evaluate", action="store_true", help="skip the scoring on high")
    a, extra = p.parse_known_args(argv)  # other flags go to `cdr-bench train rainbow`
    if a.total_steps < 1 or a.seed < 0:
        p.error("--total-steps must be >= 1 and --seed >= 0")
    if any(not 0 < r < a.total_steps for r in a.resets) or a.resets != sorted(set(a.resets)):
        p.error(f"--resets must increase and lie between 0 and --total-steps ({a.total_steps})")
    run: Path = a.run_dir
    run.mkdir(parents=True, exist_ok=True)
    record = run / "resets.json"
    done: list[int] = json.loads(record.read_text()) if record.exists() else []
    for boundary in a.resets:
        if saved_step(run) < boundary:
            train(run, a.seed, a.total_steps, boundary, extra)
        if not any(s >= boundary for s in done):
            done.append(empty_replay(run))
            record.write_text(json.dumps(done))
            print(f"replay emptied at {done[-1]:,} transitions", flush=True)
    if saved_step(run) < a.total_steps:
        train(run, a.seed, a.total_steps, 0, extra)
    if a.no_evaluate:
        return 0
    env = dict(os.environ, CDR_BENCH_CHECKPOINT=str((run / "checkpoint.pt").resolve()))
    out = (run / "result.json").resolve()
    cmd = ["-m", "cdr_bench", "evaluate", "agents/rainbow", "--scenario", "high", "--out", str(out)]
    if subprocess.run([sys.executable, *cmd], env=env, cwd=Path(__file__).parents[1]).returncode:
        raise SystemExit(f"{run}: scoring stopped with the error above")
    return 0


if __name__ == "__main__":
    sys.exit(main())
