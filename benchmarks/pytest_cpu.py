"""The CPU seconds of each test: a pytest plugin, and a summary of what it wrote.

Each test process appends one JSON line per test to ``$PYTEST_CPU_DIR/cpu-<pid>.jsonl``: the
test's id, its wall time, and the CPU (user + system) of the test process and of the
subprocesses it waited for (``getrusage``: sandboxed scorers and agents, CLI runs, training
runs; not Ray's daemons, which no test process waits for: ``benchmarks/cpu_load.sh`` counts
those with the rest of the machine).

    rm -rf /tmp/cpu && PYTEST_CPU_DIR=/tmp/cpu PYTHONPATH=benchmarks pytest -q -p pytest_cpu
    python benchmarks/pytest_cpu.py /tmp/cpu          # the 40 costliest tests, then per file
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import resource
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _checkout import positive_int  # noqa: E402

DIR_ENV = "PYTEST_CPU_DIR"


def _cpu() -> tuple[float, float]:
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime, kids.ru_utime + kids.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    folder = os.environ.get(DIR_ENV)
    own, kids = _cpu()
    t0 = time.perf_counter()
    yield
    if not folder:
        return
    own1, kids1 = _cpu()
    row = {
        "id": item.nodeid,
        "wall_s": round(time.perf_counter() - t0, 3),
        "cpu_s": round(own1 - own, 3),
        "children_cpu_s": round(kids1 - kids, 3),
    }
    Path(folder).mkdir(parents=True, exist_ok=True)
    with open(Path(folder) / f"cpu-{os.getpid()}.jsonl", "a") as f:
        f.write(json.dumps(row) + "\n")


def summarize(folder: Path, top: int) -> str:
    rows: list[dict[str, Any]] = []
    for path in sorted(folder.glob("cpu-*.jsonl")):
        rows += [json.loads(line) for line in path.read_text().splitlines() if line]
    if not rows:
        raise SystemExit(
            f"pytest_cpu.py: error: no cpu-*.jsonl in {folder}: run pytest with -p pytest_cpu first"
        )
    for r in rows:
        r["total"] = r["cpu_s"] + r["children_cpu_s"]
    rows.sort(key=lambda r: -r["total"])
    lines = [
        f"{len(rows)} tests: {sum(r['total'] for r in rows):.0f} CPU s "
        f"(test processes and what they waited for), {sum(r['wall_s'] for r in rows):.0f} s "
        "of test time summed over the test processes",
        "",
        "| CPU s | of it in subprocesses | wall s | test |",
        "|---:|---:|---:|---|",
    ]
    lines += [
        f"| {r['total']:.1f} | {r['children_cpu_s']:.1f} | {r['wall_s']:.1f} | `{r['id']}` |"
        for r in rows[:top]
    ]
    files: collections.Counter[str] = collections.Counter()
    for r in rows:
        files[r["id"].split("::")[0]] += r["total"]
    lines += ["", "| CPU s | file |", "|---:|---|"]
    lines += [f"| {cpu:.1f} | `{name}` |" for name, cpu in files.most_common(top)]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path, help=f"the folder of the run's {DIR_ENV}")
    ap.add_argument("--top", type=positive_int, default=40, help="rows of each table")
    args = ap.parse_args()
    print(summarize(args.folder, args.top))


if __name__ == "__main__":
    main()
