import math

import numpy as np
import torch

from cdr_bench.rl.diffusion_ac import DiffusionAC, PolicyConfig, UpdateConfig, teacher_distribution
from cdr_bench.rl.networks import TwinCritic, polyak_update
from cdr_bench.rl.replay import ReplayBuffer


def test_teacher_infinite_tau_is_uniform_over_feasible():
    q = torch.randn(5, 27)
    mask = torch.ones(5, 27, dtype=torch.int8)
    mask[:, :9] = 0
    p = teacher_distribution(q, mask, math.inf)
    assert torch.allclose(p[:, 9:], torch.full((5, 18), 1 / 18))
    assert torch.all(p[:, :9] == 0)


def test_teacher_small_tau_is_argmax_and_relative_is_scale_free():
    q = torch.randn(5, 27)
    mask = torch.ones(5, 27, dtype=torch.int8)
    p = teacher_distribution(q, mask, 1e-4)
    assert torch.equal(p.argmax(-1), q.argmax(-1))
    assert torch.allclose(p.max(-1).values, torch.ones(5))
    a = teacher_distribution(q, mask, 0.5, relative=True)
    b = teacher_distribution(100 * q - 7, mask, 0.5, relative=True)
    assert torch.allclose(a, b, atol=1e-5)


def test_masked_double_q_target_by_hand():
    """Eq. 34-35 on a hand-made batch: y = r + gamma (1 - d) max_{feasible a'} min(Q1', Q2')."""
    torch.manual_seed(0)
    agent = DiffusionAC(PolicyConfig(obs_dim=4), UpdateConfig(gamma=0.5))
    q1 = torch.zeros(2, 27)
    q2 = torch.zeros(2, 27)
    q1[0, 3], q2[0, 3] = 5.0, 1.0  # min 1
    q1[0, 7], q2[0, 7] = 2.0, 3.0  # min 2: the best feasible class of row 0
    q1[0, 20], q2[0, 20] = 9.0, 9.0  # masked in row 0, must be ignored

    agent.critic_target.min_q = lambda obs: torch.minimum(q1, q2)
    mask = torch.ones(2, 27, dtype=torch.int8)
    mask[0, 20] = 0
    b = {
        "obs": torch.randn(2, 4),
        "mask": mask,
        "action": torch.tensor([0, 1]),
        "reward": torch.tensor([1.0, 2.0]),
        "next_obs": torch.zeros(2, 4),
        "next_mask": mask,
        "done": torch.tensor([0.0, 1.0]),
    }
    y = torch.tensor([1.0 + 0.5 * 2.0, 2.0])
    with torch.no_grad():
        c1, c2 = agent.critic(b["obs"])
    expect = ((c1[[0, 1], [0, 1]] - y) ** 2).mean() + ((c2[[0, 1], [0, 1]] - y) ** 2).mean()
    agent.tau = 1.0
    stats = agent.update(b)
    assert abs(stats["loss_q"] - expect.item()) < 1e-5


def test_polyak_update():
    a, b = TwinCritic(3), TwinCritic(3)
    pa = [p.clone() for p in a.parameters()]
    polyak_update(a, b, 0.25)
    for p0, p1, pb in zip(pa, a.parameters(), b.parameters(), strict=True):
        assert torch.allclose(p1, 0.75 * p0 + 0.25 * pb)


def test_replay_wraparound():
    rb = ReplayBuffer(5, obs_dim=2)
    for i in range(3):
        n = 3
        rb.add(
            {
                "obs": np.full((n, 2), i, np.float32),
                "mask": np.ones((n, 27), np.int8),
                "action": np.arange(n) + 10 * i,
                "next_obs": np.zeros((n, 2)),
                "next_mask": np.ones((n, 27), np.int8),
            }
        )
    assert len(rb) == 5 and rb.pos == 4
    # 9 transitions into 5 slots: the last five (actions 11, 12, 20, 21, 22) survive
    assert rb.data["action"].tolist() == [12, 20, 21, 22, 11]
    s = rb.sample(100, np.random.default_rng(0))
    assert set(s["action"].tolist()) <= {11, 12, 20, 21, 22}
    assert (s["reward"] == 0).all()  # a column not given is stored as 0
    # The state round trip keeps the filled part and the write position.
    copy = ReplayBuffer(5, obs_dim=2)
    copy.load_state_dict(rb.state_dict())
    assert len(copy) == 5 and copy.pos == 4
    assert all(np.array_equal(copy.data[k], rb.data[k]) for k in rb.data)
