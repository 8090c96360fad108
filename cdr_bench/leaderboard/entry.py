"""``python -m cdr_bench.leaderboard.entry SPEC.json``: evaluate one leaderboard submission.

Started by ``cdr-bench leaderboard build`` as a child process (so that a wall-clock limit can
stop it and submissions can run side by side). This process is the trusted scorer: it runs the
simulator, the runner and writes the result files; the submission's agent runs in a separate,
confined process (:mod:`cdr_bench.evaluate.sandbox`) that sees the repository read-only, with the
leaderboard folder (results, staging) hidden, and only exchanges observations and actions with
this one. ``SPEC.json`` is written by the build and holds plain values only.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from cdr_bench.errors import UserError


def run(spec: dict[str, Any]) -> None:
    from cdr_bench.evaluate.analysis import multimodal
    from cdr_bench.evaluate.api import evaluate, resolve_jobs
    from cdr_bench.evaluate.remote import AgentOptions
    from cdr_bench.evaluate.sandbox import Confinement, Limits

    limits = Limits(**spec["limits"])
    options = AgentOptions(
        confinement=Confinement(view=spec["root"], hidden=tuple(spec["hidden"]), limits=limits),
        limits=limits,
    )
    jobs, _ = resolve_jobs(spec["scenarios"], spec["suite"], spec["episodes"])
    evaluate(
        spec["agent"],
        jobs,
        spec["out"],
        base_seed=spec["seed"],
        suite=spec["suite"],
        workers=spec["workers"],
        batch_size=spec["batch_size"],
        agent_options=options,
        progress=False,
    )
    for mm in spec["multimodality"]:
        multimodal(
            spec["agent"], mm["scenario"], spec["samples"], spec["seed"], options, out=mm["out"]
        )


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: python -m cdr_bench.leaderboard.entry SPEC.json", file=sys.stderr)
        return 2
    try:
        run(json.loads(Path(args[0]).read_text(encoding="utf-8")))
    except UserError as e:
        print(f"cdr-bench: error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
