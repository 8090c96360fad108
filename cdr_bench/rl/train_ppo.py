"""PPO (Stable-Baselines3), unmasked as in the paper (§5.2): 3 x 128 layers, clip 0.2, GAE 0.95.

    cdr-bench train ppo --run-dir runs/ppo --total-steps 200000

Flags, environment and outputs: :mod:`cdr_bench.rl.train_sb3`.
"""

from __future__ import annotations

import argparse

from cdr_bench.rl import train_sb3

ALGORITHM = "ppo"


def add_arguments(p: argparse.ArgumentParser) -> None:
    train_sb3.add_arguments(p, ALGORITHM)


def run(ns: argparse.Namespace) -> dict:
    """Entry point of ``cdr-bench train ppo``."""
    return train_sb3.run(ALGORITHM, ns)


if __name__ == "__main__":
    raise SystemExit(train_sb3.main(ALGORITHM, __doc__))
