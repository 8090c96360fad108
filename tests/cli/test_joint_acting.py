"""The joint acting mode: an agent that defines ``act_joint`` is asked for the controlled
aircraft of each episode together, with the episode and the aircraft of every row; its result
says so, its decisions replay, and its re-run agrees."""

from __future__ import annotations

import json

from cdr_bench.evaluate.results import read_episodes, read_result
from cdr_bench.evaluate.runner import ACTION_CODE, close_all, load_for, run_batch
from cdr_bench.leaderboard.verify import replay_result
from cdr_bench.scenarios import load_scenario
from tests.cli.test_evaluate_cli import cdr, evaluate, write_agent  # noqa: F401 - the fixture

# Each aircraft climbs (action 14: hold heading and speed, one level up) when an aircraft with
# a lower index of ITS episode is at its level, descends (12) when one is above, else holds:
# a decision that depends on the other rows of the same episode, and on no other episode.
JOINT = """
import numpy as np

class Agent:
    def __init__(self, observation_space, action_space):
        pass

    def act(self, observation):
        raise RuntimeError("a joint agent is asked through act_joint")

    def act_joint(self, observations, masks, episodes, aircraft):
        assert (np.diff(episodes) >= 0).all()
        level = observations[:, 5]
        out = np.full(len(observations), 13)
        for i in range(len(observations)):
            same = (episodes == episodes[i]) & (aircraft < aircraft[i])
            if (same & (np.abs(level - level[i]) < 1e-6)).any():
                out[i] = 14 if masks[i, 14] else 12
        return np.where(masks[np.arange(len(out)), out] == 1, out, 13)
"""


def test_joint_agent_sees_its_episode_and_is_recorded_as_joint(cdr, tmp_path):  # noqa: F811
    agent = write_agent(tmp_path, JOINT)
    out = tmp_path / "joint.json"
    r = evaluate(cdr, agent, out, scenario="marl/low-2", episodes=8)
    assert r.returncode == 0, r.stderr
    result = read_result(out)
    assert result["acting"] == "joint"
    records = read_episodes(out, result)
    # aircraft 0 never has a lower-index aircraft: it always holds; some aircraft 1 moved
    hold = ACTION_CODE[13]
    assert all(set(ep["aircraft"][0]["actions"]) == {hold} for ep in records)
    assert any(set(ep["aircraft"][1]["actions"]) - {hold} for ep in records)
    assert replay_result(out) == (8, [])
    # the re-run of the check asks act_joint again, with the same rows: 100 % agreement
    config = load_scenario("marl/low-2")
    remote = load_for(str(agent), config)
    try:
        assert remote.joint
        replay = [{a["id"]: a["actions"] for a in ep["aircraft"]} for ep in records[:4]]
        got = run_batch(remote, config, int(result["base_seed"]), 0, 4, 8, replay=replay)
        assert got["agreement"]["agree"] == got["agreement"]["decisions"] > 0
    finally:
        close_all()
    # a decentralised agent's result has no such field
    plain = tmp_path / "plain.json"
    assert evaluate(cdr, "direct", plain, scenario="marl/low-2", episodes=4).returncode == 0
    assert "acting" not in json.loads(plain.read_text())


def test_joint_agent_that_raises_is_named(cdr, tmp_path):  # noqa: F811
    agent = write_agent(tmp_path, JOINT.replace("assert (np.diff", "assert not (np.diff"))
    r = evaluate(cdr, agent, tmp_path / "x.json", scenario="marl/low-2", episodes=4)
    assert r.returncode != 0 and "Traceback" not in r.stderr
    assert "AssertionError" in r.stderr and "episode 0" in r.stderr, r.stderr
