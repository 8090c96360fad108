"""Episode identity: derived seeds, the same traffic for every agent, and the batched runner
agreeing with the PettingZoo environment episode by episode."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import cdr_bench
from cdr_bench.evaluate.loader import load_agent
from cdr_bench.evaluate.runner import run_batch, spaces_for
from cdr_bench.evaluate.seeds import derive_seed, episode_seeds
from cdr_bench.scenarios import load_scenario
from cdr_bench.sim import Simulator

ROOT = Path(__file__).resolve().parents[2]
AGENTS = ROOT / "agents"


def agent(name, config):
    return load_agent(AGENTS / name / "agent.py", *spaces_for(config))


def test_seed_derivation_is_stable_and_documented():
    s = derive_seed(0, "high", "abc", 7)
    assert s == derive_seed(0, "high", "abc", 7) and 0 <= s < 2**63
    assert len({derive_seed(0, "high", "abc", i) for i in range(1000)}) == 1000
    assert s != derive_seed(1, "high", "abc", 7) and s != derive_seed(0, "medium", "abc", 7)
    # pinned: a change here changes every published result
    assert (
        derive_seed(0, "high", "abc", 7)
        == int.from_bytes(__import__("hashlib").sha256(b"0/high/abc/7").digest()[:8], "big") >> 1
    )


def test_same_traffic_for_every_agent_and_any_batching():
    cfg = load_scenario("medium")
    a = run_batch(agent("direct", cfg), cfg, 3, 0, 6, 6)
    b = run_batch(agent("random", cfg), cfg, 3, 0, 6, 6)
    assert [e["seed"] for e in a["episodes"]] == [e["seed"] for e in b["episodes"]]
    # the start state of an episode depends on its seed only, not on the batch it is in
    seeds = episode_seeds(3, cfg.id, cfg.config_hash(), 0, 6)
    big, one = Simulator(cfg, 6), Simulator(cfg, 1)
    big.reset(seeds)
    one.reset(seeds[4:5])
    assert np.array_equal(big.pos_km[4], one.pos_km[0])
    assert np.array_equal(big.level[4], one.level[0])
    # batch 1 of size 3 is episodes 3..5 of a batch of 6
    c = run_batch(agent("direct", cfg), cfg, 3, 1, 3, 6)
    assert c["episodes"] == a["episodes"][3:]


@pytest.mark.parametrize("scenario", ["high", "marl/low-2"])
def test_batched_runner_matches_the_pettingzoo_env(scenario):
    cfg = load_scenario(scenario)
    runner = run_batch(agent("mvp", cfg), cfg, 0, 0, 5, 5)
    pol = agent("mvp", cfg)
    env = cdr_bench.parallel_env(scenario)
    for ep in runner["episodes"]:
        obs, _ = env.reset(options={"episode_seed": ep["seed"]})
        steps = {a: 0 for a in env.agents}
        outcome = {}
        goal = {a: 0.0 for a in env.agents}
        while env.agents:
            actions = {a: pol.act(obs[a]) for a in env.agents}
            obs, _, _, _, infos = env.step(actions)
            for a, info in infos.items():
                steps[a] += 1
                goal[a] += info["goal_reward"]
                if "outcome" in info:
                    outcome[a] = info["outcome"]
        for ac in ep["aircraft"]:
            assert outcome[ac["id"]] == ac["outcome"], (ep["episode"], ac["id"])
            assert steps[ac["id"]] == ac["steps"]
            assert goal[ac["id"]] == pytest.approx(ac["goal_reward"], abs=1e-5)


def test_evaluator_does_not_import_torch(tmp_path):
    code = (
        "import sys; from cdr_bench.cli import main; "
        f"rc = main(['evaluate', {str(AGENTS / 'direct')!r}, '--scenario', 'low', "
        f"'--episodes', '4', '--out', {str(tmp_path / 'r.json')!r}, '--no-progress']); "
        "assert rc == 0; print('torch' in sys.modules)"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().splitlines()[-1] == "False"
