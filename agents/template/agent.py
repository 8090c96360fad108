"""Template of a cdr-bench agent: copy this folder, fill in the two methods, then run

    cdr-bench evaluate path/to/my_agent/agent.py --episodes 100 --scenario medium

The protocol (see ``cdr_bench/evaluate/protocol.py``):

* a class named ``Agent``, constructed as ``Agent(observation_space, action_space)`` with the
  environment's per-agent spaces: ``observation_space["observation"]`` is a ``Box(F,)`` float32
  (F = 42 for the shipped scenarios; the index table is in the README's environment card,
  section "Observation Space", and in docs/environment.md),
  ``observation_space["action_mask"]`` a ``Box(27,)`` int8, ``action_space`` is
  ``Discrete(27)``;
* ``act(observation) -> int``: ``observation`` is the dict ``{"observation": (F,) float32,
  "action_mask": (27,) int8}``; return an action index 0..26 where index
  ``9 * (a_psi + 1) + 3 * (a_v + 1) + (a_h + 1)`` encodes heading -/0/+5 deg (+ = right),
  speed -/0/+50 kt and level -/0/+1 (``cdr_bench.actions.encode((a_psi, a_v, a_h))`` takes
  one tuple of three values in {-1, 0, 1}; ``decode(index)`` gives the tuple back);
* optional ``act_batch(observations (N, F), masks (N, 27)) -> N ints``: decide for many aircraft
  at once (the evaluator runs episodes in lock-step batches: much faster than ``act``);
* optional ``reset(seed)``: called before every batch of episodes; re-seed any randomness here.

The same agent drives the ownship and every learning intruder. A masked action (``mask == 0``)
is counted as invalid and its level change is not executed; anything that is not an integer in
0..26 stops the evaluation with an error.

A learned agent loads its weights relative to this file, without unpickling (the leaderboard
refuses pickles and TorchScript archives), e.g. a PyTorch state dict::

    import torch
    CHECKPOINT = Path(__file__).parent / "policy.pt"      # torch.save(model.state_dict(), ...)
    self.policy = MyNetwork()                               # a torch.nn.Module defined here
    self.policy.load_state_dict(torch.load(CHECKPOINT, map_location="cpu", weights_only=True))
    self.policy.eval()

(or safetensors, or ``numpy.load`` of an ``.npz``). Plain PyTorch is fine on the leaderboard:
results are verified by replaying their recorded decisions through the simulator (exact, on
any CPU), and your agent is asked again on a random sample of episodes, where at least 99 % of
its decisions must match (another CPU's kernels may break a near tie the other way);
CONTRIBUTING.md, "How a result is verified". ``cdr_bench.inference`` is an optional runtime of
numba layers whose outputs are the same bits on every CPU, for agents that want 100 %.

An entry's identity is the ``.py`` files of this folder, the checkpoint its submission names
and the configuration files beside that checkpoint (or, with no checkpoint named, the weight and
configuration files directly in this folder): a result names exactly what it scored. The agent
runs in its own, sandboxed process; it sees only observations and masks.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).parent
HOLD = 13  # (0, 0, 0): keep heading, speed and level


class Agent:
    def __init__(self, observation_space: Any, action_space: Any):
        self.n_actions = int(action_space.n)  # 27
        self.obs_size = int(observation_space["observation"].shape[0])
        # Load a checkpoint here, e.g. from HERE / "policy.pt".

    def reset(self, seed: int) -> None:
        """Re-seed any randomness (called before every lock-step batch of episodes)."""
        self.rng = np.random.default_rng(seed)

    def act(self, observation: dict[str, np.ndarray]) -> int:
        """One action for one aircraft. Replace with your policy."""
        obs = observation["observation"]  # (F,) float32
        mask = observation["action_mask"]  # (27,) int8, 1 = feasible
        del obs
        return HOLD if mask[HOLD] else int(np.flatnonzero(mask)[0])

    def act_batch(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        """(N,) actions for (N, F) observations and (N, 27) masks. Optional; delete it to have
        ``act`` called row by row."""
        return np.full(observations.shape[0], HOLD, dtype=np.int64)
