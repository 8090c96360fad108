"""Rainbow-DQN: one test per component (by hand where a hand value exists) and the masks."""

import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from cdr_bench.rl.rainbow import (  # noqa: E402
    NoisyLinear,
    Rainbow,
    RainbowConfig,
    RainbowNet,
    dueling_aggregate,
    masked_argmax,
    project_distribution,
)
from cdr_bench.rl.replay import (  # noqa: E402
    NStepAccumulator,
    PrioritizedReplayBuffer,
    SumTree,
)


def test_c51_projection_by_hand():
    support = torch.tensor([0.0, 1.0, 2.0, 3.0, 4.0])
    probs = torch.tensor([[0.1, 0.2, 0.3, 0.4, 0.0], [0.0, 0.0, 1.0, 0.0, 0.0]])
    # Row 0: r = 0.5, discount 0.5 -> atoms land at 0.5, 1.0, 1.5, 2.0, 2.5.
    # Row 1: r = 10 (clipped to v_max = 4): all the mass on the top atom.
    out = project_distribution(probs, torch.tensor([0.5, 10.0]), torch.tensor([0.5, 0.9]), support)
    # 0.5 splits 0.1 into 0.05 / 0.05 on atoms 0 / 1; 1.0 puts 0.2 on atom 1; 1.5 splits 0.3 into
    # 0.15 / 0.15 on atoms 1 / 2; 2.0 puts 0.4 on atom 2; 2.5 carries no mass.
    expected0 = [0.05, 0.05 + 0.2 + 0.15, 0.15 + 0.4, 0.0, 0.0]
    assert torch.allclose(out[0], torch.tensor(expected0))
    assert torch.allclose(out[1], torch.tensor([0.0, 0.0, 0.0, 0.0, 1.0]))
    # Terminal (discount 0): a point mass at r, split between its two neighbours.
    t = project_distribution(probs[:1], torch.tensor([2.25]), torch.tensor([0.0]), support)
    assert torch.allclose(t[0], torch.tensor([0.0, 0.0, 0.75, 0.25, 0.0]))


def test_dueling_aggregation():
    v = torch.tensor([[[1.0, 2.0]]])  # (1, 1, K = 2)
    a = torch.tensor([[[0.0, 3.0], [2.0, 1.0], [4.0, 2.0]]])  # (1, A = 3, K = 2); means 2, 2
    out = dueling_aggregate(v, a)
    assert torch.allclose(out, torch.tensor([[[-1.0, 3.0], [1.0, 1.0], [3.0, 2.0]]]))
    # Identifiability: a constant added to every advantage leaves the logits unchanged.
    assert torch.allclose(dueling_aggregate(v, a + 7.0), out)


def test_noisy_layer_factorised_noise_and_eval_mode():
    torch.manual_seed(0)
    layer = NoisyLinear(4, 3, sigma0=0.5)
    bound = 1 / math.sqrt(4)
    assert layer.weight_mu.abs().max() <= bound and layer.bias_mu.abs().max() <= bound
    assert torch.allclose(layer.weight_sigma, torch.full((3, 4), 0.5 * bound))
    g = torch.Generator().manual_seed(5)
    layer.reset_noise(g)
    g2 = torch.Generator().manual_seed(5)
    e_in, e_out = torch.randn(4, generator=g2), torch.randn(3, generator=g2)
    f_in, f_out = e_in.sign() * e_in.abs().sqrt(), e_out.sign() * e_out.abs().sqrt()
    assert torch.allclose(layer.weight_epsilon, torch.outer(f_out, f_in))
    assert torch.allclose(layer.bias_epsilon, f_out)
    x = torch.randn(2, 4)
    w = layer.weight_mu + layer.weight_sigma * layer.weight_epsilon
    b = layer.bias_mu + layer.bias_sigma * layer.bias_epsilon
    assert torch.allclose(layer(x), x @ w.T + b)
    y1 = layer(x)
    layer.reset_noise()
    assert not torch.allclose(layer(x), y1)  # a new noise sample changes the output
    layer.eval()
    assert torch.allclose(layer(x), x @ layer.weight_mu.T + layer.bias_mu)
    # Noise is not saved in the checkpoint.
    assert set(layer.state_dict()) == {"weight_mu", "bias_mu", "weight_sigma", "bias_sigma"}


