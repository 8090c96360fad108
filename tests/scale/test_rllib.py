"""The RLlib adapter: RLlib's own env checker and the masking keys."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("ray.rllib")

from cdr_bench.scale.rllib_env import CDRMultiAgentEnv  # noqa: E402


def test_spaces_for_every_agent_and_mask_key():
    env = CDRMultiAgentEnv({"scenario": "marl/low-2"})
    assert env.possible_agents == ["ownship_0", "intruder_0", "intruder_1"]
    obs, infos = env.reset(seed=3)
    assert set(obs) == set(env.possible_agents) == set(env.observation_spaces)
    for a, o in obs.items():
        assert set(o) == {"observations", "action_mask"}
        assert o["action_mask"].dtype == np.float32
        assert env.observation_spaces[a].contains(o)
    # random masked play to the end: "__all__" only when every agent has left
    rng = np.random.default_rng(0)
    for _ in range(2000):
        acts = {a: int(rng.choice(np.flatnonzero(o["action_mask"]))) for a, o in obs.items()}
        acts = {a: x for a, x in acts.items() if a in env.agents}
        obs, rew, term, trunc, info = env.step(acts)
        assert set(rew) == set(acts)
        if term["__all__"] or trunc["__all__"]:
            assert env.agents == []
            break
        obs = {a: o for a, o in obs.items() if a in env.agents}
    else:
        pytest.fail("episode did not end")


@pytest.mark.parametrize("scenario", ["marl/low-2", "marl/high-all", "marl/low-stream"])
def test_rllib_env_checker_accepts_it(scenario):
    """Learning intruders, every aircraft of the sector controlled (49 agents), and agents
    entering as the airways spawn them."""
    from ray.rllib.utils.pre_checks.env import check_multiagent_environments

    check_multiagent_environments(CDRMultiAgentEnv({"scenario": scenario}))


# A PPO run with one shared policy: tests/test_docs_site.py::test_rllib_tutorial (the tutorial
# docs/tutorials/rllib_ppo.py is the one RLlib training script).
