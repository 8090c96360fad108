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
