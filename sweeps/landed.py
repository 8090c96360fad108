"""What ``sweeps/landed/`` keeps of a finished run, and how to get the whole run back.

    python sweeps/landed.py slim sweeps/landed/NAME [...]      # after the study is written up
    python sweeps/landed.py restore sweeps/landed/NAME [DEST]  # DEST: runs/sweeps/NAME

A landed run (one folder per trial: ``sweeps/landed/<sweep>/<key>/``, or a single run such as
``sweeps/landed/rainbow-replay-reset/``) keeps what a reader needs: its settings
(``trial.json``, ``args.json``), its summary (``result.json``: what the leaderboard's
sensitivity study and ``cdr-bench sweep-plot`` read), its training log gzip-compressed
(``log.jsonl.gz``; ``sweeps/stage_stats.py`` and ``cdr_bench.jsonl.read_jsonl`` read it as it
is) and its learning curve (``curve.png``) where the run drew one.

``slim`` compresses a run's ``log.jsonl`` (deterministic gzip) and removes its checkpoint and
its per-episode file (``result.jsonl``, plain or ``.gz``), which stay in the git history: only
a file committed as it is is removed, and a checkpoint that a committed result, submission or
script names (the sample-target run's,
``agents/diffusion_ac/analysis/sample-target/result.json``) is kept. ``ship.py --stage`` stages
a trial whole (logs compressed): a staged seed may still be shipped.

``restore`` writes a landed sweep back as the sweep output folder ``cdr-bench sweep`` wrote
(default ``runs/sweeps/<name>/``): the logs plain, and each removed checkpoint and
per-episode file taken from the git history (the commit that removed it), checked against the
SHA-256 its ``result.json`` recorded. There ``cdr-bench sweep ... --resume`` skips the
restored trials, ``sweeps/seeds/ship.py`` ships them, ``cdr-bench report`` / ``compare`` and
``sweeps/paired_failures.py`` read their result files and
``CDR_BENCH_CHECKPOINT=runs/sweeps/<name>/<key>/checkpoint.pt cdr-bench evaluate ...`` scores
them again. A clone without that history (``--depth``) restores the rest (said per trial).
"""

from __future__ import annotations

import argparse
import gzip
import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

from cdr_bench.jsonl import GZ, gunzip_file, gzip_file

ROOT = Path(__file__).resolve().parents[1]
LOG = "log.jsonl"
CHECKPOINT = "checkpoint.pt"
EPISODES = "result.jsonl"
"""The per-episode file (the ``episodes_file`` its ``result.json`` names)."""
MARKERS = ("trial.json", "result.json", "log.jsonl", "log.jsonl.gz")
"""A folder holding one of these is a run."""
NAMED_BY = ("leaderboard/submissions/*.yaml", "agents/*/analysis/**/result.json", "agents/**/*.sh")
"""Committed files whose mention of a checkpoint's path keeps it (``slim``)."""


def runs(folder: Path) -> list[Path]:
    """The run folders at or under ``folder`` (sorted)."""
    found = {p.parent for m in MARKERS for p in folder.rglob(m)}
    return sorted(p for p in found if not p.name.startswith("."))


def _git(*args: str) -> subprocess.CompletedProcess[bytes]:
    return subprocess.run(["git", *args], cwd=ROOT, capture_output=True)


def _rel(path: Path) -> str:
    return path.resolve().relative_to(ROOT).as_posix()


def committed_as_is(path: Path) -> bool:
    """Whether ``HEAD`` holds ``path`` byte for byte (so that removing it loses nothing)."""
    head = _git("rev-parse", f"HEAD:{_rel(path)}")
    here = _git("hash-object", str(path))
    return head.returncode == 0 and head.stdout.strip() == here.stdout.strip()


def named_elsewhere(path: Path) -> list[str]:
    """The committed files of :data:`NAMED_BY` that mention ``path`` (relative to the repo)."""
    rel = _rel(path)
    out = []
    for pattern in NAMED_BY:
        for f in sorted(ROOT.glob(pattern)):
            if f.is_file() and rel in f.read_text(encoding="utf-8", errors="replace"):
                out.append(_rel(f))
    return out


def _result(run: Path) -> dict:
    try:
        data = json.loads((run / "result.json").read_text(encoding="utf-8"))
        return data if isinstance(data, dict) else {}
    except (OSError, ValueError):
        return {}


def episodes_name(run: Path) -> str:
    """The per-episode file its ``result.json`` names (``result.jsonl``)."""
    name = _result(run).get("episodes_file")
    return name if isinstance(name, str) and "/" not in name else EPISODES


