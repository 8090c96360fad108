"""MaskablePPO (sb3-contrib): PPO with the 27-action feasibility mask in acting and in the loss.

    cdr-bench train maskable-ppo --run-dir runs/maskable-ppo --total-steps 200000

Flags, environment and outputs: :mod:`cdr_bench.rl.train_sb3`.
"""

from __future__ import annotations

import argparse

from cdr_bench.rl import train_sb3

ALGORITHM = "maskable-ppo"


def add_arguments(p: argparse.ArgumentParser) -> None:
    train_sb3.add_arguments(p, ALGORITHM)


def run(ns: argparse.Namespace) -> dict:
    """Entry point of ``cdr-bench train maskable-ppo``."""
    return train_sb3.run(ALGORITHM, ns)


if __name__ == "__main__":
    raise SystemExit(train_sb3.main(ALGORITHM, __doc__))
