"""One step of policy improvement on ``mvp`` (``--combine mvp-improve``, agents/mvp_improve):
the rule by hand, the same decision in torch and on the fixed inference path, the networks
evaluate mvp (its action in the targets, its action as behaviour), and the agent's errors."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from cdr_bench.errors import UserError  # noqa: E402
from cdr_bench.inference import SafeDQNQ, improved_actions  # noqa: E402
from cdr_bench.resolvers import mvp_actions  # noqa: E402
from cdr_bench.rl.common import TrainArgs, training_env  # noqa: E402
from cdr_bench.rl.safe_dqn import SafeDQN, SafeDQNConfig, combine  # noqa: E402
from cdr_bench.rl.train_safe_dqn import Args as SafeDQNArgs  # noqa: E402
from cdr_bench.rl.train_safe_dqn import base_steps  # noqa: E402

from .helpers import ROOT, cdr_bench, sweep_script  # noqa: E402
from .test_safe_dqn import _q  # noqa: E402

margin = sweep_script("mvp_improve_margin")


def test_rule_by_hand():
    qs = _q([-1.0, -0.5, -0.2, -0.3])
    qg = _q([0.0, 0.0, -2.0, 1.0])
    mask = torch.ones(1, 27, dtype=torch.int8)
    base = torch.tensor([0])
    # gains over action 0: 0.5, 0.8, 0.7; slack 0.6 -> {2, 3}; best Q_S + Q_G there: 3 (0.7)
    assert combine(qs, qg, mask, "mvp-improve", 0.6, base).item() == 3
    # slack 0.75 -> only action 2
    assert combine(qs, qg, mask, "mvp-improve", 0.75, base).item() == 2
    # slack 0.9 -> nothing is enough better: mvp's action
    assert combine(qs, qg, mask, "mvp-improve", 0.9, base).item() == 0
    # a masked action never wins
    mask[0, 2] = 0
    assert combine(qs, qg, mask, "mvp-improve", 0.75, base).item() == 0
    with pytest.raises(ValueError, match="needs mvp's actions"):
        combine(qs, qg, mask, "mvp-improve", 0.1)


def _states(n=400):
    env = training_env(TrainArgs(n_envs=16, curriculum=False, scenario="high", seed=5))
    rows, masks = [], []
    rng = np.random.default_rng(0)
    while sum(len(r) for r in rows) < n:
        obs, mask = env.observe()
        f = env.flying.reshape(-1)
        rows.append(obs.reshape(-1, obs.shape[-1])[f])
        masks.append(mask.reshape(-1, 27)[f])
        acts = mvp_actions(obs.reshape(-1, obs.shape[-1]), mask.reshape(-1, 27))
        acts = np.where(rng.random(len(acts)) < 0.2, 13, acts)
        env.step(acts.reshape(env.flying.shape))
    return np.concatenate(rows)[:n], np.concatenate(masks)[:n]


def test_torch_and_inference_path_decide_alike():
    obs, mask = _states()
    torch.manual_seed(1)
    learner = SafeDQN(SafeDQNConfig(obs_dim=obs.shape[1], width=32, rule="mvp-improve", slack=0.02))
    with torch.no_grad():
        for p in learner.net.parameters():
            p.mul_(3.0)  # spread the Q values so that the rule deviates somewhere
    a_torch = learner.act(obs, mask, explore=False)
    sd = {k: v.numpy() for k, v in learner.net.state_dict().items()}
    a_fixed = SafeDQNQ(sd, {"rule": "mvp-improve", "slack": 0.02}).act(
        obs, mask, base=mvp_actions(obs, mask)
    )
    base = mvp_actions(obs, mask)
    assert 0 < (a_torch != base).sum() < len(base)  # the test exercises both branches
    assert (a_fixed == a_torch).mean() > 0.99  # float32 rounding of torch vs the fixed path
    assert (mask[np.arange(len(a_fixed)), a_fixed] == 1).all()


def _evaluating_learner(obs, base_steps=None):
    """An mvp-improve learner that never explores (gamma 0.9, zero margin)."""
    learner = SafeDQN(
        SafeDQNConfig(obs_dim=obs.shape[1], width=16, rule="mvp-improve", slack=0.0),
        gamma=0.9,
        epsilon=lambda step: 0.0,
        rng=np.random.default_rng(0),
        base_steps=base_steps,
    )
    learner.schedule(0, None)
    return learner


def _next_states(obs, mask):
    """A replay batch whose next states are ``obs`` (zero rewards, not done)."""
    zeros = torch.zeros(len(obs))
    return {
        "next_obs": torch.from_numpy(obs),
        "next_mask": torch.from_numpy(mask),
        "done": zeros,
        "safety_reward": zeros,
        "goal_reward": zeros,
    }


def test_the_networks_evaluate_mvp():
    obs, mask = _states(64)
    learner = _evaluating_learner(obs)
    # Behaviour without exploration is mvp itself, whatever the networks say.
    np.testing.assert_array_equal(learner.act(obs, mask, explore=True), mvp_actions(obs, mask))
    # Targets bootstrap with mvp's next action.
    b = _next_states(obs, mask)
    y_s, y_g = learner.targets(b)
    qs, qg = learner.target(b["next_obs"])
    a = torch.from_numpy(mvp_actions(obs, mask))
    idx = torch.arange(len(a))
    torch.testing.assert_close(y_s, 0.9 * qs[idx, a].detach())
    torch.testing.assert_close(y_g, 0.9 * qg[idx, a].detach())


def _agent(checkpoint, monkeypatch=None):
    spec = importlib.util.spec_from_file_location("mi", ROOT / "agents/mvp_improve/agent.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.Agent(None, None, checkpoint=str(checkpoint))


@pytest.fixture(scope="module")
def improve_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("improve") / "run"
    r = cdr_bench(
        "train", "safe-dqn-x", "--combine", "mvp-improve", "--run-dir", str(d),
        "--total-steps", "400", "--n-envs", "4", "--no-curriculum", "--scenario", "high",
        "--eval-episodes", "0", "--curve-every", "0", "--no-progress", "--width", "16",
        "--learning-starts", "64", "--batch-size", "16", "--buffer-size", "2000",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    return d


def test_agent_plays_the_checkpoint_and_a_huge_margin_is_mvp(improve_run, tmp_path):
    obs, mask = _states(200)
    agent = _agent(improve_run / "checkpoint.pt")
    a = agent.act_batch(obs, mask)
    assert (mask[np.arange(len(a)), a] == 1).all()
    (out,) = margin.with_slack(improve_run / "checkpoint.pt", tmp_path, [1e9])
    assert torch.load(out, weights_only=True)["config"]["slack"] == 1e9
    np.testing.assert_array_equal(_agent(out).act_batch(obs, mask), mvp_actions(obs, mask))


def test_agent_errors(improve_run, tmp_path):
    with pytest.raises(FileNotFoundError, match="no checkpoint at .*missing.pt: the shipped one"):
        _agent(tmp_path / "missing.pt")
    ck = torch.load(improve_run / "checkpoint.pt", weights_only=True)
    ck["config"]["rule"] = "sum"
    torch.save(ck, tmp_path / "sum.pt")
    with pytest.raises(ValueError, match="not trained with --combine mvp-improve"):
        _agent(tmp_path / "sum.pt")
    with pytest.raises(SystemExit, match="not trained with --combine mvp-improve"):
        margin.with_slack(tmp_path / "sum.pt", tmp_path, [0.1])


def test_margin_written_in_place_only_into_mvp_improve_checkpoints(improve_run, tmp_path, capsys):
    import shutil

    a, b = tmp_path / "a.pt", tmp_path / "b.pt"
    shutil.copy(improve_run / "checkpoint.pt", a)
    ck = torch.load(a, weights_only=True)
    ck["config"]["rule"] = "sum"
    torch.save(ck, b)
    before = a.read_bytes()
    with pytest.raises(SystemExit, match="b.pt: not trained with --combine mvp-improve"):
        margin.main(["--set", "0.3", str(a), str(b)])
    assert a.read_bytes() == before  # nothing written when one of them is wrong
    assert margin.main(["--set", "0.3", str(a)]) == 0
    new = torch.load(a, weights_only=True)
    assert new["config"]["slack"] == 0.3
    for k, v in torch.load(improve_run / "checkpoint.pt", weights_only=True)["state_dict"].items():
        assert torch.equal(v, new["state_dict"][k])
    with pytest.raises(SystemExit):
        margin.main([str(a)])  # neither --slack nor --set
    junk = tmp_path / "junk.pt"
    junk.write_text("not a checkpoint\n")
    with pytest.raises(SystemExit, match=r"junk\.pt: not a training checkpoint"):
        margin.main(["--set", "0.3", str(junk)])
    for bad in (["--set", "nan"], ["--set", "-0.1"], ["--slack", "0", "inf"]):
        with pytest.raises(SystemExit):
            margin.main([*bad, str(a)])
    assert torch.load(a, weights_only=True)["config"]["slack"] == 0.3  # nothing written


# --- further steps: policy iteration on mvp (--base-policy) ------------------------------------


def _spread_step(obs_dim, seed, slack):
    """An improvement step with random networks whose Q values are spread enough to deviate."""
    torch.manual_seed(seed)
    net = SafeDQN(SafeDQNConfig(obs_dim=obs_dim, width=32, rule="mvp-improve", slack=slack)).net
    with torch.no_grad():
        for p in net.parameters():
            p.mul_(3.0)
    return {
        "config": {"obs_dim": obs_dim, "width": 32, "rule": "mvp-improve", "slack": slack},
        "state_dict": {k: v.clone() for k, v in net.state_dict().items()},
    }


def test_a_step_loads_from_tensors_or_arrays_alike():
    obs, mask = _states(300)
    step = _spread_step(obs.shape[1], 1, 0.02)
    arrays = {**step, "state_dict": {k: v.numpy().copy() for k, v in step["state_dict"].items()}}
    base = mvp_actions(obs, mask)
    a = SafeDQNQ.from_step(step).act(obs, mask, base=base)
    np.testing.assert_array_equal(SafeDQNQ.from_step(arrays).act(obs, mask, base=base), a)
    assert (a != base).any()


def test_improved_actions_applies_the_steps_in_order():
    obs, mask = _states(300)
    s1, s2 = (SafeDQNQ.from_step(_spread_step(obs.shape[1], seed, 0.02)) for seed in (1, 2))
    base = mvp_actions(obs, mask)
    np.testing.assert_array_equal(improved_actions([], obs, mask, base), base)
    first = s1.act(obs, mask, base=base)
    second = s2.act(obs, mask, base=first)
    np.testing.assert_array_equal(improved_actions([s1, s2], obs, mask, base), second)
    assert (first != base).any() and (second != first).any()  # each step deviates somewhere
    # the order matters: s2 then s1 is another policy
    assert (improved_actions([s2, s1], obs, mask, base) != second).any()


def test_a_second_step_evaluates_the_first_step_not_mvp():
    obs, mask = _states(64)
    step1 = _spread_step(obs.shape[1], 1, 0.02)
    learner = _evaluating_learner(obs, base_steps=[step1])
    pi1 = SafeDQNQ.from_step(step1).act(obs, mask, base=mvp_actions(obs, mask))
    assert (pi1 != mvp_actions(obs, mask)).any()
    np.testing.assert_array_equal(learner.act(obs, mask, explore=True), pi1)  # behaviour
    b = _next_states(obs, mask)
    y_s, _ = learner.targets(b)
    qs, _ = learner.target(b["next_obs"])
    torch.testing.assert_close(y_s, 0.9 * qs[torch.arange(len(pi1)), torch.from_numpy(pi1)])
    assert learner.checkpoint_extra == {"base": [step1]}
    with pytest.raises(ValueError, match="need the mvp-improve rule"):
        SafeDQN(SafeDQNConfig(obs_dim=obs.shape[1], rule="sum"), base_steps=[step1])


def _train_step(run_dir, base=None):
    extra = ["--base-policy", str(base)] if base else []
    return cdr_bench(
        "train", "safe-dqn-x", "--combine", "mvp-improve", "--run-dir", str(run_dir),
        "--total-steps", "200", "--n-envs", "4", "--no-curriculum", "--scenario", "high",
        "--eval-episodes", "0", "--curve-every", "0", "--no-progress", "--width", "16",
        "--learning-starts", "64", "--batch-size", "16", "--buffer-size", "2000", *extra,
    )  # fmt: skip


def test_further_steps_from_the_cli(improve_run, tmp_path):
    """Step 2 trained on the step-1 run carries step 1's networks; a step 3 on it would evaluate
    both; the agent plays the steps in order (a huge margin on the last gives the step before)."""
    first = improve_run / "checkpoint.pt"
    assert _train_step(tmp_path / "two", first).returncode == 0
    ck1 = torch.load(first, weights_only=True)
    ck2 = torch.load(tmp_path / "two" / "checkpoint.pt", weights_only=True)
    assert "base" not in ck1 and len(ck2["base"]) == 1
    for k, v in ck1["state_dict"].items():
        assert torch.equal(ck2["base"][0]["state_dict"][k], v)
    obs_dim = ck1["config"]["obs_dim"]
    three = base_steps(str(tmp_path / "two" / "checkpoint.pt"), obs_dim)  # what step 3 evaluates
    assert [s["config"] for s in three] == [ck1["config"], ck2["config"]]
    obs, mask = _states(200)
    (two_mute,) = margin.with_slack(tmp_path / "two" / "checkpoint.pt", tmp_path / "m", [1e9])
    assert len(torch.load(two_mute, weights_only=True)["base"]) == 1  # the margin keeps the base
    np.testing.assert_array_equal(
        _agent(two_mute).act_batch(obs, mask), _agent(first).act_batch(obs, mask)
    )
    a2 = _agent(tmp_path / "two" / "checkpoint.pt").act_batch(obs, mask)
    assert (mask[np.arange(len(a2)), a2] == 1).all()


def test_base_policy_errors(improve_run, tmp_path):
    r = _train_step(tmp_path / "x", tmp_path / "missing.pt")  # through the CLI: one clear line
    assert r.returncode == 2 and "--base-policy" in r.stderr and "no such file" in r.stderr
    assert "Traceback" not in r.stderr
    obs_dim = torch.load(improve_run / "checkpoint.pt", weights_only=True)["config"]["obs_dim"]
    ck = torch.load(improve_run / "checkpoint.pt", weights_only=True)
    ck["config"]["rule"] = "sum"
    torch.save(ck, tmp_path / "sum.pt")
    with pytest.raises(UserError, match="sum.pt: not trained with --combine mvp-improve"):
        base_steps(str(tmp_path / "sum.pt"), obs_dim)
    (tmp_path / "junk.pt").write_text("not a checkpoint")
    with pytest.raises(UserError, match="junk.pt: not a cdr-bench checkpoint.pt"):
        base_steps(str(tmp_path / "junk.pt"), obs_dim)
    with pytest.raises(UserError, match=f"observations of {obs_dim} features, this .* 7"):
        base_steps(str(improve_run / "checkpoint.pt"), 7)
    broken = torch.load(improve_run / "checkpoint.pt", weights_only=True)
    broken["base"] = [{"config": dict(broken["config"]), "state_dict": {}}]
    torch.save(broken, tmp_path / "broken.pt")
    with pytest.raises(UserError, match="broken.pt, step 1 of 2: its networks do not load"):
        base_steps(str(tmp_path / "broken.pt"), obs_dim)
    broken["base"] = ["junk"]
    torch.save(broken, tmp_path / "broken.pt")
    with pytest.raises(UserError, match="step 1 of 2: not a step of a cdr-bench checkpoint"):
        base_steps(str(tmp_path / "broken.pt"), obs_dim)
    with pytest.raises(ValueError, match="needs --combine mvp-improve, got --combine sum"):
        SafeDQNArgs(base_policy=str(improve_run / "checkpoint.pt"))