def expected_sha256(run: Path) -> dict[str, str | None]:
    """File name -> the SHA-256 the run's ``result.json`` recorded for it: the checkpoint it
    scored (its override when it has one, else the agent folder's ``checkpoint.pt``) and its
    per-episode file; ``None`` where it recorded none."""
    res = _result(run)
    agent = res.get("agent") if isinstance(res.get("agent"), dict) else {}
    override = agent.get("checkpoint_override") or {}
    ck = override.get("sha256") or (agent.get("files") or {}).get(CHECKPOINT)
    ep = res.get("episodes_sha256")
    return {
        CHECKPOINT: ck if isinstance(ck, str) else None,
        episodes_name(run): ep if isinstance(ep, str) else None,
    }


def _drop(path: Path, keep_if_named: bool) -> str | None:
    """Remove ``path`` if committed as it is (and, with ``keep_if_named``, named by no
    committed file); what was done, or ``None`` when there is no such file."""
    if not path.is_file():
        return None
    names = named_elsewhere(path) if keep_if_named else []
    if names:
        return f"{path.name} kept (named by {', '.join(names)})"
    if not committed_as_is(path):
        return f"{path.name} kept (not committed as it is: commit it first)"
    path.unlink()
    return f"{path.name} removed (in the git history)"


def slim(folder: Path) -> int:
    """Compress the logs and remove the committed checkpoints and per-episode files of the
    runs under ``folder``."""
    for run in runs(folder):
        done = []
        if (run / LOG).is_file():
            gzip_file(run / LOG)
            done.append(f"{LOG}{GZ}")
        ep = episodes_name(run)
        for path, named in (
            (run / CHECKPOINT, True),
            (run / ep, False),
            (run / f"{ep}{GZ}", False),
        ):
            note = _drop(path, named)
            if note:
                done.append(note)
        print(f"{run.relative_to(folder.parent)}: {'; '.join(done) or 'nothing to do'}")
    return 0


def from_history(rel: str) -> bytes | None:
    """The last committed content of ``rel`` or of ``rel.gz`` (decompressed; from the parent
    of the commit that removed it)."""
    for name in (rel, f"{rel}{GZ}"):
        log = _git("log", "-1", "--format=%H", "--diff-filter=D", "--", name)
        commit = log.stdout.decode().strip()
        if log.returncode != 0 or not commit:
            continue
        show = _git("show", f"{commit}^:{name}")
        if show.returncode == 0:
            return gzip.decompress(show.stdout) if name.endswith(GZ) else show.stdout
    return None


def restore(src: Path, dest: Path) -> int:
    """Write the landed runs under ``src`` to ``dest`` as the sweep wrote them."""
    status = 0
    for run in runs(src):
        out = dest / run.relative_to(src)
        out.mkdir(parents=True, exist_ok=True)
        for f in sorted(run.iterdir()):
            if not f.is_file():
                continue
            if f.name.endswith(".jsonl" + GZ):
                gunzip_file(f, out / f.name.removesuffix(GZ))
            else:
                shutil.copyfile(f, out / f.name)
        notes = []
        for name, want in expected_sha256(run).items():
            if (out / name).is_file() or not (want or name == CHECKPOINT):
                continue
            data = from_history(_rel(run / name))
            if data is None:
                notes.append(f"without {name} (not in this clone's history)")
            elif want is not None and hashlib.sha256(data).hexdigest() != want:
                notes.append(f"without {name} (the one in history is not the one its result names)")
                status = 1
            else:
                tmp = out / f"{name}.tmp"
                tmp.write_bytes(data)
                os.replace(tmp, out / name)
                notes.append(f"{name} from the git history")
        print(f"{run} -> {out}: restored{', ' if notes else ''}{', '.join(notes)}")
    return status


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("slim", help="compress the logs, drop committed checkpoints")
    s.add_argument("folders", type=Path, nargs="+", help="sweeps/landed/NAME (or one run)")
    r = sub.add_parser("restore", help="write a landed sweep back as a sweep output folder")
    r.add_argument("src", type=Path, help="sweeps/landed/NAME")
    r.add_argument("dest", type=Path, nargs="?", help="default: runs/sweeps/NAME")
    a = ap.parse_args(argv)
    folders = a.folders if a.cmd == "slim" else [a.src]
    for f in folders:
        if not f.is_dir() or not runs(f):
            print(f"error: {f}: not a folder of landed runs", file=sys.stderr)
            return 2
    if a.cmd == "slim":
        return max(slim(f) for f in folders)
    dest = a.dest or ROOT / "runs" / "sweeps" / a.src.resolve().name
    return restore(a.src, dest)


if __name__ == "__main__":
    raise SystemExit(main())
