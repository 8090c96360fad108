"""Replay of the off-policy loop, in preallocated numpy arrays (pure numpy).

A transition is one flying aircraft, one step: ``obs, mask, action, reward, goal_reward,
safety_reward, next_obs, next_mask, done, discount`` (``reward`` = goal + safety part; Safe-DQN-X
learns the parts apart; ``discount`` = gamma^k of an n-step transition).

* :class:`ReplayBuffer` -- ring buffer, uniform sampling;
* :class:`PrioritizedReplayBuffer` -- proportional prioritised sampling over a :class:`SumTree`;
* :class:`NStepAccumulator` -- per-aircraft n-step returns in front of a buffer;
* :class:`Replay` -- what the loop holds: an optional accumulator and one of the two buffers.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cdr_bench.rl.common import linear_schedule

Batch = dict[str, NDArray]

REWARDS = ("reward", "goal_reward", "safety_reward")


class ReplayBuffer:
    """Ring buffer; ``add`` takes a batch of transitions, ``sample`` draws uniformly."""

    def __init__(self, capacity: int, obs_dim: int, n_actions: int = 27):
        self.capacity = c = int(capacity)
        self.data: Batch = {
            "obs": np.zeros((c, obs_dim), np.float32),
            "mask": np.zeros((c, n_actions), np.int8),
            "action": np.zeros(c, np.int64),
            "reward": np.zeros(c, np.float32),
            "goal_reward": np.zeros(c, np.float32),
            "safety_reward": np.zeros(c, np.float32),
            "next_obs": np.zeros((c, obs_dim), np.float32),
            "next_mask": np.zeros((c, n_actions), np.int8),
            "done": np.zeros(c, np.float32),
            "discount": np.zeros(c, np.float32),
        }
        self.pos = 0
        self.size = 0

    def __len__(self) -> int:
        return self.size

    def add(self, tr: Mapping[str, Any]) -> NDArray[np.int64]:
        """Append n transitions (columns with leading dimension n; a missing column is stored
        as 0), overwriting the oldest; returns their slots."""
        n = len(tr["action"])
        idx = (self.pos + np.arange(n)) % self.capacity
        for k, col in self.data.items():
            col[idx] = tr.get(k, 0)
        self.pos = int((self.pos + n) % self.capacity)
        self.size = min(self.size + n, self.capacity)
        return idx

    def sample(self, batch: int, rng: np.random.Generator, beta: float = 0.4) -> Batch:
        """``batch`` transitions drawn uniformly with replacement (``beta`` unused)."""
        return self.rows(rng.integers(0, self.size, batch))

    def rows(self, idx: NDArray[np.integer]) -> Batch:
        return {k: col[idx] for k, col in self.data.items()}

    def state_dict(self) -> dict[str, Any]:
        return {"data": self.rows(np.arange(self.size)), "pos": self.pos}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        n = len(state["data"]["action"])
        for k, col in self.data.items():
            col[:n] = state["data"][k]
        self.size, self.pos = n, state["pos"]


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
    """Proportional prioritised replay (Schaul et al. 2016).

    A new transition gets the largest priority seen so far. ``sample`` draws index i with
    probability P(i) = p_i^alpha / sum_j p_j^alpha (stratified: one draw per equal slice of the
    total) and returns importance weights ``weight`` w_i = (N P(i))^-beta / max_batch w and the
    drawn slots ``index``.
    """

    def __init__(self, capacity: int, obs_dim: int, alpha: float = 0.5, n_actions: int = 27):
        super().__init__(capacity, obs_dim, n_actions)
        self.alpha = alpha
        self.tree = SumTree(self.capacity)
        self.max_priority = 1.0

    def add(self, tr: Mapping[str, Any]) -> NDArray[np.int64]:
        idx = super().add(tr)
        self.tree.update(idx, np.full(len(idx), self.max_priority**self.alpha))
        return idx

    def sample(self, batch: int, rng: np.random.Generator, beta: float = 0.4) -> Batch:
        total = self.tree.total
        prefix = (np.arange(batch) + rng.random(batch)) * (total / batch)
        idx = np.minimum(self.tree.find(np.minimum(prefix, total * (1 - 1e-12))), self.size - 1)
        prob = self.tree.tree[idx + self.tree.n_leaves] / total
        w = (self.size * prob) ** (-beta)
        return {**self.rows(idx), "weight": (w / w.max()).astype(np.float32), "index": idx}

    def update_priorities(self, idx: NDArray[np.integer], priority: NDArray[np.floating]) -> None:
        """Set the priorities p_i (before the exponent alpha) of the sampled transitions."""
        p = np.maximum(np.asarray(priority, np.float64), 1e-6)
        self.max_priority = max(self.max_priority, float(p.max()))
        self.tree.update(idx, p**self.alpha)

    def state_dict(self) -> dict[str, Any]:
        return {**super().state_dict(), "tree": self.tree.tree, "max_priority": self.max_priority}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        super().load_state_dict(state)
        self.tree.tree[:] = state["tree"]
        self.max_priority = state["max_priority"]


class NStepAccumulator:
    """Turns per-step transitions of the aircraft in ``n_slots`` slots into n-step transitions
    (s_t, a_t, R = sum_{k<K} gamma^k r_{t+k}, s_{t+K}, done, gamma^K) with K = n, or fewer when
    the aircraft's flight ends first (then every pending transition of the slot is emitted).
    Every reward column (``reward``, ``goal_reward``, ``safety_reward``) is summed alike."""

    def __init__(self, n_slots: int, n: int, gamma: float):
        self.n, self.gamma = n, gamma
        self.pending: list[list[tuple]] = [[] for _ in range(n_slots)]

    def push(self, slots: NDArray[np.integer], tr: Mapping[str, Any], ended) -> Batch:
        """One step of the aircraft in ``slots`` (row i of every column is slot ``slots[i]``;
        ``ended[i]``: its flight ended); returns the completed n-step transitions, in slot
        order (possibly none)."""
        rows: list[tuple] = []
        for i, s in enumerate(slots):
            q = self.pending[s]
            q.append((tr["obs"][i], tr["mask"][i], tr["action"][i], *(tr[k][i] for k in REWARDS)))
            if len(q) == self.n:
                rows.append(self._emit(q, tr, i))
                q.pop(0)
            if ended[i]:
                while q:
                    rows.append(self._emit(q, tr, i))
                    q.pop(0)
        keys = ("obs", "mask", "action", *REWARDS, "next_obs", "next_mask", "done", "discount")
        if not rows:
            return {"action": np.zeros(0, np.int64)}
        return {k: np.asarray(c) for k, c in zip(keys, zip(*rows, strict=True), strict=True)}

    def _emit(self, q: list[tuple], tr: Mapping[str, Any], i: int) -> tuple:
        returns = [
            np.float32(sum(self.gamma**k * step[3 + j] for k, step in enumerate(q)))
            for j in range(len(REWARDS))
        ]
        s, m, a = q[0][:3]
        nxt = (tr["next_obs"][i], tr["next_mask"][i], tr["done"][i])
        return (s, m, a, *returns, *nxt, np.float32(self.gamma ** len(q)))


@dataclass(frozen=True)
class ReplayConfig:
    """How an algorithm's transitions are stored and drawn."""

    n_step: int = 1
    """n of the n-step return (1: transitions as they come)"""
    alpha: float | None = None
    """prioritised replay exponent; None: uniform sampling"""
    beta_start: float = 0.4
    """prioritised replay: importance-sampling exponent at the start, annealed linearly to 1
    at the end of the budget"""


