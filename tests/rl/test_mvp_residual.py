"""A learned residual on top of ``mvp`` (``--mvp-input``, agents/mvp_residual): the training
observation carries mvp's one-hot, the checkpoint records it, and the agent that plays it
computes the same input; other agents refuse such a checkpoint."""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest

pytest.importorskip("torch")
pytest.importorskip("stable_baselines3")

import torch  # noqa: E402

from cdr_bench.resolvers import mvp_actions, with_mvp_input  # noqa: E402
from cdr_bench.rl.common import TrainArgs, training_env  # noqa: E402
from cdr_bench.rl.sb3_policies import load_actor  # noqa: E402
from cdr_bench.wrappers import vector_env_to_sb3  # noqa: E402

from .helpers import ROOT, cdr_bench  # noqa: E402


def _agent(folder: str, checkpoint: str):
    spec = importlib.util.spec_from_file_location(folder, ROOT / "agents" / folder / "agent.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.Agent(None, None, checkpoint=checkpoint)


def test_sb3_observation_carries_mvps_one_hot() -> None:
    from cdr_bench.resolvers import mvp_onehot

    env = training_env(TrainArgs(n_envs=2, curriculum=False, scenario="high", seed=3))
    venv = vector_env_to_sb3(env, include_mask=False, extra_features=mvp_onehot)
    x = venv.reset()
    obs, masks = env.observe()
    f = obs.shape[-1]
    assert venv.observation_space.shape == (f + 27,) and x.shape[1] == f + 27
    flying = env.flying.reshape(-1)
    rows = obs.reshape(-1, f)[flying]
    np.testing.assert_array_equal(x[flying], with_mvp_input(rows, masks.reshape(-1, 27)[flying]))
    assert (x[~flying] == 0).all()


@pytest.fixture(scope="module")
def residual_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("residual") / "run"
    r = cdr_bench(
        "train", "maskable-ppo", "--run-dir", str(d), "--total-steps", "64", "--n-envs", "4",
        "--no-curriculum", "--scenario", "high", "--eval-episodes", "0", "--curve-every", "0",
        "--no-progress", "--n-steps", "16", "--n-epochs", "1", "--mvp-input",
        "--teacher", "agents/mvp", "--teacher-transitions", "6000", "--teacher-epochs", "6",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    return d


def test_residual_starts_as_a_copy_of_mvp(residual_run) -> None:
    rows = [json.loads(x) for x in (residual_run / "log.jsonl").read_text().splitlines()]
    t = next(x for x in rows if "teacher/agreement_after" in x)
    assert t["teacher/agreement_before"] < 0.2 and t["teacher/agreement_after"] > 0.9
    net, config = load_actor(str(residual_run / "checkpoint.pt"))
    assert config["mvp_input"] is True and config["obs_dim"] == 42 + 27


def test_agent_plays_the_checkpoint_on_the_trainers_input(residual_run) -> None:
    ck = str(residual_run / "checkpoint.pt")
    agent = _agent("mvp_residual", ck)
    env = training_env(TrainArgs(n_envs=8, curriculum=False, scenario="high", seed=9))
    obs, masks = env.observe()
    o, m = obs.reshape(-1, obs.shape[-1]), masks.reshape(-1, 27)
    net, _ = load_actor(ck)
    with torch.no_grad():
        logits = net(torch.from_numpy(with_mvp_input(o, m)))
    want = logits.masked_fill(torch.from_numpy(m) == 0, -torch.inf).argmax(1).numpy()
    got = agent.act_batch(o, m)
    assert (got == want).mean() > 0.99  # the fixed numeric path: equal but for near ties
    assert (got == mvp_actions(o, m)).mean() > 0.9


def test_other_agents_refuse_a_residual_checkpoint_and_vice_versa(residual_run, tmp_path) -> None:
    ck = str(residual_run / "checkpoint.pt")
    with pytest.raises(ValueError, match="69 inputs, got 42"):
        _agent("maskable_ppo", ck).act_batch(np.zeros((1, 42), np.float32), np.ones((1, 27)))
    plain = torch.load(ck, weights_only=True)
    plain["config"].pop("mvp_input")
    torch.save(plain, tmp_path / "plain.pt")
    with pytest.raises(ValueError, match="not a PPO actor trained with --mvp-input"):
        _agent("mvp_residual", str(tmp_path / "plain.pt"))
