"""TD3 (Stable-Baselines3): continuous (a_psi, a_v, a_h) rounded to the discrete triple (§5.2).

    cdr-bench train td3 --run-dir runs/td3 --total-steps 200000

Flags, environment and outputs: :mod:`cdr_bench.rl.train_sb3`.
"""

from __future__ import annotations

import argparse

from cdr_bench.rl import train_sb3

ALGORITHM = "td3"


def add_arguments(p: argparse.ArgumentParser) -> None:
    train_sb3.add_arguments(p, ALGORITHM)


def run(ns: argparse.Namespace) -> dict:
    """Entry point of ``cdr-bench train td3``."""
    return train_sb3.run(ALGORITHM, ns)


if __name__ == "__main__":
    raise SystemExit(train_sb3.main(ALGORITHM, __doc__))
