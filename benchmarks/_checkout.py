"""The reference commit of a benchmark, checked out with ``git worktree`` into ``.bench/<ref>``
(ignored by git); shared by the benchmarks that compare against a reference run."""

from __future__ import annotations

import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def checkout(ref: str) -> str:
    """The path of a worktree of ``ref`` (created on first use)."""
    path = ROOT / ".bench" / ref
    if not path.exists():
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "add", "--detach", "-f", str(path), ref],
            check=True,
            capture_output=True,
        )
    return str(path)