class Replay:
    """The loop's replay: n-step returns (if ``n_step`` > 1) in front of a uniform or a
    prioritised buffer."""

    def __init__(self, cfg: ReplayConfig, capacity: int, obs_dim: int, n_slots: int, gamma: float):
        self.cfg, self.gamma = cfg, gamma
        self.prioritized = cfg.alpha is not None
        self.buffer = (
            PrioritizedReplayBuffer(capacity, obs_dim, cfg.alpha)
            if cfg.alpha is not None
            else ReplayBuffer(capacity, obs_dim)
        )
        self.nstep = NStepAccumulator(n_slots, cfg.n_step, gamma) if cfg.n_step > 1 else None

    def __len__(self) -> int:
        return len(self.buffer)

    def add(self, slots: NDArray[np.integer], tr: Batch, ended: NDArray[np.bool_]) -> None:
        """One step's transitions (row i = the aircraft in slot ``slots[i]``)."""
        if self.nstep is not None:
            tr = self.nstep.push(slots, tr, ended)
        else:
            tr = {**tr, "discount": np.full(len(tr["action"]), self.gamma, np.float32)}
        if len(tr["action"]):
            self.buffer.add(tr)

    def beta(self, step: int, total_steps: int) -> float:
        """Prioritised replay's importance-sampling exponent after ``step`` transitions."""
        return linear_schedule(self.cfg.beta_start, 1.0, total_steps, step)

    def sample(self, batch: int, rng: np.random.Generator, beta: float) -> Batch:
        return self.buffer.sample(batch, rng, beta)

    def update_priorities(self, batch: Batch, priority: NDArray[np.floating]) -> None:
        assert isinstance(self.buffer, PrioritizedReplayBuffer)
        self.buffer.update_priorities(batch["index"], priority)

    def state_dict(self) -> dict[str, Any]:
        pending = self.nstep.pending if self.nstep is not None else None
        return {"buffer": self.buffer.state_dict(), "pending": pending}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.buffer.load_state_dict(state["buffer"])
        if self.nstep is not None:
            self.nstep.pending = state["pending"]
