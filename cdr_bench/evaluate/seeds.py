"""Common random numbers: the seed of episode ``i`` of a scenario under base seed ``b``.

``seed = int(SHA-256(f"{b}/{scenario_id}/{config_hash}/{i}")[:8]) >> 1`` (the first 8 bytes of
the digest, big-endian, shifted to a non-negative 63-bit integer). It depends on nothing else
(not on the agent, the batch size, ``--workers`` or ``--resume``), so episode ``i`` is the same
traffic, start and goal for every agent. The same seed reproduces the episode in the PettingZoo
environment: ``env.reset(options={"episode_seed": seed})``.
"""

from __future__ import annotations

import hashlib


def derive_seed(base_seed: int, scenario_id: str, config_hash: str, episode: int) -> int:
    """The simulator seed of episode ``episode`` (a non-negative 63-bit integer)."""
    key = f"{int(base_seed)}/{scenario_id}/{config_hash}/{int(episode)}".encode()
    return int.from_bytes(hashlib.sha256(key).digest()[:8], "big") >> 1


def episode_seeds(base_seed: int, scenario_id: str, config_hash: str, start: int, stop: int):
    """Seeds of episodes ``start..stop-1``."""
    return [derive_seed(base_seed, scenario_id, config_hash, i) for i in range(start, stop)]
