"""Scoring agents: the agent protocol, the loader, the lock-step episode runner, the metrics of
docs/model.md §10, result files and paired comparison. ``cdr-bench evaluate`` / ``compare`` /
``report`` are thin wrappers over these functions.

This package never imports torch (a test enforces it); an agent file may.
"""

from __future__ import annotations

from cdr_bench.evaluate.loader import AgentError, LoadedAgent, load_agent
from cdr_bench.evaluate.protocol import Agent
from cdr_bench.evaluate.seeds import derive_seed, episode_seeds

__all__ = ["Agent", "AgentError", "LoadedAgent", "derive_seed", "episode_seeds", "load_agent"]
