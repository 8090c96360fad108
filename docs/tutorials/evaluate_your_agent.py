"""Tutorial "Evaluate your agent": score ``level_change_agent.py`` with ``cdr-bench evaluate``,
read the result file, and compare the agent with the shipped ``direct`` agent on the same
episodes with ``cdr-bench compare``.

    python docs/tutorials/evaluate_your_agent.py                  # 200 episodes of medium
    python docs/tutorials/evaluate_your_agent.py --episodes 20    # a quick look (the test)
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

from cdr_bench.evaluate.results import read_episodes, read_result

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]


def cdr_bench(*args: str) -> None:
    """Run the ``cdr-bench`` command (as ``python -m cdr_bench``, the same program)."""
    print("$ cdr-bench", " ".join(args), flush=True)
    subprocess.run([sys.executable, "-m", "cdr_bench", *args], check=True)


def main(argv: list[str] | None = None) -> dict[str, float]:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenario", default="medium")
    p.add_argument("--episodes", type=int, default=200)
    p.add_argument("--out", default="results/tutorial", help="folder for the result files")
    a = p.parse_args(argv)
    out = Path(a.out)
    mine, direct = out / "level_change.json", out / "direct.json"

    # 1. Score the agent: its own process, the same episodes for every agent (seeded by the
    #    scenario, its config hash and the episode index). Writes a JSON (the run) and a
    #    xz JSONL beside it (one record per episode: each aircraft's outcome, events and
    #    decisions).
    run = ["--scenario", a.scenario, "--episodes", str(a.episodes), "--no-progress", "--force"]
    cdr_bench("evaluate", str(HERE / "level_change_agent.py"), *run, "--out", str(mine))

    # 2. Read the result: one entry per scenario, metrics per role with 95 % intervals
    #    (read_result checks the pair of files and computes the metrics from the records).
    result = read_result(mine)
    (scenario,) = result["scenarios"]
    metrics = scenario["metrics"]["ownship"]
    print(f"\n{result['agent']['name']} on {scenario['id']}, {scenario['episodes']} episodes:")
    summary = {}
    for name in ("success_rate", "los_rate", "nmac_rate", "timeout_rate", "avg_steps_success"):
        m = metrics[name]
        low, high = m["ci95"]
        print(f"  {name:18s} {m['value']:8.3f}   95 % interval [{low:.3f}, {high:.3f}]")
        summary[name] = m["value"]
    records = read_episodes(mine, result)
    print(f"  per-episode records: {len(records)} (first: {sorted(records[0])[:6]} ...)")

    # 3. Compare with a shipped agent on the same episodes: paired differences B - A.
    cdr_bench("evaluate", str(REPO / "agents" / "direct" / "agent.py"), *run, "--out", str(direct))
    cdr_bench("compare", str(direct), str(mine))
    print(json.dumps(summary))
    return summary


if __name__ == "__main__":
    main()
