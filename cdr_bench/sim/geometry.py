"""Geometry outside the step: exact heading vectors from degrees, bearings for display.

The swept closest approach used by the step and the observation is
:func:`cdr_bench.sim.kernels.closest_approach` (compiled, one implementation).

Headings in the scenario format are degrees clockwise from north; the simulator carries a unit
vector (east, north) = (sin h, cos h) instead and never calls a trigonometric function while it
runs. :func:`exact_unit_vector` gives that vector correctly rounded (decimal arithmetic, not the
platform's libm), so a configured heading means the same bits on every machine.
"""

from __future__ import annotations

import decimal
import math

import numpy as np
from numpy.typing import NDArray

from cdr_bench.sim.kernels import closest_approach

__all__ = ["bearing_deg", "closest_approach", "exact_unit_vector", "heading_deg"]

_PI = decimal.Decimal(
    "3.14159265358979323846264338327950288419716939937510582097494459230781640628620899863"
)


def _sin_cos(x: decimal.Decimal) -> tuple[decimal.Decimal, decimal.Decimal]:
    """Taylor series of sin and cos at the context's precision (|x| <= pi / 4 converges in a
    few dozen terms)."""
    ctx = decimal.getcontext()
    s, c = decimal.Decimal(0), decimal.Decimal(0)
    term = decimal.Decimal(1)  # x^k / k!
    k = 0
    eps = decimal.Decimal(10) ** (-ctx.prec - 2)  # |cos| >= 0.7 here: an absolute bound
    while True:
        if k % 4 == 0:
            c += term
        elif k % 4 == 1:
            s += term
        elif k % 4 == 2:
            c -= term
        else:
            s -= term
        k += 1
        term = term * x / k
        if k >= 2 and abs(term) < eps:  # both series started; the rest is below the precision
            return s, c


def exact_unit_vector(heading_deg: float) -> tuple[float, float]:
    """(sin h, cos h) of a heading in degrees clockwise from north, each correctly rounded to
    the nearest float64 (50 significant digits in between), identical on every platform."""
    with decimal.localcontext() as ctx:
        ctx.prec = 50
        h = decimal.Decimal(heading_deg) % 360  # exact: a float is a finite binary fraction
        # Reduce to [-45, 45] degrees around a multiple of 90 degrees (exact in decimal).
        quadrant = int((h + 45) // 90) % 4
        r = (h - 90 * int((h + 45) // 90)) * _PI / 180
        s, c = _sin_cos(r)
        sin_h, cos_h = [(s, c), (c, -s), (-s, -c), (-c, s)][quadrant]
        return float(sin_h), float(cos_h)


def heading_deg(east: NDArray[np.float64], north: NDArray[np.float64]) -> NDArray[np.float64]:
    """Heading in degrees clockwise from north, in [0, 360), of a direction vector. For display
    and analysis only: the simulator never converts back to degrees."""
    return np.mod(np.rad2deg(np.arctan2(east, north)), 360.0)


def bearing_deg(dx_km: float, dy_km: float) -> float:
    """Bearing of one vector (east, north), degrees clockwise from north in [0, 360)."""
    return math.degrees(math.atan2(dx_km, dy_km)) % 360.0
