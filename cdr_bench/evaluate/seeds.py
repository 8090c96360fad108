"""Common random numbers: the seed of episode ``i`` of a scenario under base seed ``b``.

``seed = int(SHA-256(f"{b}/{scenario_id}/{config_hash}/{i}")[:8]) >> 1`` (the first 8 bytes of
the digest, big-endian, shifted to a non-negative 63-bit integer). It depends on nothing else
(not on the agent, the batch size, ``--workers`` or ``--resume``), so episode ``i`` is the same
traffic, start and goal for every agent. The same seed reproduces the episode in the PettingZoo
environment: ``env.reset(options={"episode_seed": seed})``.

**Validation and test episodes** (:data:`SPLITS`). Every set of episodes is a base seed.
Tuning, sweeps, candidate comparison, early stopping and checkpoint choice use a *validation*
set; the *test* set scores a finished leaderboard entry once, and nothing is chosen on it.
``validation`` (base seed 1) is the default of ``cdr-bench evaluate`` and of sweeps;
``validation-0`` (base seed 0) was the leaderboard's test set until 2026-11-27, when it was
retired because candidates had been compared on it (every sweep in ``sweeps/landed/`` was
evaluated on its first episodes), and it stays public as a second validation set; ``test``
(base seed 20261127) is the leaderboard's test set since then, drawn new and never used by a
sweep or a candidate comparison. The trainers' own evaluations (the learning curve, the
curriculum's checks) draw raw episode seeds outside this derivation and never meet these sets.
"""

from __future__ import annotations

import hashlib

SPLITS = {"validation": 1, "validation-0": 0, "test": 20261127}
"""Base seed of each named episode set (see the module docstring)."""

VALIDATION = "validation"
"""The default split of ``cdr-bench evaluate`` and of sweeps."""

TEST_SEED = SPLITS["test"]
"""The leaderboard's test episodes."""


def split_of(base_seed: int) -> str | None:
    """The name of the split whose base seed is ``base_seed`` (None: a custom one)."""
    return next((k for k, v in SPLITS.items() if v == int(base_seed)), None)


def derive_seed(base_seed: int, scenario_id: str, config_hash: str, episode: int) -> int:
    """The simulator seed of episode ``episode`` (a non-negative 63-bit integer)."""
    key = f"{int(base_seed)}/{scenario_id}/{config_hash}/{int(episode)}".encode()
    return int.from_bytes(hashlib.sha256(key).digest()[:8], "big") >> 1


def episode_seeds(base_seed: int, scenario_id: str, config_hash: str, start: int, stop: int):
    """Seeds of episodes ``start..stop-1``."""
    return [derive_seed(base_seed, scenario_id, config_hash, i) for i in range(start, stop)]
