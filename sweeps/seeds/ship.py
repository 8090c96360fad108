"""Ship the finished seeds of a seed sweep into an agent's folder (issue 16's campaign).

    python sweeps/seeds/ship.py runs/sweeps/seeds-ppo agents/ppo [--primary 1]

For every finished trial of the sweep (``trial.json`` and ``checkpoint.pt`` present) it copies
the checkpoint, the training log and the training arguments: the ``--primary`` seed into the
agent folder itself (``checkpoint.pt``, ``training_log.jsonl``, ``train_args.json`` and its
``curve.png``: the files the agent loads by default, replacing the earlier run), every other
seed into ``seeds/<k>/`` (``--primary 0``: every seed there, to commit the seeds that finished
before all have; the submission is not touched). ``run_dir`` in the arguments is made relative
to the repository. Then it prints the ``checkpoint`` and ``seeds`` fields for the entry's
submission file. Unfinished trials are
skipped (say so); copying is by temporary file and rename, so an interrupted run leaves no
half-written checkpoint.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _copy(src: Path, dst: Path) -> None:
    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = dst.with_name(dst.name + ".tmp")
    shutil.copyfile(src, tmp)
    os.replace(tmp, dst)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sweep_dir", type=Path, help="output folder of `cdr-bench sweep`")
    ap.add_argument("agent_dir", type=Path, help="the agent's folder, e.g. agents/ppo")
    ap.add_argument(
        "--primary", type=int, default=1, help="seed shipped as the default (1; 0: none)"
    )
    a = ap.parse_args(argv)
    if not a.sweep_dir.is_dir() or not (a.agent_dir / "agent.py").is_file():
        print(
            f"error: {a.sweep_dir} is not a folder or {a.agent_dir} has no agent.py",
            file=sys.stderr,
        )
        return 2
    shipped: dict[int, Path] = {}
    for trial in sorted(a.sweep_dir.glob("*/trial.json")):
        d = trial.parent
        t = json.loads(trial.read_text(encoding="utf-8"))
        seed = int(t["seed"])
        if not (d / "checkpoint.pt").is_file() or not (d / "result.json").is_file():
            print(f"skip {d.name} (seed {seed}): not finished")
            continue
        dest = a.agent_dir if seed == a.primary else a.agent_dir / "seeds" / str(seed)
        args = json.loads((d / "args.json").read_text(encoding="utf-8"))
        args["run_dir"] = os.path.relpath(d.resolve(), ROOT)
        _copy(d / "checkpoint.pt", dest / "checkpoint.pt")
        _copy(d / "log.jsonl", dest / "training_log.jsonl")
        if seed == a.primary and (d / "curve.png").is_file():
            _copy(d / "curve.png", dest / "curve.png")
        tmp = dest / "train_args.json.tmp"
        tmp.write_text(json.dumps(args, indent=2) + "\n", encoding="utf-8")
        os.replace(tmp, dest / "train_args.json")
        shipped[seed] = dest
        print(f"seed {seed}: {d} -> {dest}")
    staged = a.agent_dir / "seeds" / str(a.primary)
    if a.primary in shipped and staged.is_dir():  # shipped earlier with --primary 0
        shutil.rmtree(staged)
        print(f"removed {staged} (the primary seed now lives in {a.agent_dir})")
    if a.primary not in shipped:
        print(f"note: the primary seed {a.primary} is not finished yet")
    rel = {k: v.resolve().relative_to(ROOT).as_posix() for k, v in sorted(shipped.items())}
    if a.primary in rel:
        print(f"\ncheckpoint: {rel[a.primary]}/checkpoint.pt")
    print("seeds:")
    for k, p in rel.items():
        print(
            f"  - {{seed: {k}, checkpoint: {p}/checkpoint.pt, "
            f"training_log: {p}/training_log.jsonl}}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
