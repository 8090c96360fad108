"""The trainers' fast paths compute what the plain formulations compute (issue 16: training
throughput): the denoiser's rearranged attention against ``nn.MultiheadAttention``, the compiled
attention's gradients, mish, the stacked twin critics, the flat parameters, Polyak averaging, and
that an update stays deterministic."""

import copy

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from cdr_bench.rl.diffusion_ac import DiffusionAC, PolicyConfig, UpdateConfig
from cdr_bench.rl.networks import (
    Denoiser,
    FlatParameters,
    Mish,
    TwinCritic,
    adam,
    mlp,
    polyak_update,
    sinusoidal_embedding,
)


@pytest.fixture(autouse=True)
def one_thread():
    """One torch thread, as the trainers (two threads on a busy 2-core machine are slower)."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def _plain_forward_h(net: Denoiser, h, yt, t):
    """The denoiser as first written: three tokens through ``nn.MultiheadAttention``, summed."""
    te = net.t_mlp(sinusoidal_embedding(t, net.width))
    ye = net.y_mlp(yt)
    tokens = torch.stack([h, te, ye], dim=1)
    x = net.attn_norm(tokens)
    tokens = tokens + net.attn(x, x, x, need_weights=False)[0]
    return net.head(net.blocks(tokens.sum(dim=1)))


def _random_denoiser(seed: int = 0, **kw) -> Denoiser:
    torch.manual_seed(seed)
    net = Denoiser(42, **kw)
    with torch.no_grad():  # non-trivial affines and biases
        for m in net.modules():
            if isinstance(m, torch.nn.LayerNorm):
                m.weight.uniform_(0.5, 1.5)
                m.bias.uniform_(-0.3, 0.3)
        net.attn.in_proj_bias.uniform_(-0.3, 0.3)
        net.attn.out_proj.bias.uniform_(-0.3, 0.3)
    return net


def _close(a: torch.Tensor, b: torch.Tensor, rtol: float = 1e-5) -> None:
    assert a.shape == b.shape
    assert (a - b).abs().max() <= rtol * b.abs().max() + 1e-6, (a - b).abs().max()


@pytest.mark.parametrize("kw", [{}, {"width": 64, "n_heads": 4, "n_blocks": 1}])
def test_denoiser_equals_multihead_attention_values_and_gradients(kw):
    net = _random_denoiser(**kw)
    g = torch.Generator().manual_seed(1)
    obs = torch.randn(50, 42, generator=g)
    y = 3 * torch.randn(50, 27, generator=g)
    t = torch.randint(0, 11, (50,), generator=g)
    params = list(net.parameters())

    ref = _plain_forward_h(net, net.encode(obs), y, t)
    got = net.forward_h(net.encode(obs), y, t)
    _close(got, ref)
    g_ref = torch.autograd.grad((ref * ref).sum(), params)
    g_got = torch.autograd.grad((got * got).sum(), params)
    for a, b in zip(g_got, g_ref, strict=True):
        _close(a, b, 1e-4)

    # one conditioning shared by two passes of 2N rows (the actor loss), and an int step
    c = net.condition(net.encode(obs), 10)
    y2 = torch.cat([y, -y])
    t2 = torch.cat([t, torch.zeros_like(t)])
    both = net.denoise(c, y2, t2)
    _close(both[:50], ref)
    _close(both[50:], _plain_forward_h(net, net.encode(obs), -y, torch.zeros_like(t)))
    with torch.no_grad():
        _close(net.denoise(c, y, 7), _plain_forward_h(net, c.h, y, torch.full((50,), 7)))


def test_compiled_attention_gradient_against_autograd():
    """The hand-written backward pass of the three-token attention against autograd through
    the same function written in tensor operations, with shared rows (idx0, idx1 repeat)."""
    from cdr_bench.rl.networks import ThreeTokenAttention

    g = torch.Generator().manual_seed(2)
    heads, w, n = 4, 32, 20
    q0 = torch.randn(5, 3 * w, generator=g, requires_grad=True)
    q1 = torch.randn(3, 3 * w, generator=g, requires_grad=True)
    q2 = torch.randn(n, 3 * w, generator=g, requires_grad=True)
    i0 = np.arange(n, dtype=np.int64) % 5
    i1 = np.random.default_rng(0).integers(0, 3, n)

    def plain(a, b, c):
        x = torch.stack([a[i0], b[i1], c], 1).view(n, 3, 3, heads, w // heads)
        q, k, v = x.unbind(2)
        s = (q.unsqueeze(2) * k.unsqueeze(1)).sum(-1) / (w // heads) ** 0.5
        att = torch.softmax(s, dim=2)
        return (att.sum(1).unsqueeze(-1) * v).sum(1).reshape(n, w)

    up = torch.randn(n, w, generator=g)
    ref = plain(q0, q1, q2)
    got = ThreeTokenAttention.apply(q0, i0, q1, i1, q2, heads)
    _close(got, ref)
    for a, b in zip(
        torch.autograd.grad((got * up).sum(), (q0, q1, q2)),
        torch.autograd.grad((ref * up).sum(), (q0, q1, q2)),
        strict=True,
    ):
        _close(a, b, 1e-5)


def test_mish_equals_torch_mish():
    x = torch.cat([torch.linspace(-30, 30, 601), torch.tensor([-200.0, -90.0, 19.9, 20.0, 88.0])])
    x.requires_grad_(True)
    up = torch.randn(len(x), generator=torch.Generator().manual_seed(0))
    ref, got = F.mish(x), Mish()(x)
    assert torch.allclose(got, ref, rtol=1e-6, atol=1e-6)
    assert torch.allclose(
        torch.autograd.grad((got * up).sum(), x)[0],
        torch.autograd.grad((ref * up).sum(), x)[0],
        rtol=1e-5,
        atol=1e-6,
    )
    with torch.no_grad():
        assert torch.allclose(Mish()(x), ref, rtol=1e-6, atol=1e-6)
    assert torch.isfinite(got).all()


@pytest.mark.parametrize("twin", [True, False])
def test_stacked_twin_critics_equal_two_mlps(twin):
    """Same seed, same initial weights as the two separate three-layer MLPs, the same Q values,
    and a state dict of the separate critics loads."""
    torch.manual_seed(3)
    q1 = mlp(42, 128, 27)
    q2 = mlp(42, 128, 27) if twin else q1
    torch.manual_seed(3)
    critic = TwinCritic(42, 128, twin=twin)
    obs = torch.randn(64, 42)
    a, b = critic(obs)
    _close(a, q1(obs))
    _close(b, q2(obs))
    assert torch.equal(critic.min_q(obs), torch.minimum(a, b))
    old = {f"q1.{k}": v for k, v in q1.state_dict().items()}
    if twin:
        old.update({f"q2.{k}": v for k, v in q2.state_dict().items()})
    fresh = TwinCritic(42, 128, twin=twin)
    fresh.load_state_dict(old)
    assert all(torch.equal(x, y) for x, y in zip(fresh(obs), (a, b), strict=True))


def test_flat_parameters_adam_and_clipping_match_per_tensor():
    torch.manual_seed(4)
    net = torch.nn.Sequential(torch.nn.Linear(6, 8), torch.nn.ReLU(), torch.nn.Linear(8, 3))
    twin = copy.deepcopy(net)
    flat = FlatParameters(net)
    opt_flat = adam([flat.flat], lr=1e-2)
    opt_ref = adam(twin.parameters(), lr=1e-2)
    for i in range(5):
        x = torch.randn(16, 6)
        flat.zero_grad()
        (net(x) ** 2).sum().backward()
        opt_ref.zero_grad(set_to_none=True)
        (twin(x) ** 2).sum().backward()
        for p, q in zip(net.parameters(), twin.parameters(), strict=True):
            assert torch.equal(p.grad, q.grad)
        flat.clip_grad_norm(0.5 if i % 2 else 1e6)
        torch.nn.utils.clip_grad_norm_(twin.parameters(), 0.5 if i % 2 else 1e6)
        for p, q in zip(net.parameters(), twin.parameters(), strict=True):
            assert torch.allclose(p.grad, q.grad, rtol=1e-6, atol=1e-8)
            p.grad.copy_(q.grad)  # continue from the same gradients
        opt_flat.step()
        opt_ref.step()
        for p, q in zip(net.parameters(), twin.parameters(), strict=True):
            assert torch.allclose(p, q, rtol=1e-6, atol=1e-7)


def test_polyak_update_is_the_per_tensor_arithmetic():
    torch.manual_seed(5)
    a, b = TwinCritic(7, 16), TwinCritic(7, 16)
    expect = [tp.detach().clone().mul_(0.99).add_(sp, alpha=0.01) for tp, sp in
              zip(a.parameters(), b.parameters(), strict=True)]  # fmt: skip
    polyak_update(a, b, 0.01)
    assert all(torch.equal(x, y) for x, y in zip(a.parameters(), expect, strict=True))


def _batch(n: int = 64, seed: int = 0) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    mask = (torch.rand(n, 27, generator=g) > 0.3).to(torch.int8)
    mask[:, 13] = 1
    return {
        "obs": torch.randn(n, 42, generator=g),
        "mask": mask,
        "action": torch.randint(0, 27, (n,), generator=g),
        "reward": torch.randn(n, generator=g),
        "next_obs": torch.randn(n, 42, generator=g),
        "next_mask": mask.flip(0),
        "done": (torch.rand(n, generator=g) < 0.1).float(),
    }


@pytest.mark.parametrize("ce_input", ["y0", "noise", "none"])
def test_diffusion_ac_update_is_deterministic(ce_input):
    """Same seed, same batches: the same weights bit for bit after a few updates (and acting)."""

    def run() -> list[torch.Tensor]:
        torch.manual_seed(6)
        ac = DiffusionAC(PolicyConfig(width=32, critic_width=32), UpdateConfig(ce_input=ce_input))
        for i in range(3):
            ac.update(_batch(seed=i))
            ac.act(_batch(seed=i)["obs"].numpy(), _batch(seed=i)["mask"].numpy(), True)
        return [p.detach().clone() for p in (*ac.policy.parameters(), *ac.critic.parameters())]

    a, b = run(), run()
    assert all(torch.equal(x, y) for x, y in zip(a, b, strict=True))
