"""Observation vector of every controlled aircraft (pure numpy).

Layout (``F = 12 + 10 K`` float32 values, K nearest aircraft by horizontal distance at any level;
every value is clipped to the bounds in :func:`observation_bounds`):

====  =====================  ==================================================================
idx   name                   meaning (normalisation)
====  =====================  ==================================================================
0     x                      own x: 2 x / size - 1 (-1 west edge, +1 east edge)
1     y                      own y: 2 y / size - 1
2     sin_heading            sin(heading); heading clockwise from north
3     cos_heading            cos(heading)
4     speed                  (speed - mid) / half-range of [min_speed_kt, max_speed_kt]
5     level                  level - 1 (-1, 0, +1)
6     goal_dx                (x_goal - x) / size
7     goal_dy                (y_goal - y) / size
8     goal_dist              distance to goal / size
9     goal_sin_rel           sin(bearing to goal - heading) (+ = goal to the right)
10    goal_cos_rel           cos(bearing to goal - heading)
11    time                   steps elapsed / max_steps
12+   neighbour k (10 each)  for k = 0..K-1, nearest first, all zero when the slot is empty:
+0    present                1 if an aircraft fills this slot
+1    dx                     (x_k - x) / range_km
+2    dy                     (y_k - y) / range_km
+3    dvx                    (vx_k - vx) / 1000 kt
+4    dvy                    (vy_k - vy) / 1000 kt
+5    dlevel                 (level_k - level) / 2
+6    dist                   horizontal distance / range_km
+7    t_cpa                  time to closest approach / lookahead_s (0 if diverging)
+8    d_cpa                  distance at closest approach (within lookahead) / range_km
+9    conflict               1 if same level and d_cpa < los_km (a predicted LoS)
====  =====================  ==================================================================
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from cdr_bench.scenarios.schema import ScenarioConfig
from cdr_bench.sim.core import Simulator
from cdr_bench.sim.geometry import bearing_deg, closest_approach
from cdr_bench.sim.units import KM_PER_S_PER_KT

OWN_FEATURES = (
    "x", "y", "sin_heading", "cos_heading", "speed", "level", "goal_dx", "goal_dy", "goal_dist",
    "goal_sin_rel", "goal_cos_rel", "time",
)
NEIGHBOUR_FEATURES = ("present", "dx", "dy", "dvx", "dvy", "dlevel", "dist", "t_cpa", "d_cpa",
                      "conflict")
_VEL_SCALE_KM_S = 1000.0 * KM_PER_S_PER_KT


def feature_names(neighbours: int) -> list[str]:
    """Name of every observation index."""
    names = list(OWN_FEATURES)
    for k in range(neighbours):
        names += [f"n{k}_{f}" for f in NEIGHBOUR_FEATURES]
    return names


def observation_bounds(config: ScenarioConfig) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """(low, high) of the observation Box, each (F,)."""
    own_lo = [-3, -3, -1, -1, -1, -1, -3, -3, 0, -1, -1, 0]
    own_hi = [3, 3, 1, 1, 1, 1, 3, 3, 5, 1, 1, 1]
    nb_lo = [0, -10, -10, -2, -2, -1, 0, 0, 0, 0]
    nb_hi = [1, 10, 10, 2, 2, 1, 10, 1, 10, 1]
    k = config.observation.neighbours
    low = np.array(own_lo + nb_lo * k, dtype=np.float32)
    high = np.array(own_hi + nb_hi * k, dtype=np.float32)
    return low, high


def observe(sim: Simulator) -> NDArray[np.float32]:
    """Observation of every controlled aircraft, (E, M, F) float32.

    Aircraft that are not flying get the observation of their last state (the environment does
    not ask for it once they have left).
    """
    cfg = sim.config
    size = sim.size_km
    K = cfg.observation.neighbours
    rng_km = cfg.observation.range_km
    E, M = sim.E, sim.M
    pos = sim.ac_pos_km
    vel = sim.velocities_km_s()
    head = sim.ac_heading_deg
    goal_vec = sim.ac_goal_km - pos
    goal_dist = np.sqrt((goal_vec**2).sum(-1))
    rel_bearing = np.deg2rad(bearing_deg(goal_vec[..., 0], goal_vec[..., 1]) - head)
    mid = 0.5 * (sim.min_speed_kt + sim.max_speed_kt)
    half = max(0.5 * (sim.max_speed_kt - sim.min_speed_kt), 1e-9)
    h = np.deg2rad(head)
    own = np.stack(
        [
            2 * pos[..., 0] / size - 1, 2 * pos[..., 1] / size - 1, np.sin(h), np.cos(h),
            (sim.ac_speed_kt - mid) / half, sim.ac_level - 1.0, goal_vec[..., 0] / size,
            goal_vec[..., 1] / size, goal_dist / size, np.sin(rel_bearing), np.cos(rel_bearing),
            np.broadcast_to((sim.steps / sim.max_steps)[:, None], (E, M)),
        ],
        axis=-1,
    )

    # Every other aircraft: background, then the other controlled ones still flying.
    o_pos = np.concatenate([sim.bg_pos_km, pos], axis=1)  # (E, N, 2)
    o_vel = np.concatenate([sim.bg_vel_km_s, vel], axis=1)
    o_lvl = np.concatenate([sim.bg_level, sim.ac_level], axis=1)
    o_act = np.concatenate([sim.bg_active, sim.ac_active], axis=1)
    N = o_pos.shape[1]
    rel = o_pos[:, None] - pos[:, :, None]  # (E, M, N, 2)
    dist = np.sqrt((rel**2).sum(-1))
    valid = np.broadcast_to(o_act[:, None, :], (E, M, N)).copy()
    valid[:, :, sim.B:] &= ~np.eye(M, dtype=bool)[None]
    dist = np.where(valid, dist, np.inf)
    if N > K:
        near = np.argpartition(dist, K - 1, axis=-1)[..., :K]
        order = np.argsort(np.take_along_axis(dist, near, -1), axis=-1)
        near = np.take_along_axis(near, order, -1)
    else:
        near = np.argsort(dist, axis=-1)
    kk = near.shape[-1]
    nd = np.take_along_axis(dist, near, -1)  # (E, M, k)
    present = np.isfinite(nd)
    nrel = np.take_along_axis(rel, near[..., None], 2)
    nvel = o_vel[np.arange(E)[:, None, None], near] - vel[:, :, None]
    nlvl = o_lvl[np.arange(E)[:, None, None], near] - sim.ac_level[:, :, None]
    d_cpa, t_cpa = closest_approach(nrel, nvel, cfg.observation.lookahead_s)
    nb = np.stack(
        [
            np.ones_like(nd), nrel[..., 0] / rng_km, nrel[..., 1] / rng_km,
            nvel[..., 0] / _VEL_SCALE_KM_S, nvel[..., 1] / _VEL_SCALE_KM_S, nlvl / 2.0,
            nd / rng_km, t_cpa / cfg.observation.lookahead_s, d_cpa / rng_km,
            ((nlvl == 0) & (d_cpa < sim.los_km)).astype(float),
        ],
        axis=-1,
    )
    nb = np.where(present[..., None], nb, 0.0)
    if kk < K:
        nb = np.concatenate([nb, np.zeros((E, M, K - kk, nb.shape[-1]))], axis=2)
    obs = np.concatenate([own, nb.reshape(E, M, -1)], axis=-1).astype(np.float32)
    low, high = observation_bounds(cfg)
    return np.clip(obs, low, high)
