"""The reference commit of a benchmark, checked out with ``git worktree`` into ``.bench/<ref>``
(ignored by git); shared by the benchmarks that compare against a reference run."""

from __future__ import annotations

import argparse
import subprocess
from collections.abc import Callable
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


PROBE_PRELUDE = """
import json, sys, time
from pathlib import Path
code = Path(sys.argv[1])
sys.meta_path[:] = [f for f in sys.meta_path if 'editable' not in repr(f).lower()]
sys.path.insert(0, str(code))
"""
"""The start of a probe (:func:`run_probe`): ``code`` is the checkout at ``argv[1]``, whose
package is imported instead of the editable install of the current one."""


def run_probe(probe: str, code: Path, cpu: int | None, what: str) -> dict[str, float]:
    """Run ``probe`` (Python source that imports the package of the checkout at ``argv[1]``
    and prints one JSON line last) in a fresh single-threaded process, pinned to ``cpu`` when
    given; its JSON, or a one-line error naming ``what`` failed."""
    import json
    import os
    import sys

    cmd = [sys.executable, "-c", probe, str(code)]
    if cpu is not None:
        cmd = ["taskset", "-c", str(cpu), *cmd]
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONHASHSEED="0")
    env.pop("PYTHONPATH", None)
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=code)
    if r.returncode != 0:
        raise SystemExit(f"{what} failed in {code}:\n{r.stderr[-3000:]}")
    out: dict[str, float] = json.loads(r.stdout.strip().splitlines()[-1])
    return out


def seconds_table(label: str, cur: list[float], old: list[float], header: str) -> str:
    """The Markdown table of a benchmark timed in seconds against a reference: ``header``
    (its ``#`` line), then the medians and the median of the per-round ratios ref/cur."""
    import statistics

    head = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    ratios = [o / c for o, c in zip(old, cur, strict=False)]
    tail = f"{statistics.median(old):.1f} | {statistics.median(ratios):.2f} |" if old else "- | -"
    return "\n".join(
        [
            header,
            f"| measure | current ({head}) median s | reference median s | ratio ref/cur |",
            "|---|---:|---:|---:|",
            f"| {label} | {statistics.median(cur):.1f} | {tail}" + (" |" if not old else ""),
        ]
    )


def probe_main(
    doc: str,
    default_reference: str,
    probe: str,
    what: str,
    label: str,
    check: Callable[[dict[str, float], dict[str, float] | None], None] | None = None,
    extra: Callable[[dict[str, float]], str] = lambda c: "",
) -> None:
    """The command line of a benchmark that times one probe (:func:`run_probe`) on the current
    checkout and on a reference commit, alternating, and prints :func:`seconds_table`.
    ``check(current, reference)`` may end the run (a wrong page, other data); ``extra`` adds to
    the ``#`` line."""
    import os
    import sys

    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--reference", default=default_reference, help="commit, or 'none'")
    ap.add_argument("--rounds", type=positive_int, default=3)
    ap.add_argument("--cpu", type=int, default=None, help="pin every process to this CPU")
    args = ap.parse_args()
    ref = None if args.reference == "none" else Path(checkout(args.reference))
    cur: list[float] = []
    old: list[float] = []
    c: dict[str, float] = {}
    for _ in range(args.rounds):
        c = run_probe(probe, ROOT, args.cpu, what)
        r = run_probe(probe, ref, args.cpu, what) if ref is not None else None
        if check is not None:
            check(c, r)
        cur.append(c["seconds"])
        if r is not None:
            old.append(r["seconds"])
    header = (
        f"# python {sys.version.split()[0]}, {args.rounds} rounds, {extra(c)}load average at "
        f"the end {os.getloadavg()[0]:.1f}"
    )
    print(seconds_table(label, cur, old, header))