def test_n_step_return_by_hand():
    g = 0.9
    acc = NStepAccumulator(n_slots=2, n=3, gamma=g)
    o = np.arange(6, dtype=np.float32)[:, None]  # obs of steps 0..5
    m = np.ones((1, 27), np.int8)
    out = []
    rewards = [1.0, 2.0, 3.0, 4.0]
    done = [0, 0, 0, 1]
    for t, r in enumerate(rewards):
        tr = {
            "obs": o[t : t + 1], "mask": m, "action": np.array([t]),
            "reward": np.array([r], np.float32), "goal_reward": np.array([r], np.float32),
            "safety_reward": np.zeros(1, np.float32), "next_obs": o[t + 1 : t + 2],
            "next_mask": m, "done": np.array([done[t]], np.float32),
        }  # fmt: skip
        out.append(acc.push(np.array([1]), tr, np.array([bool(done[t])])))
    assert [len(x["action"]) for x in out] == [0, 0, 1, 3]
    assert acc.pending == [[], []]  # slot 1 flushed at the end of its flight, slot 0 unused
    first = out[2]
    assert first["action"][0] == 0 and first["next_obs"][0, 0] == 3
    assert np.isclose(first["reward"][0], 1 + g * 2 + g * g * 3)
    assert first["goal_reward"][0] == first["reward"][0] and first["safety_reward"][0] == 0
    assert np.isclose(first["discount"][0], g**3) and first["done"][0] == 0
    last = out[3]  # the episode terminated: the three pending transitions are flushed
    assert list(last["action"]) == [1, 2, 3]
    assert np.allclose(last["reward"], [2 + g * 3 + g * g * 4, 3 + g * 4, 4])
    assert np.allclose(last["discount"], [g**3, g**2, g])
    assert (last["done"] == 1).all() and (last["next_obs"][:, 0] == 4).all()


def test_n_step_slots_are_independent():
    """Two aircraft in one step: each slot keeps its own queue; rows come out in slot order."""
    acc = NStepAccumulator(n_slots=3, n=2, gamma=0.5)
    m = np.ones((2, 27), np.int8)

    def step(t, ended):
        tr = {
            "obs": np.array([[t], [10 + t]], np.float32), "mask": m,
            "action": np.array([t, 10 + t]),
            "reward": np.array([1.0, 2.0], np.float32), "goal_reward": np.zeros(2, np.float32),
            "safety_reward": np.zeros(2, np.float32), "next_obs": np.array([[t + 1], [11 + t]]),
            "next_mask": m, "done": np.zeros(2, np.float32),
        }  # fmt: skip
        return acc.push(np.array([0, 2]), tr, np.array(ended))

    assert len(step(0, [False, False])["action"]) == 0
    out = step(1, [False, True])
    assert list(out["action"]) == [0, 10, 11]  # slot 0 (n = 2 reached), then slot 2 flushed
    assert np.allclose(out["reward"], [1.5, 3.0, 2.0])
    assert len(acc.pending[0]) == 1 and acc.pending[2] == []


def test_sum_tree_and_prioritised_sampling_weights():
    tree = SumTree(5)
    tree.update(np.arange(5), np.array([1.0, 2.0, 3.0, 4.0, 0.0]))
    assert tree.total == 10
    assert list(tree.find(np.array([0.0, 0.99, 1.0, 2.9, 3.0, 5.99, 6.0, 9.99]))) == [
        0, 0, 1, 1, 2, 2, 3, 3,
    ]  # fmt: skip

    buf = PrioritizedReplayBuffer(8, obs_dim=1, alpha=1.0)
    z = np.zeros((4, 1), np.float32)
    k = np.ones((4, 27), np.int8)
    tr = {"obs": z, "mask": k, "action": np.arange(4), "next_obs": z, "next_mask": k}
    buf.add({**tr, "discount": np.full(4, 0.9)})
    buf.update_priorities(np.arange(4), np.array([1.0, 1.0, 2.0, 4.0]))
    rng = np.random.default_rng(0)
    idx = np.concatenate([buf.sample(64, rng)["index"] for _ in range(200)])
    freq = np.bincount(idx, minlength=4) / len(idx)
    assert np.allclose(freq, [0.125, 0.125, 0.25, 0.5], atol=0.01)
    b = buf.sample(64, rng, beta=0.5)
    # w_i = (N P(i))^-beta / max w with P = (1, 1, 2, 4) / 8 and N = 4:
    # (N P)^-0.5 = (sqrt 2, sqrt 2, 1, 1 / sqrt 2); stratified sampling draws every index here,
    # so the batch maximum is sqrt 2.
    assert set(b["index"].tolist()) == {0, 1, 2, 3}
    expected = {0: 1.0, 1: 1.0, 2: 1 / math.sqrt(2), 3: 0.5}
    for i, w in zip(b["index"], b["weight"], strict=True):
        assert np.isclose(w, expected[int(i)], rtol=1e-5)
    assert np.allclose(b["discount"], 0.9)
    # A new transition gets the largest priority so far (alpha = 1: 4 / total 12).
    buf.add({k_: v[:1] for k_, v in tr.items()})
    assert buf.tree.tree[buf.tree.n_leaves + 4] == 4.0


