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
    for i in range(6):
        x = torch.randn(16, 6)
        flat.zero_grad()
        (net(x) ** 2).sum().backward()
        flat.collect_grad()
        opt_ref.zero_grad(set_to_none=True)
        (twin(x) ** 2).sum().backward()
        assert torch.equal(
            flat.flat.grad, torch.cat([q.grad.reshape(-1) for q in twin.parameters()])
        )
        max_norm = 0.5 if i % 2 else 1e6  # clipping, then not
        flat.clip_grad_norm(max_norm)
        torch.nn.utils.clip_grad_norm_(twin.parameters(), max_norm)
        ref = torch.cat([q.grad.reshape(-1) for q in twin.parameters()])
        assert torch.allclose(flat.flat.grad, ref, rtol=1e-6, atol=1e-8)
        flat.flat.grad.copy_(ref)  # continue from the same gradients
        opt_flat.step()
        opt_ref.step()
        for p, q in zip(net.parameters(), twin.parameters(), strict=True):
            assert torch.allclose(p, q, rtol=1e-6, atol=1e-7)
            assert p.data_ptr() != q.data_ptr()


def test_polyak_update_is_one_lerp_per_tensor():
    torch.manual_seed(5)
    a, b = TwinCritic(7, 16), TwinCritic(7, 16)
    pairs = list(zip(a.parameters(), b.parameters(), strict=True))
    lerp = [tp.detach().clone().lerp_(sp, 0.01) for tp, sp in pairs]
    mul_add = [tp.detach().clone().mul_(0.99).add_(sp, alpha=0.01) for tp, sp in pairs]
    polyak_update(a, b, 0.01)
    assert all(torch.equal(x, y) for x, y in zip(a.parameters(), lerp, strict=True))
    assert all(torch.allclose(x, y) for x, y in zip(a.parameters(), mul_add, strict=True))


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


# --- replay: the compiled sum tree and n-step queues against the implementations they replaced


