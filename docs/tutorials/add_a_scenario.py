"""Tutorial "Add a scenario": validate ``tight-medium.yaml`` (a scenario extending ``medium``),
see what a mistake in it looks like, and fly episodes of it in the PettingZoo environment.

    python docs/tutorials/add_a_scenario.py                 # 50 episodes
    python docs/tutorials/add_a_scenario.py --episodes 5    # a quick look (the test)
"""

from __future__ import annotations

import argparse
import collections
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import cdr_bench

SCENARIO = Path(__file__).resolve().parent / "tight-medium.yaml"


def cdr_bench_cli(*args: str) -> int:
    """Run ``cdr-bench`` (as ``python -m cdr_bench``) and return its exit code."""
    print("$ cdr-bench", " ".join(args), flush=True)
    return subprocess.run([sys.executable, "-m", "cdr_bench", *args]).returncode


def main(argv: list[str] | None = None) -> dict[str, int]:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--episodes", type=int, default=50)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)

    # 1. Validate the file: every problem, each naming the file and the field; exit code 0 if none.
    assert cdr_bench_cli("scenarios", "validate", str(SCENARIO)) == 0

    # 2. A broken copy: a typo in a key and an out-of-range value are both reported (exit code 2).
    with tempfile.TemporaryDirectory() as tmp:
        broken = Path(tmp) / "broken.yaml"
        broken.write_text(
            SCENARIO.read_text().replace("los_km: 8.0", "los_km: -8.0") + "trafic: {per_route: 2}\n"
        )
        assert cdr_bench_cli("scenarios", "validate", str(broken)) == 2

    # 3. Load it: the fully resolved config, identified by its hash.
    config = cdr_bench.load_scenario(SCENARIO)
    print(f"\nscenario {config.id}: {config.description}")
    print(
        f"  {config.n_route_intruders} intruders on {config.traffic.routes} airways, LoS < "
        f"{config.separation.los_km} km ends the episode: {config.separation.los_terminates}"
    )
    print(f"  config hash {config.config_hash()[:16]}...")

    # 4. Fly it: the PettingZoo env takes a registry name, a YAML path or a ScenarioConfig.
    #    The ownship starts heading for its goal; holding course (action 13) flies straight to
    #    it, through whatever traffic is in the way: here a LoS ends the flight.
    env = cdr_bench.parallel_env(scenario=SCENARIO)
    outcomes: collections.Counter[str] = collections.Counter()
    for episode in range(a.episodes):
        obs, infos = env.reset(seed=a.seed + episode)
        while env.agents:
            actions = {agent: cdr_bench.actions.HOLD for agent in env.agents}
            obs, rewards, terminations, truncations, infos = env.step(actions)
        outcomes[infos["ownship_0"]["outcome"]] += 1
    print(f"  {a.episodes} episodes holding course: {dict(outcomes)}")
    print(json.dumps(dict(outcomes)))
    return dict(outcomes)


if __name__ == "__main__":
    main()