def test_masked_acting_never_picks_a_masked_action():
    torch.manual_seed(0)
    net = RainbowNet(RainbowConfig(obs_dim=3, width=16, n_atoms=11))
    obs = torch.randn(256, 3)
    q = net.q_values(obs)
    best = q.argmax(1)
    mask = torch.ones(256, 27, dtype=torch.int8)
    mask[torch.arange(256), best] = 0  # forbid every row's unmasked favourite
    mask[:128, 2::3] = 0  # and every climb in half the rows
    a = masked_argmax(q, mask)
    assert (mask[torch.arange(256), a] == 1).all() and (a != best).all()
    net.reset_noise()  # acting while training: noisy weights, same masked rule
    assert (mask[torch.arange(256), net.act(obs, mask)] == 1).all()
    net.eval()
    assert torch.equal(net.act(obs, mask), masked_argmax(net.q_values(obs), mask))


def test_double_q_target_uses_online_argmax_over_next_mask():
    torch.manual_seed(0)
    cfg = RainbowConfig(obs_dim=2, width=8, n_atoms=5, v_min=0.0, v_max=4.0)
    learner = Rainbow(cfg)
    learner.net.eval()
    learner.target.eval()
    obs = torch.randn(4, 2)
    q_online = learner.net.q_values(obs)
    mask = torch.ones(4, 27, dtype=torch.int8)
    mask[torch.arange(4), q_online.argmax(1)] = 0  # the online favourite is infeasible
    a_star = masked_argmax(q_online, mask)
    p_target = learner.target.log_probs(obs).exp()[torch.arange(4), a_star]
    r, disc = torch.tensor([0.5, 1.0, 0.0, 2.0]), torch.tensor([0.9, 0.0, 0.5, 0.99])
    expected = project_distribution(p_target, r, disc, learner.net.support)
    got = learner.target_distribution(obs, mask, r, disc)
    assert torch.allclose(got, expected)
    # Double Q: the target network's own argmax is not what chooses the action.
    learner.target.advantage[-1].bias_mu.data += torch.randn(27 * 5) * 5
    p_target2 = learner.target.log_probs(obs).exp()[torch.arange(4), a_star]
    got2 = learner.target_distribution(obs, mask, r, disc)
    assert torch.allclose(got2, project_distribution(p_target2, r, disc, learner.net.support))


def test_update_decreases_loss_on_a_fixed_batch():
    torch.manual_seed(0)
    cfg = RainbowConfig(obs_dim=3, width=32, n_atoms=11, v_min=-2, v_max=2)
    learner = Rainbow(cfg, lr=1e-3, polyak=0.0)
    n = 64
    b = {
        "obs": torch.randn(n, 3),
        "mask": torch.ones(n, 27, dtype=torch.int8),
        "action": torch.randint(0, 27, (n,)),
        "reward": torch.randn(n).clamp(-1, 1),
        "next_obs": torch.randn(n, 3),
        "next_mask": torch.ones(n, 27, dtype=torch.int8),
        "done": torch.ones(n),  # terminal: a fixed target
        "discount": torch.full((n,), 0.97),
        "weight": torch.ones(n),
    }
    first = learner.update(b)["loss_ce"]
    for _ in range(100):
        last = learner.update(b)["loss_ce"]
    assert last < first - 0.1
    assert learner.priorities.shape == (n,) and (learner.priorities > 0).all()
