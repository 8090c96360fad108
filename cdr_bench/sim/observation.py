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

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from cdr_bench.scenarios.schema import ScenarioConfig

if TYPE_CHECKING:
    from cdr_bench.sim.core import Simulator

OWN_FEATURES = (
    "x",
    "y",
    "sin_heading",
    "cos_heading",
    "speed",
    "level",
    "goal_dx",
    "goal_dy",
    "goal_dist",
    "goal_sin_rel",
    "goal_cos_rel",
    "time",
)
NEIGHBOUR_FEATURES = (
    "present",
    "dx",
    "dy",
    "dvx",
    "dvy",
    "dlevel",
    "dist",
    "t_cpa",
    "d_cpa",
    "conflict",
)


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


def observe(
    sim: Simulator,
    episodes: NDArray[np.integer] | None = None,
    out: NDArray[np.float32] | None = None,
) -> NDArray[np.float32]:
    """Observation of every controlled aircraft, (E, M, F) float32: the first part of
    :meth:`Simulator.observe <cdr_bench.sim.core.Simulator.observe>` (which also gives the
    action masks).

    Args:
        sim: the simulator.
        episodes: only these episodes (default all); the rows of the others in ``out`` are
            left as they are.
        out: (E, M, F) float32 array to write into (default a new zero array).
    """
    return sim.observe(episodes, obs=out)[0]
