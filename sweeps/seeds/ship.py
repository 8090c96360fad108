"""Ship the finished seeds of a seed sweep into an agent's folder (issue 16's campaign).

    python sweeps/seeds/ship.py runs/sweeps/seeds-ppo agents/ppo [--primary 1]

For every finished trial of the sweep (``trial.json`` and ``checkpoint.pt`` present) it copies
the checkpoint, the training log and the training arguments: the ``--primary`` seed into the
agent folder itself (``checkpoint.pt``, ``training_log.jsonl.xz``, ``train_args.json`` and its
``curve.png``: the files the agent loads by default, replacing the earlier run), every other
seed into ``seeds/<k>/``. The training log is shipped xz-compressed
(:func:`cdr_bench.evaluate.results.compress_log`, deterministic; the leaderboard reads it as
it is) and replaces a plain ``training_log.jsonl`` of an earlier run. ``run_dir`` in the
arguments is made relative to the repository. Then it prints the ``checkpoint`` and ``seeds``
fields for the entry's submission file. Unfinished trials are skipped (say so); copying is by
temporary file and rename, so an interrupted run leaves no half-written checkpoint.

    python sweeps/seeds/ship.py runs/sweeps/table3 agents/diffusion_ac \
        --where ablation=no-dpsc --into ablations/no-dpsc

ships only the trials whose training flags match every ``--where FLAG=VALUE`` (a sweep of
several settings, such as the Table 3 ablations), into ``<agent_dir>/<into>`` (the same layout:
the primary seed there, the others in ``seeds/<k>/``).

    python sweeps/seeds/ship.py runs/sweeps/seeds-td3 --stage

commits nothing to an agent (its weights are part of its leaderboard identity, so they change
only with a re-scoring): it copies the finished trials to ``sweeps/landed/<sweep>/<key>/`` so
that a finished seed is committed as it lands: trial.json, args.json, result.json and
checkpoint.pt as the sweep wrote them, the per-episode file and the training log compressed
(result.jsonl.gz, log.jsonl.gz) and the learning curve (curve.png) where the run drew one.
``python sweeps/landed.py restore sweeps/landed/<sweep>`` writes it back as a sweep output folder
(``runs/sweeps/<sweep>/``: ``cdr-bench sweep ... --resume`` skips those trials, this script
ships them); ``python sweeps/landed.py slim`` drops the checkpoints and per-episode files of a
study nothing will ship from (they stay in the git history, where ``restore`` finds them).
Shipping trials later removes their staged copies (one copy of each checkpoint; the staged
trials of other settings stay); trials whose checkpoint is already shipped into an agent folder
are not staged again.
A sweep folder given here may hold the logs plain or compressed.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import sys
from pathlib import Path

from cdr_bench.evaluate.results import compress_log, log_text
from cdr_bench.jsonl import existing, gzip_file, read_bytes

ROOT = Path(__file__).resolve().parents[2]


def _copy(src: Path, dst: Path) -> None:
    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = dst.with_name(dst.name + ".tmp")
    shutil.copyfile(src, tmp)
    os.replace(tmp, dst)


STAGED = ("trial.json", "result.json", "result.jsonl", "checkpoint.pt", "log.jsonl", "args.json")
COMPRESSED = ("result.jsonl", "log.jsonl")
"""Staged as ``<name>.gz`` (:func:`cdr_bench.jsonl.gzip_file`)."""
OPTIONAL = ("curve.png",)
"""Staged when the trial has it."""


def _digest(path: Path) -> str:
    """SHA-256 of the file's content (decompressed if it is gzip or xz; any name)."""
    return hashlib.sha256(read_bytes(path)).hexdigest()


def shipped_checkpoints() -> dict[str, Path]:
    """sha256 -> path of every checkpoint and training log already shipped into an agent folder
    (the log too: a shipped checkpoint may have been edited after shipping, e.g. the margin
    written into an MVP + learned improvement checkpoint, while its log is a byte copy)."""
    agents = ROOT / "agents"
    logs = [
        *agents.rglob("training_log.jsonl"),
        *agents.rglob("training_log.jsonl.gz"),
        *agents.rglob("training_log.jsonl.xz"),
    ]
    return {_digest(p): p for p in sorted([*agents.rglob("*.pt"), *logs])}


