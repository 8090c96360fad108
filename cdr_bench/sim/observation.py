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
from cdr_bench.sim.units import KM_PER_S_PER_KT

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
    E, M, B = sim.E, sim.M, sim.B
    out = np.zeros((E, M, 12 + 10 * K))

    # Own state and goal; complex numbers as 2-D vectors (east = real, north = imag), written
    # as (x, y) pairs where two features are the two components of one vector.
    pc, vc = sim._pc, sim._vc  # (E, N)
    own = pc[:, B:]
    out[..., 0:2] = sim.pos_km[:, B:] * (2.0 / size) - 1.0
    h = np.deg2rad(sim.ac_heading_deg)
    out[..., 2] = np.sin(h)
    out[..., 3] = np.cos(h)
    mid = 0.5 * (sim.min_speed_kt + sim.max_speed_kt)
    half = max(0.5 * (sim.max_speed_kt - sim.min_speed_kt), 1e-9)
    out[..., 4] = (sim.ac_speed_kt - mid) / half
    out[..., 5] = sim.level[:, B:] - 1.0
    g_xy = sim.ac_goal_km - sim.pos_km[:, B:]  # (E, M, 2)
    out[..., 6:8] = g_xy / size
    g = g_xy.view(np.complex128)[..., 0]
    gd = np.abs(g)
    out[..., 8] = gd / size
    # Goal direction relative to the heading: rotate by e^{i(h - 90°)}; for a goal to the right
    # (clockwise of the heading) the rotated vector points to negative imag.
    rel = g * np.exp(1j * (h - np.pi / 2)) / np.maximum(gd, 1e-9)
    out[..., 9] = -rel.imag
    out[..., 10] = rel.real
    out[..., 11] = (sim.steps / sim.max_steps)[:, None]

    # K nearest other aircraft (horizontal distance, any level).
    rp = pc[:, None, :] - own[:, :, None]  # (E, M, N)
    dist = np.where(sim.active[:, None, :] & sim._not_self, np.abs(rp), np.inf)
    near = np.argsort(dist, axis=-1)[..., :K]  # (E, M, k)
    kk = near.shape[-1]
    pair = near + sim._pair_offset  # flat index into (E, M, N)
    other = near + sim._episode_offset  # flat index into (E, N)
    nd = dist.take(pair)
    nrel = rp.take(pair)
    nvel = vc.take(other) - vc[:, B:, None]
    nlvl = (sim.level.take(other) - sim.level[:, B:, None]).astype(float)
    look = cfg.observation.lookahead_s
    t = np.minimum(np.maximum(-(nrel * nvel.conj()).real / (np.abs(nvel) ** 2 + 1e-300), 0.0), look)
    d_cpa = np.abs(nrel + nvel * t)
    nb = out[..., 12 : 12 + 10 * kk].reshape(E, M, kk, 10)
    nb[..., 0] = 1.0
    nb[..., 1:3] = nrel.view(np.float64).reshape(E, M, kk, 2) / rng_km
    nb[..., 3:5] = nvel.view(np.float64).reshape(E, M, kk, 2) / _VEL_SCALE_KM_S
    nb[..., 5] = nlvl / 2.0
    nb[..., 6] = nd / rng_km
    nb[..., 7] = t / look
    nb[..., 8] = d_cpa / rng_km
    nb[..., 9] = (nlvl == 0) & (d_cpa < sim.los_km)
    absent = nd == np.inf
    if np.count_nonzero(absent):
        nb[absent] = 0.0
    low, high = _bounds(cfg)
    return np.minimum(np.maximum(out, low, out=out), high, out=out).astype(np.float32)


