"""Replay of the off-policy loop, in preallocated numpy arrays (numpy, and numba for the sum tree
and the n-step queues).

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

from cdr_bench.rl import kernels
from cdr_bench.rl.common import linear_schedule

Batch = dict[str, NDArray]

REWARDS = ("reward", "goal_reward", "safety_reward")


def _columns(obs_dim: int, n_actions: int) -> list[tuple[str, np.dtype, tuple[int, ...]]]:
    return [
        ("obs", np.dtype(np.float32), (obs_dim,)),
        ("next_obs", np.dtype(np.float32), (obs_dim,)),
        ("action", np.dtype(np.int64), ()),
        ("reward", np.dtype(np.float32), ()),
        ("goal_reward", np.dtype(np.float32), ()),
        ("safety_reward", np.dtype(np.float32), ()),
        ("done", np.dtype(np.float32), ()),
        ("discount", np.dtype(np.float32), ()),
        ("mask", np.dtype(np.int8), (n_actions,)),
        ("next_mask", np.dtype(np.int8), (n_actions,)),
    ]


class ReplayBuffer:
    """Ring buffer; ``add`` takes a batch of transitions, ``sample`` draws uniformly.

    A transition is one row of bytes holding every column (:attr:`data` are strided views of
    the columns), so that drawing a batch is one gather of whole rows (adjacent cache lines)
    instead of one gather per column; the batch's columns are views of the gathered rows."""

    def __init__(self, capacity: int, obs_dim: int, n_actions: int = 27):
        self.capacity = c = int(capacity)
        self.layout: list[tuple[str, np.dtype, tuple[int, ...], int, tuple[int, ...]]] = []
        offset = 0
        for name, dtype, shape in _columns(obs_dim, n_actions):
            offset = -(-offset // dtype.itemsize) * dtype.itemsize  # aligned
            inner = (dtype.itemsize,) if shape else ()  # (every column has at most one axis)
            self.layout.append((name, dtype, shape, offset, inner))
            offset += dtype.itemsize * int(np.prod(shape, dtype=np.int64))
        self.row_bytes = -(-offset // 8) * 8  # a multiple of every column's alignment
        self.storage = np.zeros((c, self.row_bytes), np.uint8)
        self.data: Batch = self._views(self.storage)
        self.pos = 0
        self.size = 0

    def _views(self, rows: NDArray[np.uint8]) -> Batch:
        """The columns of ``rows`` (n, row_bytes) as strided views."""
        n, step = len(rows), self.row_bytes
        return {
            name: np.ndarray((n, *shape), dtype, rows, offset, (step, *inner))
            for name, dtype, shape, offset, inner in self.layout
        }

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
        """The transitions in slots ``idx`` (views of one gathered copy)."""
        return self._views(self.storage[idx])

    def state_dict(self) -> dict[str, Any]:
        data = {k: np.ascontiguousarray(v[: self.size]) for k, v in self.data.items()}
        return {"data": data, "pos": self.pos}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        n = len(state["data"]["action"])
        for k, col in self.data.items():
            col[:n] = state["data"][k]
        self.size, self.pos = n, state["pos"]


class SumTree:
    """Binary sum tree over ``capacity`` leaves (rounded up to a power of two): ``update`` sets
    many leaves at once, ``find`` descends for many prefix sums at once (compiled loops,
    :mod:`cdr_bench.rl.kernels`)."""

    def __init__(self, capacity: int):
        self.n_leaves = 1 << max(0, int(capacity - 1).bit_length())
        self.tree = np.zeros(2 * self.n_leaves, np.float64)  # node i has children 2i, 2i + 1

    @property
    def total(self) -> float:
        return float(self.tree[1])

    def update(self, idx: NDArray[np.integer], value: NDArray[np.floating]) -> None:
        """Leaves ``idx`` <- ``value`` (a repeated leaf keeps its last value), sums above."""
        leaves = np.ascontiguousarray(idx, np.int64)
        values = np.ascontiguousarray(np.broadcast_to(value, leaves.shape), np.float64)
        kernels.sum_tree_update(self.tree, self.n_leaves, leaves, values)

    def find(self, prefix: NDArray[np.floating]) -> NDArray[np.int64]:
        """Leaf index i with cumsum(leaves)[i-1] <= prefix < cumsum(leaves)[i], per prefix."""
        sums = np.ascontiguousarray(prefix, np.float64)
        out = np.empty(len(sums), np.int64)
        kernels.sum_tree_find(self.tree, self.n_leaves, sums, out)
        return out


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
    Every reward column (``reward``, ``goal_reward``, ``safety_reward``) is summed alike, in
    float32 from the oldest step.

    The pending steps of each slot are a ring buffer of n rows in preallocated arrays, pushed
    and emitted by one compiled loop (:func:`cdr_bench.rl.kernels.n_step_push`);
    :attr:`pending` shows them as lists."""

    def __init__(self, n_slots: int, n: int, gamma: float):
        self.n, self.gamma, self.n_slots = n, gamma, n_slots
        self.gamma_pow = np.array([np.float32(gamma**k) for k in range(n + 1)], np.float32)
        self.q: dict[str, NDArray] | None = None  # allocated at the first push
        self.q_start = np.zeros(n_slots, np.int64)
        self.q_len = np.zeros(n_slots, np.int64)

    def _allocate(self, obs_dim: int, n_actions: int) -> dict[str, NDArray]:
        s, n = self.n_slots, self.n
        self.q = {
            "obs": np.zeros((s, n, obs_dim), np.float32),
            "mask": np.zeros((s, n, n_actions), np.int8),
            "action": np.zeros((s, n), np.int64),
            "rewards": np.zeros((s, n, len(REWARDS)), np.float32),
        }
        return self.q

    def push(self, slots: NDArray[np.integer], tr: Mapping[str, Any], ended) -> Batch:
        """One step of the aircraft in ``slots`` (row i of every column is slot ``slots[i]``;
        ``ended[i]``: its flight ended); returns the completed n-step transitions, in slot
        order (possibly none)."""
        obs = np.ascontiguousarray(tr["obs"], np.float32)
        mask = np.ascontiguousarray(tr["mask"], np.int8)
        q = self.q if self.q is not None else self._allocate(obs.shape[1], mask.shape[1])
        rows = len(slots)
        cap = rows * self.n
        out: dict[str, NDArray[Any]] = {
            "src": np.empty(cap, np.int64),
            "row": np.empty(cap, np.int64),
            "obs": np.empty((cap, obs.shape[1]), np.float32),
            "mask": np.empty((cap, mask.shape[1]), np.int8),
            "action": np.empty(cap, np.int64),
            "rewards": np.empty((cap, len(REWARDS)), np.float32),
            "discount": np.empty(cap, np.float32),
        }
        m = kernels.n_step_push(
            np.ascontiguousarray(slots, np.int64),
            obs,
            mask,
            np.ascontiguousarray(tr["action"], np.int64),
            np.stack([np.asarray(tr[k], np.float32) for k in REWARDS], axis=1),
            np.ascontiguousarray(ended, np.bool_),
            q["obs"],
            q["mask"],
            q["action"],
            q["rewards"],
            self.q_start,
            self.q_len,
            self.gamma_pow,
            out["src"],
            out["row"],
            out["obs"],
            out["mask"],
            out["action"],
            out["rewards"],
            out["discount"],
        )
        if not m:
            return {"action": np.zeros(0, np.int64)}
        r = out["row"][:m]
        batch = {k: out[k][:m] for k in ("obs", "mask", "action")}
        batch.update({k: out["rewards"][:m, j] for j, k in enumerate(REWARDS)})
        batch.update({k: np.asarray(tr[k])[r] for k in ("next_obs", "next_mask", "done")})
        batch["discount"] = out["discount"][:m]
        return batch

    @property
    def pending(self) -> list[list[tuple]]:
        """Per slot, its pending steps, oldest first: (obs, mask, action, *rewards)."""
        out: list[list[tuple]] = [[] for _ in range(self.n_slots)]
        if self.q is None:
            return out
        for s in np.flatnonzero(self.q_len):
            for k in range(self.q_len[s]):
                j = (self.q_start[s] + k) % self.n
                rewards = tuple(self.q["rewards"][s, j])
                out[s].append(
                    (self.q["obs"][s, j], self.q["mask"][s, j], self.q["action"][s, j], *rewards)
                )
        return out

    def state_dict(self) -> dict[str, Any]:
        return {"q": self.q, "start": self.q_start, "len": self.q_len}

    def load_state_dict(self, state: dict[str, Any] | list[list[tuple]]) -> None:
        self.q_start[:] = 0
        self.q_len[:] = 0
        if isinstance(state, dict):
            self.q = None if state["q"] is None else {k: v.copy() for k, v in state["q"].items()}
            self.q_start[:] = state["start"]
            self.q_len[:] = state["len"]
            return
        # the lists of a state written before the ring buffers
        first = next((q[0] for q in state if q), None)
        self.q = None
        if first is None:
            return
        q = self._allocate(len(first[0]), len(first[1]))
        for s, steps in enumerate(state):
            for k, (o, mk, a, *rewards) in enumerate(steps):
                q["obs"][s, k], q["mask"][s, k], q["action"][s, k] = o, mk, a
                q["rewards"][s, k] = rewards
            self.q_len[s] = len(steps)


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
        pending = self.nstep.state_dict() if self.nstep is not None else None
        return {"buffer": self.buffer.state_dict(), "pending": pending}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.buffer.load_state_dict(state["buffer"])
        if self.nstep is not None:
            self.nstep.load_state_dict(state["pending"])