class _NumpySumTree:
    """The level-by-level numpy sum tree (before issue 16)."""

    def __init__(self, capacity: int):
        self.n_leaves = 1 << max(0, int(capacity - 1).bit_length())
        self.tree = np.zeros(2 * self.n_leaves, np.float64)

    def update(self, idx, value) -> None:
        node = np.asarray(idx, np.int64) + self.n_leaves
        self.tree[node] = value
        node = np.unique(node // 2)
        while node.size and node[0] >= 1:
            self.tree[node] = self.tree[2 * node] + self.tree[2 * node + 1]
            node = np.unique(node // 2)
            node = node[node >= 1]

    def find(self, prefix):
        u = np.asarray(prefix, np.float64).copy()
        node = np.ones(len(u), np.int64)
        while node[0] < self.n_leaves:
            left = 2 * node
            go_right = u >= self.tree[left]
            u = np.where(go_right, u - self.tree[left], u)
            node = left + go_right
        return node - self.n_leaves


def test_sum_tree_equals_the_numpy_tree_bit_for_bit():
    from cdr_bench.rl.replay import SumTree

    rng = np.random.default_rng(7)
    for capacity in (1, 5, 1000):
        fast, ref = SumTree(capacity), _NumpySumTree(capacity)
        for _ in range(50):
            idx = rng.integers(0, capacity, rng.integers(1, 40))  # repeats included
            value = rng.random(len(idx)) ** 3
            fast.update(idx, value)
            ref.update(idx, value)
            assert np.array_equal(fast.tree, ref.tree)
            prefix = rng.random(64) * fast.total
            assert np.array_equal(fast.find(prefix), ref.find(prefix))


class _ListNStep:
    """The per-slot Python lists of n-step returns (before issue 16)."""

    REWARDS = ("reward", "goal_reward", "safety_reward")

    def __init__(self, n_slots: int, n: int, gamma: float):
        self.n, self.gamma = n, gamma
        self.pending: list[list[tuple]] = [[] for _ in range(n_slots)]

    def push(self, slots, tr, ended):
        rows: list[tuple] = []
        for i, s in enumerate(slots):
            q = self.pending[s]
            q.append(
                (tr["obs"][i], tr["mask"][i], tr["action"][i], *(tr[k][i] for k in self.REWARDS))
            )
            if len(q) == self.n:
                rows.append(self._emit(q, tr, i))
                q.pop(0)
            if ended[i]:
                while q:
                    rows.append(self._emit(q, tr, i))
                    q.pop(0)
        keys = ("obs", "mask", "action", *self.REWARDS, "next_obs", "next_mask", "done", "discount")
        if not rows:
            return {"action": np.zeros(0, np.int64)}
        return {k: np.asarray(c) for k, c in zip(keys, zip(*rows, strict=True), strict=True)}

    def _emit(self, q, tr, i):
        returns = [
            np.float32(sum(self.gamma**k * step[3 + j] for k, step in enumerate(q)))
            for j in range(len(self.REWARDS))
        ]
        nxt = (tr["next_obs"][i], tr["next_mask"][i], tr["done"][i])
        return (*q[0][:3], *returns, *nxt, np.float32(self.gamma ** len(q)))


@pytest.mark.parametrize("n", [1, 3, 5])
def test_n_step_queues_equal_the_lists_bit_for_bit(n):
    from cdr_bench.rl.replay import NStepAccumulator

    rng = np.random.default_rng(n)
    fast, ref = NStepAccumulator(6, n, 0.99), _ListNStep(6, n, 0.99)
    for step in range(60):
        slots = np.sort(rng.choice(6, rng.integers(1, 7), replace=False))
        k = len(slots)
        tr = {
            "obs": rng.standard_normal((k, 5), dtype=np.float32),
            "mask": rng.integers(0, 2, (k, 27)).astype(np.int8),
            "action": rng.integers(0, 27, k),
            "reward": rng.standard_normal(k).astype(np.float32),
            "goal_reward": rng.standard_normal(k).astype(np.float32),
            "safety_reward": -rng.random(k).astype(np.float32),
            "next_obs": rng.standard_normal((k, 5), dtype=np.float32),
            "next_mask": rng.integers(0, 2, (k, 27)).astype(np.int8),
            "done": (rng.random(k) < 0.1).astype(np.float32),
        }
        ended = rng.random(k) < 0.15
        a, b = fast.push(slots, tr, ended), ref.push(slots, tr, ended)
        assert a.keys() == b.keys() or len(b["action"]) == 0
        for key in b:
            assert a[key].dtype == b[key].dtype and np.array_equal(a[key], b[key]), key
        if step == 30:  # the state round trip, and a state of the lists loads
            for state in (fast.state_dict(), ref.pending):
                again = NStepAccumulator(6, n, 0.99)
                again.load_state_dict(copy.deepcopy(state))
                assert repr(again.pending) == repr(fast.pending)
            fast.load_state_dict(copy.deepcopy(ref.pending))


# --- Rainbow ----------------------------------------------------------------------------------


def test_rainbow_rows_of_taken_actions_equal_the_full_head():
    """log_probs_of (one action's atoms per sample, the noisy head in compiled loops) against
    the rows of log_probs (every action): values and gradients, noise on and off."""
    from cdr_bench.rl.rainbow import RainbowConfig, RainbowNet

    torch.manual_seed(8)
    net = RainbowNet(RainbowConfig(obs_dim=42, width=64, n_atoms=11))
    net.reset_noise()
    g = torch.Generator().manual_seed(9)
    obs = torch.randn(40, 42, generator=g)
    actions = torch.randint(0, 27, (40,), generator=g)
    up = torch.randn(40, 11, generator=g)
    for training in (True, False):
        net.train(training)
        params = [p for name, p in net.named_parameters() if training or "sigma" not in name]
        ref = net.log_probs(obs)[torch.arange(40), actions]
        got = net.log_probs_of(obs, actions)
        _close(got, ref)
        g_ref = torch.autograd.grad((ref * up).sum(), params)
        g_got = torch.autograd.grad((got * up).sum(), params)
        for x, y in zip(g_got, g_ref, strict=True):
            _close(x, y, 1e-5)


def test_rainbow_noise_and_q_values():
    """One draw for the whole network, split layer after layer (eps_in, eps_out), factorised
    as by each layer; and the expected Q is the mean of the support under the softmax of the
    aggregated logits."""
    from cdr_bench.rl.rainbow import NoisyLinear, RainbowConfig, RainbowNet

    torch.manual_seed(10)
    net = RainbowNet(RainbowConfig(obs_dim=5, width=16, n_atoms=7))
    layers = [m for m in net.modules() if isinstance(m, NoisyLinear)]
    net.reset_noise(torch.Generator().manual_seed(11))
    sizes = [n for m in layers for n in (m.in_features, m.out_features)]
    draws = torch.randn(sum(sizes), generator=torch.Generator().manual_seed(11)).split(sizes)
    for i, m in enumerate(layers):
        e_in, e_out = (NoisyLinear.scale_noise(d.clone()) for d in draws[2 * i : 2 * i + 2])
        assert torch.equal(m.input_epsilon, e_in) and torch.equal(m.bias_epsilon, e_out)
        assert torch.equal(m.weight_epsilon, torch.outer(e_out, e_in))
    obs = torch.randn(9, 5)
    for training in (True, False):
        net.train(training)
        with torch.no_grad():
            expect = (net.log_probs(obs).exp() * net.support).sum(-1)
            assert torch.allclose(net.q_values(obs), expect, atol=1e-5)
            assert torch.allclose(net.expected_q(obs), expect, atol=1e-5)


def _plain_projection(probs, reward, discount, support):
    """The C51 projection in tensor operations (before issue 16)."""
    v_min, v_max = float(support[0]), float(support[-1])
    dz = (v_max - v_min) / (len(support) - 1)
    tz = (reward[:, None] + discount[:, None] * support[None, :]).clamp(v_min, v_max)
    b = (tz - v_min) / dz
    lower, upper = b.floor().long(), b.ceil().long()
    out = torch.zeros_like(probs)
    out.scatter_add_(1, lower, probs * (upper.to(probs.dtype) - b))
    out.scatter_add_(1, upper, probs * (b - lower.to(probs.dtype)))
    out.scatter_add_(1, lower, probs * (lower == upper).to(probs.dtype))
    return out


def test_c51_projection_equals_the_tensor_version():
    from cdr_bench.rl.rainbow import project_distribution

    g = torch.Generator().manual_seed(12)
    support = torch.linspace(-20.0, 5.0, 51)
    probs = torch.softmax(3 * torch.randn(300, 51, generator=g), -1)
    reward = torch.cat([6 * torch.randn(290, generator=g), torch.tensor([-30.0, 30.0] * 5)])
    discount = torch.where(torch.rand(300, generator=g) < 0.2, 0.0, 0.97**3)
    discount[:5] = 1.0  # atoms landing exactly on atoms
    reward[:5] = 0.0
    got = project_distribution(probs, reward, discount, support)
    ref = _plain_projection(probs, reward, discount, support)
    assert torch.allclose(got, ref, atol=1e-6)
    assert torch.allclose(got.sum(-1), torch.ones(300), atol=1e-5)


def test_rainbow_update_is_deterministic():
    """Same seed, same batches: the same weights bit for bit after a few updates (and acting)."""
    from cdr_bench.rl.rainbow import Rainbow, RainbowConfig

    def run() -> list[torch.Tensor]:
        torch.manual_seed(13)
        learner = Rainbow(RainbowConfig(obs_dim=42, width=32, n_atoms=11))
        for i in range(3):
            b = _batch(seed=i)
            n = len(b["action"])
            b.update(discount=torch.full((n,), 0.97), weight=torch.rand(n))
            learner.update(b)
            learner.act(b["obs"].numpy(), b["mask"].numpy(), True)
        return [p.detach().clone() for p in learner.net.parameters()]

    a, b = run(), run()
    assert all(torch.equal(x, y) for x, y in zip(a, b, strict=True))


def test_fused_adam_step_equals_torch_adam():
    """The direct fused step of one flat tensor is torch's fused Adam step, bit for bit."""
    from cdr_bench.rl.networks import FusedAdam

    g = torch.Generator().manual_seed(14)
    a = torch.nn.Parameter(torch.randn(1000, generator=g))
    b = torch.nn.Parameter(a.detach().clone())
    fast = FusedAdam([a], lr=1e-3, eps=1.5e-4, fused=True)
    ref = torch.optim.Adam([b], lr=1e-3, eps=1.5e-4, fused=True)
    for _ in range(5):
        grad = torch.randn(1000, generator=g)
        a.grad, b.grad = grad.clone(), grad.clone()
        fast.step()
        ref.step()
        assert torch.equal(a, b)
    assert all(torch.equal(fast.state[a][k], ref.state[b][k]) for k in ref.state[b])
    fresh = FusedAdam([torch.nn.Parameter(torch.zeros(1000))], lr=1e-3, fused=True)
    fresh.load_state_dict(ref.state_dict())  # the state dicts are interchangeable