def stage(sweep_dir: Path) -> int:
    dest = ROOT / "sweeps" / "landed" / sweep_dir.resolve().name
    n = 0
    shipped = shipped_checkpoints()
    for trial in sorted(sweep_dir.glob("*/trial.json")):
        d = trial.parent
        if not all((d / f).is_file() for f in STAGED):
            print(f"skip {d.name}: not finished")
            continue
        where = shipped.get(_digest(d / "checkpoint.pt")) or shipped.get(_digest(d / "log.jsonl"))
        if where is not None:  # one copy of each checkpoint: the agent folder's
            print(f"skip {d.name}: already shipped as {where.relative_to(ROOT)}")
            continue
        for f in STAGED:
            _copy(d / f, dest / d.name / f)
            if f in COMPRESSED:
                gzip_file(dest / d.name / f)
        for f in OPTIONAL:
            if (d / f).is_file():
                _copy(d / f, dest / d.name / f)
        n += 1
        print(f"{d.name} (seed {json.loads(trial.read_text())['seed']}) -> {dest / d.name}")
    print(f"{n} finished trial(s) in {dest}")
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sweep_dir", type=Path, help="output folder of `cdr-bench sweep`")
    ap.add_argument("agent_dir", type=Path, nargs="?", help="the agent's folder, e.g. agents/ppo")
    ap.add_argument("--stage", action="store_true", help="copy to sweeps/landed/ only")
    ap.add_argument("--primary", type=int, default=1, help="seed shipped as the default (1)")
    ap.add_argument(
        "--where",
        action="append",
        default=[],
        metavar="FLAG=VALUE",
        help="only trials trained with this flag value (repeatable), e.g. ablation=no-dpsc",
    )
    ap.add_argument(
        "--into", default="", help="sub-folder of the agent folder, e.g. ablations/no-dpsc"
    )
    a = ap.parse_args(argv)
    where = {}
    for w in a.where:
        flag, eq, value = w.partition("=")
        if not eq or not flag:
            print(f"error: --where {w!r}: expected FLAG=VALUE", file=sys.stderr)
            return 2
        where[flag] = value
    into = Path(a.into)
    if into.is_absolute() or ".." in into.parts:
        print(f"error: --into {a.into!r}: expected a path inside the agent folder", file=sys.stderr)
        return 2
    if not a.sweep_dir.is_dir():
        print(f"error: {a.sweep_dir}: not a folder (expected a `cdr-bench sweep` output folder)",
              file=sys.stderr)  # fmt: skip
        return 2
    if a.stage:
        return stage(a.sweep_dir)
    if a.agent_dir is None or not (a.agent_dir / "agent.py").is_file():
        print(
            f"error: {a.agent_dir or 'agent_dir'}: expected an agent folder holding agent.py "
            "(or use --stage)",
            file=sys.stderr,
        )
        return 2
    shipped: dict[int, Path] = {}
    keys: list[str] = []
    root = a.agent_dir / into
    chosen: dict[int, Path] = {}
    for trial in sorted(a.sweep_dir.glob("*/trial.json")):
        d = trial.parent
        t = json.loads(trial.read_text(encoding="utf-8"))
        seed = int(t["seed"])
        flags = t.get("train_flags", {})
        if any(str(flags.get(k)) != v for k, v in where.items()):
            continue
        if not (d / "checkpoint.pt").is_file() or not (d / "result.json").is_file():
            print(f"skip {d.name} (seed {seed}): not finished")
            continue
        if seed in chosen:
            print(
                f"error: trials {chosen[seed].name} and {d.name} both have seed {seed}; "
                "choose one setting with --where",
                file=sys.stderr,
            )
            return 2
        chosen[seed] = d
    for seed, d in sorted(chosen.items()):
        dest = root if seed == a.primary else root / "seeds" / str(seed)
        args = json.loads((d / "args.json").read_text(encoding="utf-8"))
        args["run_dir"] = os.path.relpath(d.resolve(), ROOT)
        _copy(d / "checkpoint.pt", dest / "checkpoint.pt")
        dest.mkdir(parents=True, exist_ok=True)
        tmp = dest / "training_log.jsonl.xz.tmp"
        tmp.write_bytes(compress_log(log_text(existing(d / "log.jsonl"), "training log")))
        os.replace(tmp, dest / "training_log.jsonl.xz")
        (dest / "training_log.jsonl").unlink(missing_ok=True)  # an earlier run's, plain
        if seed == a.primary and (d / "curve.png").is_file():
            _copy(d / "curve.png", dest / "curve.png")
        tmp = dest / "train_args.json.tmp"
        tmp.write_text(json.dumps(args, indent=2) + "\n", encoding="utf-8")
        os.replace(tmp, dest / "train_args.json")
        shipped[seed] = dest
        keys.append(d.name)
        print(f"seed {seed}: {d} -> {dest}")
    landed = ROOT / "sweeps" / "landed" / a.sweep_dir.resolve().name
    if shipped and landed.is_dir() and landed.resolve() != a.sweep_dir.resolve():
        for key in keys:  # one copy: the shipped seeds replace their staged ones
            if (landed / key).is_dir():
                shutil.rmtree(landed / key)
                print(f"removed the staged copy {landed / key}")
        if not any(landed.iterdir()):
            landed.rmdir()
    if a.primary not in shipped:
        print(f"note: the primary seed {a.primary} is not finished yet")
    rel = {k: v.resolve().relative_to(ROOT).as_posix() for k, v in sorted(shipped.items())}
    if a.primary in rel:
        print(f"\ncheckpoint: {rel[a.primary]}/checkpoint.pt")
    print("seeds:")
    for k, p in rel.items():
        print(
            f"  - {{seed: {k}, checkpoint: {p}/checkpoint.pt, "
            f"training_log: {p}/training_log.jsonl.xz}}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
