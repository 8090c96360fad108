"""The reference commit of a benchmark, checked out with ``git worktree`` into ``.bench/<ref>``
(ignored by git); shared by the benchmarks that compare against a reference run."""

from __future__ import annotations

import argparse
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def checkout(ref: str) -> str:
    """The path of a worktree of ``ref`` (created on first use); a ref that is not a commit of
    this repository ends the benchmark with a one-line error."""
    path = ROOT / ".bench" / ref
    if not path.exists():
        ok = subprocess.run(
            ["git", "-C", str(ROOT), "rev-parse", "--verify", "--quiet", f"{ref}^{{commit}}"],
            capture_output=True,
        )
        if ok.returncode != 0:
            raise SystemExit(
                f"error: --reference {ref!r}: not a commit of this repository (a commit id, "
                "e.g. the default, or 'none' to measure the current checkout only)"
            )
        r = subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "add", "--detach", "-f", str(path), ref],
            capture_output=True,
            text=True,
        )
        if r.returncode != 0:
            raise SystemExit(f"error: git worktree add {ref}: {r.stderr.strip()}")
    return str(path)


def positive_int(text: str) -> int:
    """An argparse type: a whole number >= 1 (rounds, steps, episodes)."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {v}")
    return v