def observe_one(sim: Simulator) -> NDArray[np.float32]:
    """:func:`observe` of a single-episode simulator (``E = 1``), (M, F) float32.

    Bit-identical to ``observe(sim)[0]`` (tested): numpy computes what it may round differently
    from Python (complex products and magnitudes, trigonometric functions, the sort) on the
    same values as :func:`observe`; the arithmetic of the few features is done on Python floats
    (see :meth:`Simulator.step_one`).
    """
    if sim.E != 1:
        raise ValueError(f"observe_one needs a single-episode simulator, this one has E={sim.E}")
    cfg = sim.config
    size = sim.size_km
    K = cfg.observation.neighbours
    rng_km = cfg.observation.range_km
    look = cfg.observation.lookahead_s
    los_km = sim.los_km
    M, B = sim.M, sim.B
    one = sim._one
    vc, level, own = one.vc, one.level, one.own
    N = sim.N

    # Relative positions of every aircraft and, in the last M columns, of the goals: the same
    # subtractions and magnitudes as observe() makes for the neighbours and for the goal.
    rp = one.pcg[None, :] - own[:, None]  # (M, N + M)
    dist = np.abs(rp)
    gd_l = [dist.item(m, N + m) for m in range(M)]  # |goal - own|
    for m in range(M):
        dist[m, B + m] = _INF  # not its own neighbour
    dist = np.where(one.active_all, dist, _INF)  # goals and aircraft not in the sky: inf

    # K nearest other aircraft (horizontal distance, any level), sorted as observe() sorts.
    near = np.argsort(dist[:, :N], axis=-1)[:, :K]  # (M, k)
    kk = near.shape[-1]
    pair = near + one.row_offset if M > 1 else near  # flat index into (M, N + M)
    nd = dist.take(pair).ravel().tolist()  # flat: row m, neighbour k at m * kk + k
    at = pair.ravel().tolist()
    for m in range(M):
        at.append(m * (N + M) + N + m)
    nrel = rp.take(at).tolist()  # neighbours row by row, then each row's goal
    nvel_a = vc.take(near) - one.own_v[:, None]
    rel_speed = np.abs(nvel_a).ravel().tolist()
    nvel = nvel_a.ravel().tolist()
    nlvl = level.take(near).ravel().tolist()
    trig = [sim._trig(h) for h in sim.ac_heading_deg[0].tolist()]
    # One complex product for both: neighbour * conj(relative velocity) (closest approach) and
    # goal * e^{i(h - 90°)} (goal bearing relative to the heading).
    other = [v.conjugate() for v in nvel]
    for tr in trig:
        other.append(tr[3])
    prod = (np.array(nrel) * np.array(other)).tolist()
    n = M * kk
    t, ends = [], []
    for i in range(n):
        s = rel_speed[i]
        ti = -prod[i].real / (s * s + 1e-300)
        ti = ti if ti > 0.0 else 0.0  # np.maximum / np.minimum, ties to the bound
        ti = ti if ti < look else look
        t.append(ti)
        ends.append(nrel[i] + nvel[i] * ti)
    d_cpa = np.abs(ends).tolist()

    xy = one.pos[B:].tolist()
    goal = sim.ac_goal_km[0].tolist()
    speed = sim.ac_speed_kt[0].tolist()
    own_level = level[B:].tolist()
    mid = 0.5 * (sim.min_speed_kt + sim.max_speed_kt)
    half = max(0.5 * (sim.max_speed_kt - sim.min_speed_kt), 1e-9)
    time = sim.steps.item(0) / sim.max_steps
    scale = 2.0 / size

    rows = []
    for m in range(M):
        x, y = xy[m]
        _, sin_h, cos_h, _ = trig[m]
        # numpy divides a complex by a real c as by c + 0i: scale 1 / c, both parts * scale
        z, g = prod[n + m], gd_l[m]
        inv = 1.0 / (g if g > 1e-9 else 1e-9)
        lv = own_level[m]
        row = [
            x * scale - 1.0,
            y * scale - 1.0,
            sin_h,
            cos_h,
            (speed[m] - mid) / half,
            lv - 1.0,
            (goal[m][0] - x) / size,
            (goal[m][1] - y) / size,
            g / size,
            -(z.imag * inv),
            z.real * inv,
            time,
        ]
        for i in range(m * kk, (m + 1) * kk):
            d = nd[i]
            if d == _INF:  # fewer than K other aircraft
                row += _ABSENT
                continue
            r, v, dc = nrel[i], nvel[i], d_cpa[i]
            dl = float(nlvl[i] - lv)
            row += (
                1.0,
                r.real / rng_km,
                r.imag / rng_km,
                v.real / _VEL_SCALE_KM_S,
                v.imag / _VEL_SCALE_KM_S,
                dl / 2.0,
                d / rng_km,
                t[i] / look,
                dc / rng_km,
                1.0 if dl == 0 and dc < los_km else 0.0,
            )
        row += _ABSENT * (K - kk)
        rows.append(row)
    out = np.array(rows)
    low, high = _bounds(cfg)
    return np.minimum(np.maximum(out, low, out=out), high, out=out).astype(np.float32)


_ABSENT = [0.0] * 10
_INF = float("inf")


_BOUNDS_CACHE: dict[int, tuple[NDArray[np.float32], NDArray[np.float32]]] = {}


def _bounds(cfg: ScenarioConfig) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    key = cfg.observation.neighbours
    if key not in _BOUNDS_CACHE:
        _BOUNDS_CACHE[key] = observation_bounds(cfg)
    return _BOUNDS_CACHE[key]
