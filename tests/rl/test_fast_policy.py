"""The numpy inference path computes what the PyTorch policy computes, on the same noise."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from cdr_bench.rl.diffusion_ac import Policy, PolicyConfig, load_policy  # noqa: E402
from cdr_bench.rl.fast_policy import FastDiffusionPolicy  # noqa: E402

CHECKPOINT = Path(__file__).resolve().parents[2] / "agents" / "diffusion_ac" / "checkpoint.pt"


def _random_policy(**kw) -> Policy:
    torch.manual_seed(0)
    pol = Policy(PolicyConfig(**kw))
    with torch.no_grad():  # non-trivial LayerNorm affines, so folding them is exercised
        for m in pol.modules():
            if isinstance(m, torch.nn.LayerNorm):
                m.weight.uniform_(0.5, 1.5)
                m.bias.uniform_(-0.3, 0.3)
    return pol.eval()


@pytest.mark.parametrize(
    "kw",
    [{}, {"schedule": "linear"}, {"T": 3, "width": 64, "n_blocks": 1}, {"T": 20, "n_heads": 4}],
)
def test_clean_logits_match_torch(kw):
    pol = _random_policy(**kw)
    fast = FastDiffusionPolicy(pol)
    obs = np.random.default_rng(1).normal(size=(33, pol.cfg.obs_dim)).astype(np.float32)
    ref = pol.clean_logits(torch.as_tensor(obs), torch.Generator().manual_seed(7)).numpy()
    got = fast.clean_logits(obs, torch.Generator().manual_seed(7))
    assert got.shape == (33, 27) and got.dtype == np.float32
    np.testing.assert_allclose(got, ref, rtol=1e-4, atol=1e-4 * np.abs(ref).max())


def test_different_noise_gives_different_logits():
    """Guard against a path that ignores the generator (the diffusion actor is stochastic)."""
    fast = FastDiffusionPolicy(_random_policy())
    obs = np.zeros((4, 42), np.float32)
    a = fast.clean_logits(obs, torch.Generator().manual_seed(1))
    b = fast.clean_logits(obs, torch.Generator().manual_seed(2))
    assert np.abs(a - b).max() > 1e-3


def test_masked_classes_are_never_chosen():
    fast = FastDiffusionPolicy(_random_policy())
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(200, 42)).astype(np.float32)
    mask = (rng.random((200, 27)) < 0.3).astype(np.int8)
    mask[np.arange(200), rng.integers(0, 27, 200)] = 1
    a = fast.act(obs, mask, torch.Generator().manual_seed(0))
    assert mask[np.arange(200), a].all()


def test_categorical_actor_is_refused():
    with pytest.raises(ValueError, match="diffusion"):
        FastDiffusionPolicy(_random_policy(actor="categorical"))


@pytest.mark.skipif(not CHECKPOINT.exists(), reason="shipped checkpoint absent")
def test_shipped_checkpoint_same_actions_on_simulator_states():
    from cdr_bench.scenarios import load_scenario
    from cdr_bench.sim import Simulator, observe

    pol = load_policy(str(CHECKPOINT))
    fast = FastDiffusionPolicy(pol)
    sim = Simulator(load_scenario("high"), n_episodes=256)
    sim.reset(np.arange(256))
    for _ in range(3):
        sim.step(np.full((256, sim.M), 13))
    obs, mask = observe(sim)[:, 0].astype(np.float32), sim.action_masks()[:, 0]
    ref = pol.act(torch.as_tensor(obs), torch.as_tensor(mask), torch.Generator().manual_seed(4))
    got = fast.act(obs, mask, torch.Generator().manual_seed(4))
    assert (got == ref.numpy()).all()
