"""IPPO and MAPPO (``cdr-bench train ippo`` / ``mappo``, :mod:`cdr_bench.rl.mappo`): the
centralised critic's inputs, and tiny runs on marl/high-all whose checkpoints the shipped
agents/ippo and agents/mappo load and fly with feasible actions only."""

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from cdr_bench.rl.mappo import critic_inputs  # noqa: E402
from cdr_bench.vector_env import VectorEnv  # noqa: E402

from .helpers import agent_module, cdr_bench, summary  # noqa: E402


def test_critic_inputs_pool_the_other_flying_aircraft():
    rng = np.random.default_rng(0)
    E, M, F = 5, 7, 4
    obs = rng.integers(-3, 4, (E, M, F)).astype(np.float32)  # small integers: many ties
    flying = rng.random((E, M)) < 0.6
    flying[0] = False  # an episode with nobody flying
    flying[1] = False
    flying[1, 2] = True  # one aircraft alone
    x = critic_inputs(obs, flying)
    assert x.shape == (E, M, 3 * F + 1) and x.dtype == np.float32
    for e in range(E):
        for m in range(M):
            others = [k for k in range(M) if k != m and flying[e, k]]
            np.testing.assert_array_equal(x[e, m, :F], obs[e, m])
            if others:
                np.testing.assert_allclose(x[e, m, F : 2 * F], obs[e, others].mean(0), rtol=1e-6)
                np.testing.assert_array_equal(x[e, m, 2 * F : 3 * F], obs[e, others].max(0))
            else:
                assert not x[e, m, F : 3 * F].any()
            assert x[e, m, -1] == pytest.approx(flying[e].sum() / M)
    # the pool does not depend on the order of the aircraft
    perm = rng.permutation(M)
    np.testing.assert_array_equal(critic_inputs(obs[:, perm], flying[:, perm]), x[:, perm])


@pytest.mark.slow
@pytest.mark.parametrize("name", ["ippo", "mappo"])
def test_tiny_run_and_shipped_agent(tmp_path, monkeypatch, name):
    d = tmp_path / name
    r = cdr_bench(
        "train", name, "--run-dir", str(d), "--scenario", "marl/high-all",
        "--total-steps", "3000", "--n-envs", "2", "--n-steps", "16", "--width", "16",
        "--log-every", "1000", "--hold-bias", "3",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    out = summary(r.stdout)
    assert out["algorithm"] == name and out["steps"] >= 3000 and out["updates"] >= 1
    args = json.loads((d / "args.json").read_text())
    assert args["algorithm"] == name and args["scenario"] == "marl/high-all"
    lines = [json.loads(x) for x in (d / "log.jsonl").read_text().splitlines()]
    assert "final" in lines[-1]
    assert all(np.isfinite(x["losses/value"]) for x in lines[:-1] if "losses/value" in x)
    assert any(x.get("charts/flights", 0) > 0 for x in lines[:-1])
    ck = torch.load(d / "checkpoint.pt", weights_only=True)
    assert ck["config"]["algorithm"] == name and ck["config"]["width"] == 16
    # the untrained actor's bias: hold is the most likely action
    assert int(ck["state_dict"]["4.bias"].argmax()) == 13

    # the shipped agent loads the checkpoint and flies every aircraft of marl/high-all
    monkeypatch.setenv("CDR_BENCH_CHECKPOINT", str(d / "checkpoint.pt"))
    agent = agent_module(name).Agent(None, None)
    env = VectorEnv("marl/high-all", 2)
    obs, masks = env.reset(seeds=[11, 12])
    assert masks.min() == 0  # some actions are masked in these episodes
    for _ in range(40):
        fl = env.flying
        if not fl.any():
            break
        a = np.full(fl.shape, 13, np.int64)
        a[fl] = agent.act_batch(obs[fl], masks[fl])
        assert (np.take_along_axis(masks, a[..., None], -1)[..., 0][fl] == 1).all()
        st = env.step(a)
        assert not st.result.invalid_action.any()
        obs, masks = st.obs, st.action_mask
    # the other trainer's checkpoint is refused
    other = agent_module("mappo" if name == "ippo" else "ippo")
    with pytest.raises(ValueError, match="not a"):
        other.Agent(None, None)


@pytest.mark.slow
def test_same_seed_same_weights(tmp_path):
    """A run is fixed by its seed (one torch thread): the recipe's seeds can be retrained."""
    flags = ["--total-steps", "2000", "--n-envs", "2", "--n-steps", "8", "--width", "16"]
    for d in ("a", "b"):
        r = cdr_bench("train", "mappo", "--run-dir", str(tmp_path / d), "--seed", "5", *flags)
        assert r.returncode == 0, r.stderr
    a, b = (torch.load(tmp_path / d / "checkpoint.pt", weights_only=True) for d in ("a", "b"))
    assert all(torch.equal(a["state_dict"][k], b["state_dict"][k]) for k in a["state_dict"])
