"""Uniform replay buffer of (s, mask, a, r, s', mask', done) in preallocated numpy arrays."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


class ReplayBuffer:
    """Ring buffer; ``add`` takes a batch of transitions, ``sample`` draws uniformly."""

    def __init__(self, capacity: int, obs_dim: int, n_actions: int = 27):
        self.capacity = int(capacity)
        self.obs = np.zeros((self.capacity, obs_dim), np.float32)
        self.next_obs = np.zeros((self.capacity, obs_dim), np.float32)
        self.mask = np.zeros((self.capacity, n_actions), np.int8)
        self.next_mask = np.zeros((self.capacity, n_actions), np.int8)
        self.action = np.zeros(self.capacity, np.int64)
        self.reward = np.zeros(self.capacity, np.float32)
        self.done = np.zeros(self.capacity, np.float32)
        self.pos = 0
        self.size = 0

    def __len__(self) -> int:
        return self.size

    def add(self, obs, mask, action, reward, next_obs, next_mask, done) -> None:
        """Append n transitions (arrays with leading dimension n), overwriting the oldest."""
        n = len(action)
        idx = (self.pos + np.arange(n)) % self.capacity
        self.obs[idx], self.mask[idx], self.action[idx] = obs, mask, action
        self.reward[idx], self.next_obs[idx] = reward, next_obs
        self.next_mask[idx], self.done[idx] = next_mask, done
        self.pos = int((self.pos + n) % self.capacity)
        self.size = min(self.size + n, self.capacity)

    def sample(self, batch: int, rng: np.random.Generator) -> dict[str, NDArray]:
        idx = rng.integers(0, self.size, batch)
        return {
            "obs": self.obs[idx],
            "mask": self.mask[idx],
            "action": self.action[idx],
            "reward": self.reward[idx],
            "next_obs": self.next_obs[idx],
            "next_mask": self.next_mask[idx],
            "done": self.done[idx],
        }

    def state_dict(self) -> dict[str, NDArray | int]:
        n = self.size
        return {
            "obs": self.obs[:n],
            "next_obs": self.next_obs[:n],
            "mask": self.mask[:n],
            "next_mask": self.next_mask[:n],
            "action": self.action[:n],
            "reward": self.reward[:n],
            "done": self.done[:n],
            "pos": self.pos,
        }


class SumTree:
    """Binary sum tree over ``capacity`` leaves (rounded up to a power of two), vectorised:
    ``update`` sets many leaves at once, ``find`` descends for many prefix sums at once."""

    def __init__(self, capacity: int):
        self.n_leaves = 1 << max(0, int(capacity - 1).bit_length())
        self.tree = np.zeros(2 * self.n_leaves, np.float64)  # node i has children 2i, 2i + 1

    @property
    def total(self) -> float:
        return float(self.tree[1])

    def update(self, idx: NDArray[np.integer], value: NDArray[np.floating]) -> None:
        node = np.asarray(idx, np.int64) + self.n_leaves
        self.tree[node] = value
        node = np.unique(node // 2)
        while node.size and node[0] >= 1:
            self.tree[node] = self.tree[2 * node] + self.tree[2 * node + 1]
            node = np.unique(node // 2)
            node = node[node >= 1]

    def find(self, prefix: NDArray[np.floating]) -> NDArray[np.int64]:
        """Leaf index i with cumsum(leaves)[i-1] <= prefix < cumsum(leaves)[i], per prefix."""
        u = np.asarray(prefix, np.float64).copy()
        node = np.ones(len(u), np.int64)
        while node[0] < self.n_leaves:
            left = 2 * node
            go_right = u >= self.tree[left]
            u = np.where(go_right, u - self.tree[left], u)
            node = left + go_right
        return node - self.n_leaves


class PrioritizedReplayBuffer(ReplayBuffer):
    """Proportional prioritised replay (Schaul et al. 2016) of n-step transitions.

    Stores ``discount`` = gamma^k of each transition (k <= n steps actually summed into its
    ``reward``). A new transition gets the largest priority seen so far. ``sample`` draws
    index i with probability P(i) = p_i^alpha / sum_j p_j^alpha (stratified: one draw per
    equal slice of the total) and returns importance weights w_i = (N P(i))^-beta / max_batch w.
    """

    def __init__(self, capacity: int, obs_dim: int, alpha: float = 0.5, n_actions: int = 27):
        super().__init__(capacity, obs_dim, n_actions)
        self.alpha = alpha
        self.discount = np.zeros(self.capacity, np.float32)
        self.tree = SumTree(self.capacity)
        self.max_priority = 1.0

    def add(self, obs, mask, action, reward, next_obs, next_mask, done, discount=None) -> None:
        n = len(action)
        idx = (self.pos + np.arange(n)) % self.capacity
        super().add(obs, mask, action, reward, next_obs, next_mask, done)
        self.discount[idx] = 0.0 if discount is None else discount
        self.tree.update(idx, np.full(n, self.max_priority**self.alpha))

    def sample(  # type: ignore[override]
        self, batch: int, rng: np.random.Generator, beta: float = 0.4
    ) -> dict[str, NDArray]:
        total = self.tree.total
        prefix = (np.arange(batch) + rng.random(batch)) * (total / batch)
        idx = np.minimum(self.tree.find(np.minimum(prefix, total * (1 - 1e-12))), self.size - 1)
        prob = self.tree.tree[idx + self.tree.n_leaves] / total
        w = (self.size * prob) ** (-beta)
        return {
            "obs": self.obs[idx],
            "mask": self.mask[idx],
            "action": self.action[idx],
            "reward": self.reward[idx],
            "next_obs": self.next_obs[idx],
            "next_mask": self.next_mask[idx],
            "done": self.done[idx],
            "discount": self.discount[idx],
            "weight": (w / w.max()).astype(np.float32),
            "index": idx,
        }

    def update_priorities(self, idx: NDArray[np.integer], priority: NDArray[np.floating]) -> None:
        """Set the priorities p_i (before the exponent alpha) of the sampled transitions."""
        p = np.maximum(np.asarray(priority, np.float64), 1e-6)
        self.max_priority = max(self.max_priority, float(p.max()))
        self.tree.update(idx, p**self.alpha)


class NStepAccumulator:
    """Turns per-step transitions of ``n_envs`` parallel episodes (row e = episode e) into
    n-step transitions (s_t, a_t, R = sum_{k<K} gamma^k r_{t+k}, s_{t+K}, done, gamma^K) with
    K = n, or fewer when the episode ends first (then every pending transition is emitted)."""

    def __init__(self, n_envs: int, n: int, gamma: float):
        self.n, self.gamma = n, gamma
        self.pending: list[list[tuple]] = [[] for _ in range(n_envs)]

    def push(self, obs, mask, action, reward, next_obs, next_mask, done, ended) -> dict:
        """One step of every episode (arrays with leading dimension n_envs); returns the
        completed n-step transitions as arrays (possibly empty)."""
        rows: list[tuple] = []
        for e, q in enumerate(self.pending):
            q.append((obs[e], mask[e], action[e], reward[e]))
            if len(q) == self.n:
                rows.append(self._emit(q, next_obs[e], next_mask[e], done[e]))
                q.pop(0)
            if ended[e]:
                while q:
                    rows.append(self._emit(q, next_obs[e], next_mask[e], done[e]))
                    q.pop(0)
        if not rows:
            return {"action": np.zeros(0, np.int64)}
        cols = list(zip(*rows, strict=True))
        keys = ("obs", "mask", "action", "reward", "next_obs", "next_mask", "done", "discount")
        return {k: np.asarray(c) for k, c in zip(keys, cols, strict=True)}

    def _emit(self, q: list[tuple], next_obs, next_mask, done) -> tuple:
        ret = sum(self.gamma**k * r for k, (_, _, _, r) in enumerate(q))
        s, m, a, _ = q[0]
        return (
            s,
            m,
            a,
            np.float32(ret),
            next_obs,
            next_mask,
            done,
            np.float32(self.gamma ** len(q)),
        )


class SplitRewardReplayBuffer(ReplayBuffer):
    """Uniform replay that keeps the goal part and the safety part of the reward apart
    (Safe-DQN-X); ``reward`` holds their sum."""

    def __init__(self, capacity: int, obs_dim: int, n_actions: int = 27):
        super().__init__(capacity, obs_dim, n_actions)
        self.goal_reward = np.zeros(self.capacity, np.float32)
        self.safety_reward = np.zeros(self.capacity, np.float32)

    def add_split(
        self, obs, mask, action, goal_reward, safety_reward, next_obs, next_mask, done
    ) -> None:
        n = len(action)
        idx = (self.pos + np.arange(n)) % self.capacity
        self.add(obs, mask, action, goal_reward + safety_reward, next_obs, next_mask, done)
        self.goal_reward[idx], self.safety_reward[idx] = goal_reward, safety_reward

    def sample(self, batch: int, rng: np.random.Generator) -> dict[str, NDArray]:
        idx = rng.integers(0, self.size, batch)
        return {
            "obs": self.obs[idx],
            "mask": self.mask[idx],
            "action": self.action[idx],
            "goal_reward": self.goal_reward[idx],
            "safety_reward": self.safety_reward[idx],
            "next_obs": self.next_obs[idx],
            "next_mask": self.next_mask[idx],
            "done": self.done[idx],
        }
