"""Swept geometry: closest point of approach of straight segments over one step.

Every function broadcasts over leading axes; the last axis of positions and velocities is (x, y).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


def closest_approach(
    rel_pos_km: Array, rel_vel_km_s: Array, horizon_s: float | Array
) -> tuple[Array, Array]:
    """Minimum distance of a relative straight motion over ``[0, horizon_s]``.

    Args:
        rel_pos_km: relative position at t = 0, shape (..., 2), km.
        rel_vel_km_s: relative velocity, shape (..., 2), km/s.
        horizon_s: end of the interval, s (scalar or broadcastable to (...)).

    Returns:
        ``(d_min_km, t_min_s)``, each of shape (...): the smallest distance over the interval and
        the time at which it is reached (0 for diverging or static pairs).
    """
    px, py = rel_pos_km[..., 0], rel_pos_km[..., 1]
    vx, vy = rel_vel_km_s[..., 0], rel_vel_km_s[..., 1]
    vv = vx * vx + vy * vy
    pv = px * vx + py * vy
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(vv > 0.0, -pv / np.where(vv > 0.0, vv, 1.0), 0.0)
    t = np.minimum(np.maximum(t, 0.0), horizon_s)
    dx = px + vx * t
    dy = py + vy * t
    return np.sqrt(dx * dx + dy * dy), t


def heading_to_unit(heading_deg: Array) -> Array:
    """Unit vector (east, north) of a heading in degrees clockwise from north, shape (..., 2)."""
    h = np.deg2rad(heading_deg)
    return np.stack([np.sin(h), np.cos(h)], axis=-1)


def bearing_deg(dx_km: Array, dy_km: Array) -> Array:
    """Bearing of a vector (east, north) in degrees clockwise from north, in [0, 360)."""
    return np.mod(np.rad2deg(np.arctan2(dx_km, dy_km)), 360.0)
