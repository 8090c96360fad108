"""How often numpy and plain Python round the same float64 operation differently, here.

The single-episode fast path (``Simulator.step_one`` / ``observe_one``) moves scalar work from
numpy to Python floats and must stay bit-identical to the batched path. This script shows which
operations can move: it applies each operation to random inputs both ways and counts results
that differ in any bit. Fused multiply-adds in numpy's SIMD loops make complex products and
magnitudes differ on machines with FMA/AVX-512; ``x ** 2`` differs because Python calls ``pow``.

Run: python benchmarks/numpy_python_rounding.py [--n 200000]
"""

from __future__ import annotations

import argparse
import cmath
import math
import platform

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, default=200_000, help="random inputs per operation")
    n = ap.parse_args().n
    rng = np.random.default_rng(1)
    scale = rng.choice([1e-3, 1.0, 100.0, 1e4], n)
    a = rng.normal(size=n) * scale + 1j * rng.normal(size=n) * scale
    b = rng.normal(size=n) + 1j * rng.normal(size=n)
    x = np.abs(rng.normal(size=n)) * scale
    h = rng.uniform(0.0, 360.0, n)
    ang = np.deg2rad(90.0 - h)
    al, bl, xl, hl = a.tolist(), b.tolist(), x.tolist(), h.tolist()
    prod = [u * v.conjugate() for u, v in zip(al, bl, strict=True)]
    scaled = [u * v for u, v in zip(al, xl, strict=True)]
    cases = {
        "complex product a * conj(b)": (a * b.conj(), prod),
        "complex magnitude |a|": (np.abs(a), [abs(u) for u in al]),
        "complex * real": (a * x, scaled),
        "x ** 2 (numpy) vs x ** 2 (Python)": (x**2, [v**2 for v in xl]),
        "x ** 2 (numpy) vs x * x (Python)": (x**2, [v * v for v in xl]),
        "(h + 45) % 360": ((h + 45.0) % 360.0, [(v + 45.0) % 360.0 for v in hl]),
        "deg2rad vs math.radians": (np.deg2rad(h), [math.radians(v) for v in hl]),
        "sin": (np.sin(ang), [math.sin(v) for v in ang.tolist()]),
        "exp(i angle) vs cmath.exp": (np.exp(1j * ang), [cmath.exp(1j * v) for v in ang]),
    }
    print(f"# {platform.machine()}, numpy {np.__version__}, {n:,} random inputs per operation")
    print("| operation | results differing from Python's |")
    print("|---|---:|")
    for name, (ours, theirs) in cases.items():
        differ = np.count_nonzero(ours != np.asarray(theirs))
        print(f"| {name} | {differ / n:.2%} |")


if __name__ == "__main__":
    main()
