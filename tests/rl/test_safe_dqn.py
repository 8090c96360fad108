"""Safe-DQN-X: the combination rules by hand, masks in acting and in the targets, epsilon-greedy
exploration, and TD3's rounding map."""

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from cdr_bench.actions import TRIPLES, encode  # noqa: E402
from cdr_bench.rl.baselines import continuous_to_index  # noqa: E402
from cdr_bench.rl.safe_dqn import SafeDQN, SafeDQNConfig, combine  # noqa: E402


def _q(*rows):
    """Q values for the first len(row) actions, the others very low."""
    q = torch.full((len(rows), 27), -100.0)
    for i, r in enumerate(rows):
        q[i, : len(r)] = torch.tensor(r)
    return q


def test_sum_rule_by_hand():
    qs = _q([-1.0, -0.2, 0.0, -0.5])
    qg = _q([3.0, 2.0, 1.0, 5.0])
    mask = torch.ones(1, 27, dtype=torch.int8)
    # sums: 2.0, 1.8, 1.0, 4.5 -> action 3
    assert combine(qs, qg, mask, "sum").item() == 3
    mask[0, 3] = 0  # masked: next best sum is action 0
    assert combine(qs, qg, mask, "sum").item() == 0


def test_lexicographic_rule_by_hand():
    qs = _q([-1.0, -0.05, 0.0, -0.5])
    qg = _q([3.0, 2.0, 1.0, 5.0])
    mask = torch.ones(1, 27, dtype=torch.int8)
    # best safety 0.0 (action 2); slack 0.1 -> safe set {1, 2}; best goal in it: action 1
    assert combine(qs, qg, mask, "lexicographic", slack=0.1).item() == 1
    # slack 0.6 -> safe set {1, 2, 3}: action 3 (goal 5)
    assert combine(qs, qg, mask, "lexicographic", slack=0.6).item() == 3
    # slack 0: only the safest action
    assert combine(qs, qg, mask, "lexicographic", slack=0.0).item() == 2
    # the safest action is masked: the best feasible safety value defines the safe set
    mask[0, 2] = 0
    assert combine(qs, qg, mask, "lexicographic", slack=0.1).item() == 1
    with pytest.raises(ValueError, match="combination rule"):
        combine(qs, qg, mask, "max")


def test_trainer_rule_names_match_the_learner():
    from cdr_bench.rl import safe_dqn, train_safe_dqn

    assert train_safe_dqn.RULES == safe_dqn.RULES


@pytest.mark.parametrize("rule", ["sum", "lexicographic"])
def test_masks_in_acting_and_targets(rule):
    torch.manual_seed(0)
    learner = SafeDQN(SafeDQNConfig(obs_dim=3, width=16, rule=rule, slack=0.05), gamma=0.9)
    obs = torch.randn(128, 3)
    free = learner.net.act(obs, torch.ones(128, 27, dtype=torch.int8))
    mask = torch.ones(128, 27, dtype=torch.int8)
    mask[torch.arange(128), free] = 0
    a = learner.net.act(obs, mask)
    assert (mask[torch.arange(128), a] == 1).all()
    # Targets: both components bootstrap with the rule's feasible next action (online nets),
    # scored by the target nets.
    b = {
        "next_obs": obs,
        "next_mask": mask,
        "done": torch.zeros(128),
        "goal_reward": torch.full((128,), -0.1),
        "safety_reward": torch.full((128,), -0.5),
    }
    for p in learner.target.parameters():
        p.data += 0.3 * torch.randn_like(p)  # target differs from online
    y_s, y_g = learner.targets(b)
    qs_t, qg_t = learner.target(obs)
    assert torch.allclose(y_s, -0.5 + 0.9 * qs_t[torch.arange(128), a])
    assert torch.allclose(y_g, -0.1 + 0.9 * qg_t[torch.arange(128), a])
    b["done"] = torch.ones(128)
    y_s, y_g = learner.targets(b)
    assert torch.allclose(y_s, torch.full((128,), -0.5))


def test_epsilon_greedy_explores_feasible_actions_only():
    from cdr_bench.rl.train_safe_dqn import Args, build

    torch.manual_seed(0)
    args = Args(total_steps=1000, eps_start=1.0, eps_end=0.0, eps_fraction=0.5, width=16)
    learner = build(args, 3, np.random.default_rng(0))
    obs = np.random.default_rng(1).normal(size=(4000, 3)).astype(np.float32)
    mask = np.ones((4000, 27), np.int8)
    mask[:, 2::3] = 0  # no climb
    greedy = learner.act(obs, mask, explore=False)
    assert learner.schedule(0, None) == {"epsilon": 1.0}
    a = learner.act(obs, mask, explore=True)
    assert (mask[np.arange(4000), a] == 1).all() and len(np.unique(a)) == 18  # uniform, feasible
    assert learner.schedule(250, None) == {"epsilon": 0.5}
    assert 0.4 < np.mean(learner.act(obs, mask, explore=True) != greedy) < 0.6
    assert learner.schedule(600, 3) == {"epsilon": 0.0}  # annealed after half the budget
    assert (learner.act(obs, mask, explore=True) == greedy).all()


def test_td3_rounding_map_by_hand():
    a = np.array(
        [
            [0.0, 0.0, 0.0],  # hold
            [0.51, -0.51, 0.49],  # right, slower, level
            [-1.0, 1.0, 1.0],  # left, faster, climb
            [0.5, -0.5, -0.9],  # +-0.5 round to 0; descend
            [-0.7, 0.2, 0.8],
        ]
    )
    got = continuous_to_index(a)
    expected = [
        encode((0, 0, 0)),
        encode((1, -1, 0)),
        encode((-1, 1, 1)),
        encode((0, 0, -1)),
        encode((-1, 0, 1)),
    ]
    assert list(got) == expected == [13, 19, 8, 12, 5]
    # Every triple is reachable, and the map inverts TRIPLES exactly.
    assert list(continuous_to_index(TRIPLES.astype(float))) == list(range(27))
