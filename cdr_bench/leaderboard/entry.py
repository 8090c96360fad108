"""``python -m cdr_bench.leaderboard.entry SPEC.json``: evaluate one leaderboard submission.

Started by ``cdr-bench leaderboard build`` as a child process (so that a wall-clock limit can
stop it and submissions can run side by side). This process is the trusted scorer: it runs the
simulator, the runner and writes the result files; the submission's agent runs in a separate,
confined process (:mod:`cdr_bench.evaluate.sandbox`) that sees the repository read-only, with the
leaderboard folder (results, staging) hidden, and only exchanges observations and actions with
this one. ``SPEC.json`` is written by the build and holds plain values only.

With ``rerun`` in the spec it scores nothing: it asks the agent again along committed episodes
(:func:`cdr_bench.leaderboard.verify.check_batch`) and writes how many of its decisions equal the
recorded ones (``leaderboard build --check``), and, with ``fresh`` in it, flies the agent on
episodes nobody has seen (:func:`cdr_bench.leaderboard.verify.fresh_run`).

Besides the result files it maps first-action distributions (``multimodality``) and records the
trajectories of the first episodes of the scenarios a submission replays
(:func:`cdr_bench.evaluate.api.record_traces`: the same episodes, seeds and agent reset as the
evaluation) into one JSON file (``replays``), here, where the simulator runs.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from cdr_bench.errors import UserError

REPLAY_KIND = "cdr-bench replays"


def run(spec: dict[str, Any]) -> None:
    from cdr_bench.evaluate.remote import AgentOptions
    from cdr_bench.evaluate.sandbox import Confinement, Limits

    limits = Limits(**spec["limits"])
    options = AgentOptions(
        confinement=Confinement(view=spec["root"], hidden=tuple(spec["hidden"]), limits=limits),
        limits=limits,
    )
    if spec.get("rerun") is not None:
        _rerun(spec, options)
    else:
        _evaluate(spec, options)
    _analyses(spec, options)


def _rerun(spec: dict[str, Any], options: Any) -> None:
    """Ask the agent again along committed episodes (the batches ``spec["rerun"]["batches"]``
    of the result ``spec["rerun"]["result"]``), flying the recorded decisions; write the
    agreement and any record that the replay did not reproduce to ``spec["rerun"]["out"]``."""
    from cdr_bench.evaluate.results import atomic_write_text, read_episodes, read_result
    from cdr_bench.evaluate.runner import close_all, load_for
    from cdr_bench.leaderboard.verify import check_batch, fresh_run
    from cdr_bench.scenarios import load_scenario

    rr = spec["rerun"]
    try:
        result = read_result(rr["result"], metrics=False)
        episodes = read_episodes(rr["result"], result)
    except ValueError as e:
        raise UserError(str(e)) from None
    agent_file = str(Path(spec["agent"]).resolve())
    batches = []
    try:
        for scenario, k in rr["batches"]:
            agent = load_for(agent_file, load_scenario(scenario), options)
            chk = check_batch(result, episodes, scenario, k, agent=agent)
            batches.append(
                {
                    "scenario": scenario,
                    "batch": k,
                    **(chk.agreement or {"decisions": 0, "agree": 0, "disagreements": []}),
                    "differences": chk.differences,
                }
            )
        fr = rr.get("fresh")
        fresh = None
        if fr is not None:  # episodes nobody has seen, drawn at check time
            agent = load_for(agent_file, load_scenario(fr["scenario"]), options)
            fresh = fresh_run(
                agent,
                fr["scenario"],
                int(fr["base_seed"]),
                int(fr["episodes"]),
                str(fr["agent_key"]),
                int(result["batch_size"]),
            )
    finally:
        close_all()
    doc = {"batches": batches, "fresh": fresh}
    atomic_write_text(Path(rr["out"]), json.dumps(doc) + "\n")


def _evaluate(spec: dict[str, Any], options: Any) -> None:
    from cdr_bench.evaluate.api import evaluate, resolve_jobs

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
        agent_key=spec.get("agent_key", ""),
    )


def _analyses(spec: dict[str, Any], options: Any) -> None:
    """The first-action maps and the recorded trajectories a submission asks for."""
    from cdr_bench.evaluate.analysis import multimodal
    from cdr_bench.evaluate.api import record_traces
    from cdr_bench.evaluate.results import atomic_write_text

    for mm in spec["multimodality"]:
        multimodal(
            spec["agent"],
            mm["scenario"],
            spec["multimodal"]["samples"],
            spec["seed"],
            options,
            out=mm["out"],
            episodes=spec["multimodal"]["episodes"],
            search=True,
        )
    rp = spec.get("replays")
    if rp and rp["scenarios"]:
        n = min(rp["episodes"], spec["episodes"], spec["batch_size"])
        if spec.get("rerun") is not None:  # the check: from the committed decisions
            from cdr_bench.evaluate.results import read_episodes, read_result
            from cdr_bench.leaderboard.verify import replayed_traces

            try:
                result = read_result(spec["rerun"]["result"], metrics=False)
                eps = read_episodes(spec["rerun"]["result"], result)
            except ValueError as e:
                raise UserError(str(e)) from None
            traces = {sc: replayed_traces(result, eps, sc, n) for sc in rp["scenarios"]}
        else:
            traces = {
                sc: record_traces(
                    spec["agent"],
                    sc,
                    n,
                    base_seed=spec["seed"],
                    agent_options=options,
                    batch_size=spec["batch_size"],
                    n_episodes=spec["episodes"],
                    agent_key=spec.get("agent_key", ""),
                )
                for sc in rp["scenarios"]
            }
        doc = {"kind": REPLAY_KIND, "base_seed": spec["seed"], "episodes": n, "traces": traces}
        atomic_write_text(Path(rp["out"]), json.dumps(doc, separators=(",", ":")) + "\n")


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
