"""The simulator's compiled loops (numba): closest approach, episode streams, reset, step, observe.

One implementation serves every batch size: the PettingZoo env is a batch of one, evaluation
and training step hundreds of episodes in lock-step through the same functions. Every loop runs
over episodes ``e``, controlled aircraft ``m`` and other aircraft ``n`` on flat arrays, so a step
costs the same few microseconds of call overhead at any batch size plus the arithmetic.

Arrays (``E`` episodes, ``B`` background slots, ``M`` controlled aircraft, ``N = B + M``;
background first, controlled last; km, km/s, knots, seconds):

=================  ============  =============================================================
name               shape         meaning
=================  ============  =============================================================
pos                (E, N, 2)     position (east, north), km
vel                (E, N, 2)     velocity (east, north), km/s
level              (E, N)        flight level index 0..2
active             (E, N)        in the sky
ac_dir             (E, M, 2)     unit heading vector (east, north) = (sin h, cos h)
ac_speed           (E, M)        commanded ground speed, kt
ac_goal            (E, M, 2)     goal position, km
ac_outcome         (E, M)        outcome code once finished, else 0 (int8)
steps              (E,)          steps elapsed
bg_arc             (E, R * C)    arc flown along its airway by each airway slot, km
route_last         (E, R)        arc flown by the newest aircraft of each airway, km
route_count        (E, R)        aircraft spawned on each airway (the next one's level: count % 3)
route_waiting      (E, R)        the airway's due spawn is held back by a controlled aircraft
=================  ============  =============================================================

Floating point (docs/model.md §12): only ``+ - * /`` and ``sqrt`` (correctly rounded by IEEE
754 on every CPU), no transcendental function, compiled without ``fastmath`` (no reassociation,
no fused multiply-add: ``tests/sim/test_kernels.py`` checks the machine code), so a step gives
the same bits on any x86-64 CPU whatever SIMD it has. Headings are unit vectors rotated by the
exact sine and cosine of the heading step (:func:`cdr_bench.sim.geometry.exact_unit_vector`).

Every function of the simulator that numba compiles lives in this one file: numba's cache is
invalidated per file, so a kernel calling a compiled function of another module could run stale
code after an edit.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

KM_PER_S_PER_KT = 1.852 / 3600.0
"""km/s in one knot (the same value as :data:`cdr_bench.sim.units.KM_PER_S_PER_KT`)."""

N_LEVELS = 3
HOLD = 13

# Outcome codes of a controlled aircraft (0 while it flies).
RUNNING, SUCCESS, NMAC, LOS, BOUNDARY, TIMEOUT = 0, 1, 2, 3, 4, 5

# Reward terms, in this order along the last axis of the step's ``terms`` array.
R_GOAL, R_PATH, R_BOUNDARY, R_STEP, R_TIMEOUT, R_LOS, R_NMAC = range(7)
N_TERMS = 7

# Step flags, along the last axis of the step's ``flags`` array.
F_ACTING, F_INVALID, F_OUTSIDE, F_REACHED, F_TERMINATED, F_TRUNCATED = range(6)
N_FLAGS = 6

# Float parameters (the ``fp`` array), see :meth:`cdr_bench.sim.core.Simulator.__init__`.
(
    P_DT,
    P_LOS,
    P_NMAC,
    P_GOAL_RADIUS,
    P_SIZE,
    P_TRAFFIC_STEP,
    P_SPAWN_CLEARANCE,
    P_TRAFFIC_SPEED,
    P_MIN_SPEED,
    P_MAX_SPEED,
    P_SPEED_STEP,
    P_TURN_COS,
    P_TURN_SIN,
    P_W_GOAL,
    P_W_PATH,
    P_W_BOUNDARY,
    P_W_STEP,
    P_W_TIMEOUT,
    P_W_LOS,
    P_W_NMAC,
    P_RANGE,
    P_LOOKAHEAD,
    P_GOAL_MARGIN,
    P_START_CLEARANCE,
    P_START_SPEED,
    P_LOS_TERMINATES,
    P_BOUNDARY_TERMINATES,
    P_MAX_STEPS,
) = range(28)
N_FLOAT_PARAMS = 28

# Explicit ownship start (the ``own_fixed`` array; ``has`` = 0 for a random start).
O_HAS, O_X, O_Y, O_DIR_X, O_DIR_Y, O_SPEED, O_LEVEL, O_GOAL_X, O_GOAL_Y = range(9)

VEL_SCALE_KM_S = 1000.0 * KM_PER_S_PER_KT
"""Velocity normalisation of the observation: 1000 kt in km/s."""


# ----------------------------------------------------------------------------------------------
# Geometry


@njit(cache=True, inline="always")
def closest_approach(
    px: float, py: float, vx: float, vy: float, horizon_s: float
) -> tuple[float, float]:
    """Closest approach of a relative straight motion over ``[0, horizon_s]``.

    Args:
        px, py: relative position at t = 0, km.
        vx, vy: relative velocity, km/s.
        horizon_s: end of the interval, s (>= 0).

    Returns:
        ``(d_min_km, t_min_s)``: the smallest distance over the interval and the time it is
        reached (0 for diverging or static pairs).
    """
    vv = vx * vx + vy * vy
    t = 0.0
    if vv > 0.0:
        t = -(px * vx + py * vy) / vv
        if t < 0.0:
            t = 0.0
        elif t > horizon_s:
            t = horizon_s
    dx = px + vx * t
    dy = py + vy * t
    return math.sqrt(dx * dx + dy * dy), t


# ----------------------------------------------------------------------------------------------
# Episode random streams (splitmix64): a fixed algorithm, so that an episode seed gives the same
# episode whatever the numpy version.

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_U30, _U27, _U31, _U11, _U53 = (np.uint64(k) for k in (30, 27, 31, 11, 53))
_TWO_M53 = 1.0 / 9007199254740992.0  # 2**-53


@njit(cache=True)
def _next_u64(state: np.ndarray) -> np.uint64:
    z = state[0] + _GOLDEN
    state[0] = z
    z = (z ^ (z >> _U30)) * _MIX1
    z = (z ^ (z >> _U27)) * _MIX2
    return z ^ (z >> _U31)


@njit(cache=True)
def _uniform(state: np.ndarray, lo: float, hi: float) -> float:
    """Uniform in [lo, hi): 53 random bits."""
    u = float(_next_u64(state) >> _U11) * _TWO_M53
    return lo + (hi - lo) * u


@njit(cache=True)
def _below(state: np.ndarray, n: int) -> int:
    """Uniform integer in 0..n-1 (n < 2**11): the top bits of a 53-bit draw times n."""
    return int(((_next_u64(state) >> _U11) * np.uint64(n)) >> _U53)


# ----------------------------------------------------------------------------------------------
# Reset


@njit(cache=True)
def _populate_traffic(
    e,
    rs,
    pos,
    vel,
    level,
    active,
    bg_arc,
    route_last,
    route_count,
    route_waiting,
    route_start,
    route_unit,
    route_len,
    spacing,
    per_route,
    C,
    x_pos,
    x_dir,
    x_speed,
    x_level,
    fp,
):
    """Steady state: each airway holds ``per_route`` aircraft one spacing apart, random phase;
    levels cyclic in spawn order. Then the explicitly placed aircraft."""
    R = route_start.shape[0]
    B = R * C + x_pos.shape[0]
    for b in range(B):
        active[e, b] = False
    for r in range(R):
        route_last[e, r] = _uniform(rs, 0.0, 1.0) * spacing[r]  # arc of the newest aircraft
    for r in range(R):
        route_count[e, r] = _below(rs, N_LEVELS) + 1  # the newest aircraft's level + 1
    speed = fp[P_TRAFFIC_SPEED]
    for r in range(R):
        newest_level = route_count[e, r] - 1
        route_waiting[e, r] = False
        for j in range(C):
            slot = r * C + j
            bg_arc[e, slot] = 0.0
            if j >= per_route:
                continue
            arc = route_last[e, r] + j * spacing[r]  # older aircraft spawned earlier
            bg_arc[e, slot] = arc
            pos[e, slot, 0] = route_start[r, 0] + arc * route_unit[r, 0]
            pos[e, slot, 1] = route_start[r, 1] + arc * route_unit[r, 1]
            vel[e, slot, 0] = route_unit[r, 0] * speed
            vel[e, slot, 1] = route_unit[r, 1] * speed
            level[e, slot] = (newest_level - j) % N_LEVELS
            active[e, slot] = arc < route_len[r]
    for i in range(x_pos.shape[0]):
        b = R * C + i
        pos[e, b, 0] = x_pos[i, 0]
        pos[e, b, 1] = x_pos[i, 1]
        vel[e, b, 0] = x_dir[i, 0] * x_speed[i]
        vel[e, b, 1] = x_dir[i, 1] * x_speed[i]
        level[e, b] = x_level[i]
        active[e, b] = True


@njit(cache=True)
def _clear_of_traffic(e, x, y, clearance, lv, pos, level, active, B):
    """No background aircraft (at level ``lv``, or any level when ``lv < 0``) closer than
    ``clearance`` km to (x, y)."""
    for b in range(B):
        if not active[e, b] or (lv >= 0 and level[e, b] != lv):
            continue
        dx = pos[e, b, 0] - x
        dy = pos[e, b, 1] - y
        if math.sqrt(dx * dx + dy * dy) < clearance:
            return False
    return True


@njit(cache=True)
def _place_controlled(
    e,
    rs,
    pos,
    level,
    active,
    ac_dir,
    ac_speed,
    ac_goal,
    B,
    li_start,
    li_goal,
    li_dir,
    own_fixed,
    fp,
):
    """Learning intruders at the entry of their airway on a level clear of traffic, then the
    ownship (explicit, or on the boundary clear of traffic heading for a random goal).
    False when no clear start was found (the caller redraws the traffic)."""
    clearance = fp[P_START_CLEARANCE]
    M = ac_dir.shape[1]
    perm = np.empty(N_LEVELS, dtype=np.int64)
    for k in range(1, M):
        sx, sy = li_start[k - 1, 0], li_start[k - 1, 1]
        for i in range(N_LEVELS):
            perm[i] = i
        for i in range(N_LEVELS - 1, 0, -1):  # Fisher-Yates
            j = _below(rs, i + 1)
            perm[i], perm[j] = perm[j], perm[i]
        near_placed = False
        for p in range(1, k):
            dx = sx - pos[e, B + p, 0]
            dy = sy - pos[e, B + p, 1]
            if math.sqrt(dx * dx + dy * dy) < clearance:
                near_placed = True
        found = -1
        if not near_placed:
            for i in range(N_LEVELS):
                if _clear_of_traffic(e, sx, sy, clearance, perm[i], pos, level, active, B):
                    found = perm[i]
                    break
        if found < 0:
            return False
        pos[e, B + k, 0], pos[e, B + k, 1] = sx, sy
        ac_dir[e, k, 0], ac_dir[e, k, 1] = li_dir[k - 1, 0], li_dir[k - 1, 1]
        ac_speed[e, k] = fp[P_START_SPEED]
        level[e, B + k] = found
        ac_goal[e, k, 0], ac_goal[e, k, 1] = li_goal[k - 1, 0], li_goal[k - 1, 1]

    if own_fixed[O_HAS] != 0.0:
        pos[e, B, 0], pos[e, B, 1] = own_fixed[O_X], own_fixed[O_Y]
        ac_dir[e, 0, 0], ac_dir[e, 0, 1] = own_fixed[O_DIR_X], own_fixed[O_DIR_Y]
        ac_speed[e, 0] = own_fixed[O_SPEED]
        level[e, B] = int(own_fixed[O_LEVEL])
        ac_goal[e, 0, 0], ac_goal[e, 0, 1] = own_fixed[O_GOAL_X], own_fixed[O_GOAL_Y]
        return True

    size = fp[P_SIZE]
    margin = fp[P_GOAL_MARGIN]
    gx = _uniform(rs, margin, size - margin)
    gy = _uniform(rs, margin, size - margin)
    own_level = _below(rs, N_LEVELS)
    n_candidates = 64
    perims = np.empty(n_candidates)
    for c in range(n_candidates):
        perims[c] = _uniform(rs, 0.0, 4.0 * size)
    for c in range(n_candidates):
        side = min(int(perims[c] // size), 3)
        u = perims[c] - side * size
        if side == 0:
            x, y = u, 0.0
        elif side == 1:
            x, y = size, u
        elif side == 2:
            x, y = size - u, size
        else:
            x, y = 0.0, size - u
        if not _clear_of_traffic(e, x, y, clearance, -1, pos, level, active, B):
            continue
        ok = True
        for p in range(1, M):
            dx = x - pos[e, B + p, 0]
            dy = y - pos[e, B + p, 1]
            if math.sqrt(dx * dx + dy * dy) < clearance:
                ok = False
        if not ok:
            continue
        pos[e, B, 0], pos[e, B, 1] = x, y
        dx, dy = gx - x, gy - y
        norm = math.sqrt(dx * dx + dy * dy)
        if norm > 0.0:
            ac_dir[e, 0, 0], ac_dir[e, 0, 1] = dx / norm, dy / norm
        else:
            ac_dir[e, 0, 0], ac_dir[e, 0, 1] = 0.0, 1.0
        ac_speed[e, 0] = fp[P_START_SPEED]
        level[e, B] = own_level
        ac_goal[e, 0, 0], ac_goal[e, 0, 1] = gx, gy
        return True
    return False


@njit(cache=True)
def reset_episodes(
    episodes,
    seeds,
    pos,
    vel,
    level,
    active,
    ac_dir,
    ac_speed,
    ac_goal,
    ac_outcome,
    steps,
    bg_arc,
    route_last,
    route_count,
    route_waiting,
    route_start,
    route_unit,
    route_len,
    spacing,
    per_route,
    C,
    x_pos,
    x_dir,
    x_speed,
    x_level,
    li_start,
    li_goal,
    li_dir,
    own_fixed,
    fp,
):
    """Start episode ``episodes[i]`` from ``seeds[i]`` (uint64) for every i.

    Returns -1, or the position ``i`` of the first episode for which no start with the
    required clearance was found in 200 draws of the traffic.
    """
    M = ac_dir.shape[1]
    B = pos.shape[1] - M
    rs = np.empty(1, dtype=np.uint64)
    for i in range(episodes.shape[0]):
        e = episodes[i]
        rs[0] = seeds[i]
        placed = False
        for _attempt in range(200):
            _populate_traffic(
                e,
                rs,
                pos,
                vel,
                level,
                active,
                bg_arc,
                route_last,
                route_count,
                route_waiting,
                route_start,
                route_unit,
                route_len,
                spacing,
                per_route,
                C,
                x_pos,
                x_dir,
                x_speed,
                x_level,
                fp,
            )
            if _place_controlled(
                e,
                rs,
                pos,
                level,
                active,
                ac_dir,
                ac_speed,
                ac_goal,
                B,
                li_start,
                li_goal,
                li_dir,
                own_fixed,
                fp,
            ):
                placed = True
                break
        if not placed:
            return i
        steps[e] = 0
        for m in range(M):
            ac_outcome[e, m] = RUNNING
            active[e, B + m] = True
            v = ac_speed[e, m] * KM_PER_S_PER_KT
            vel[e, B + m, 0] = ac_dir[e, m, 0] * v
            vel[e, B + m, 1] = ac_dir[e, m, 1] * v
    return -1


# ----------------------------------------------------------------------------------------------
# Step


@njit(cache=True)
def _spawn_traffic(
    e,
    pos,
    vel,
    level,
    active,
    bg_arc,
    route_last,
    route_count,
    route_waiting,
    route_start,
    route_unit,
    spacing,
    C,
    n_explicit,
    acting,
    fp,
):
    """A due airway spawn enters unless a controlled aircraft that flew this step is within the
    spawn clearance at the spawn level (it then waits, and enters at the airway start later)."""
    R = route_start.shape[0]
    M = acting.shape[0]
    B = R * C + n_explicit
    step_km = fp[P_TRAFFIC_STEP]
    speed = fp[P_TRAFFIC_SPEED]
    clearance = fp[P_SPAWN_CLEARANCE]
    for r in range(R):
        route_last[e, r] += step_km
        if route_last[e, r] < spacing[r]:
            continue
        arc = 0.0 if route_waiting[e, r] else route_last[e, r] - spacing[r]
        lv = route_count[e, r] % N_LEVELS
        x = route_start[r, 0] + arc * route_unit[r, 0]
        y = route_start[r, 1] + arc * route_unit[r, 1]
        blocked = False
        for m in range(M):
            if acting[m] and level[e, B + m] == lv:
                dx = x - pos[e, B + m, 0]
                dy = y - pos[e, B + m, 1]
                if math.sqrt(dx * dx + dy * dy) < clearance:
                    blocked = True
        route_waiting[e, r] = blocked
        if blocked:
            continue
        slot = -1
        for j in range(C):
            if not active[e, r * C + j]:
                slot = r * C + j
                break
        if slot < 0:  # pragma: no cover - capacity per_route + 2 suffices
            raise RuntimeError("airway slot capacity exceeded")
        active[e, slot] = True
        bg_arc[e, slot] = arc
        pos[e, slot, 0], pos[e, slot, 1] = x, y
        vel[e, slot, 0] = route_unit[r, 0] * speed
        vel[e, slot, 1] = route_unit[r, 1] * speed
        level[e, slot] = lv
        route_last[e, r] = arc
        route_count[e, r] += 1


@njit(cache=True)
def step_episodes(
    actions,
    pos,
    vel,
    level,
    active,
    ac_dir,
    ac_speed,
    ac_goal,
    ac_outcome,
    steps,
    bg_arc,
    route_last,
    route_count,
    route_waiting,
    route_start,
    route_unit,
    route_len_slot,
    spacing,
    C,
    n_explicit,
    fp,
    low,
    high,
    terms,
    flags,
    outcome,
    min_sep,
    events,
    reward,
    done,
    obs,
    masks,
):
    """Advance every episode by one step (docs/model.md §3-§6).

    Args:
        actions: (E, M) action indices 0..26 (validated by the caller); aircraft that are not
            flying hold.
        terms: (E, M, 7) out, the named reward terms of the step.
        flags: (E, M, 6) out, bool: acting, invalid action, outside, reached goal, terminated,
            truncated.
        outcome: (E, M) out, int8: the outcome code of an aircraft that finished this step.
        min_sep: (E, M) out, smallest swept distance to a same-level aircraft (inf if none).
        events: (2, E, M, N) out, bool, zero on entry: LoS with / NMAC with aircraft n.
        reward: (E, M) out, zero on entry: the sum of the terms.
        done: (E,) out, zero on entry: the episode's last aircraft finished this step.
        obs, masks: (E, M, F) float32 and (E, M, 27) int8 out: observations and action masks
            after the step (:func:`observe_episodes`; low, high: the observation bounds).

    Returns:
        The number of episodes done this step.
    """
    E, M = ac_dir.shape[0], ac_dir.shape[1]
    N = pos.shape[1]
    B = N - M
    dt = fp[P_DT]
    los_km, nmac_km = fp[P_LOS], fp[P_NMAC]
    size = fp[P_SIZE]
    turn_c, turn_s = fp[P_TURN_COS], fp[P_TURN_SIN]
    path_w = -fp[P_W_PATH] / (size * size)
    max_steps = int(fp[P_MAX_STEPS])
    new_level = np.empty(M, dtype=np.int64)
    acting = np.empty(M, dtype=np.bool_)
    n_los = np.empty(M, dtype=np.int64)
    n_nmac = np.empty(M, dtype=np.int64)
    occ = np.empty(M, dtype=np.int64)
    row = np.zeros(obs.shape[2])
    best_d = np.empty(max((obs.shape[2] - 12) // 10, 1))
    best_n = np.empty(best_d.shape[0], dtype=np.int64)
    n_done = 0
    for e in range(E):
        live = False
        for m in range(M):
            acting[m] = active[e, B + m]
            live |= acting[m]
            flags[e, m, F_ACTING] = acting[m]
            min_sep[e, m] = np.inf
            new_level[m] = level[e, B + m]
        if not live:
            _observe_episode(
                e,
                obs,
                masks,
                pos,
                vel,
                level,
                active,
                ac_dir,
                ac_speed,
                ac_goal,
                steps,
                fp,
                low,
                high,
                row,
                best_d,
                best_n,
            )
            continue

        # 1. Apply the actions at the start of the step: turn, clipped speed, target level.
        for m in range(M):
            if not acting[m]:
                continue
            a = actions[e, m]
            a_psi = a // 9 - 1
            a_v = (a // 3) % 3 - 1
            a_h = a % 3 - 1
            target = level[e, B + m] + a_h
            if target < 0 or target >= N_LEVELS:
                flags[e, m, F_INVALID] = True  # masked: the level change is not executed
            else:
                new_level[m] = target
            if a_psi != 0:  # rotate the heading vector clockwise by a_psi heading steps
                s = turn_s * a_psi
                ux, uy = ac_dir[e, m, 0], ac_dir[e, m, 1]
                rx = ux * turn_c + uy * s
                ry = uy * turn_c - ux * s
                norm = math.sqrt(rx * rx + ry * ry)
                ac_dir[e, m, 0], ac_dir[e, m, 1] = rx / norm, ry / norm
            sp = ac_speed[e, m] + a_v * fp[P_SPEED_STEP]
            ac_speed[e, m] = min(max(sp, fp[P_MIN_SPEED]), fp[P_MAX_SPEED])
            v = ac_speed[e, m] * KM_PER_S_PER_KT
            vel[e, B + m, 0] = ac_dir[e, m, 0] * v
            vel[e, B + m, 1] = ac_dir[e, m, 1] * v

        # 2. Swept separation over [0, dt] against every aircraft in the sky; a level change
        #    occupies the old and the new level for the step.
        for m in range(M):
            occ[m] = ((1 << level[e, B + m]) | (1 << new_level[m])) if acting[m] else 0
        for m in range(M):
            n_los[m] = 0
            n_nmac[m] = 0
            if not acting[m]:
                continue
            i = B + m
            occ_m = occ[m]
            px, py = pos[e, i, 0], pos[e, i, 1]
            vx, vy = vel[e, i, 0], vel[e, i, 1]
            best = np.inf  # locals, not array elements: kept in registers
            n_l = 0
            n_n = 0
            for n in range(N):
                if n == i or not active[e, n]:
                    continue
                occ_n = (1 << level[e, n]) if n < B else occ[n - B]
                if occ_m & occ_n == 0:
                    continue
                d, _ = closest_approach(
                    pos[e, n, 0] - px, pos[e, n, 1] - py, vel[e, n, 0] - vx, vel[e, n, 1] - vy, dt
                )
                if d < best:
                    best = d
                if d < los_km:  # an NMAC (d < nmac_km < los_km) is also a LoS
                    events[0, e, m, n] = True
                    n_l += 1
                    if d < nmac_km:
                        events[1, e, m, n] = True
                        n_n += 1
            min_sep[e, m] = best
            n_los[m] = n_l
            n_nmac[m] = n_n

        # 4. Move the background (every slot: one not in the sky is placed again when it
        #    spawns); airway aircraft leave at the end of their airway, explicit ones at the
        #    sector edge.
        n_airway = bg_arc.shape[1]
        step_km = fp[P_TRAFFIC_STEP]
        for n in range(B):
            x = pos[e, n, 0] + vel[e, n, 0] * dt
            y = pos[e, n, 1] + vel[e, n, 1] * dt
            pos[e, n, 0] = x
            pos[e, n, 1] = y
            if n < n_airway:
                arc = bg_arc[e, n] + step_km
                bg_arc[e, n] = arc
                if arc >= route_len_slot[n]:
                    active[e, n] = False
            elif x < 0.0 or x > size or y < 0.0 or y > size:
                active[e, n] = False

        # 3. Swept goal test: the goal is a fixed point.
        for m in range(M):
            if acting[m]:
                i = B + m
                d, _ = closest_approach(
                    ac_goal[e, m, 0] - pos[e, i, 0],
                    ac_goal[e, m, 1] - pos[e, i, 1],
                    -vel[e, i, 0],
                    -vel[e, i, 1],
                    dt,
                )
                flags[e, m, F_REACHED] = d < fp[P_GOAL_RADIUS]

        # 4. Move the controlled aircraft (a controlled aircraft that has left has zero
        #    velocity); due airway spawns enter.
        for n in range(B, N):
            pos[e, n, 0] += vel[e, n, 0] * dt
            pos[e, n, 1] += vel[e, n, 1] * dt
        for m in range(M):
            level[e, B + m] = new_level[m]
        steps[e] += 1
        _spawn_traffic(
            e,
            pos,
            vel,
            level,
            active,
            bg_arc,
            route_last,
            route_count,
            route_waiting,
            route_start,
            route_unit,
            spacing,
            C,
            n_explicit,
            acting,
            fp,
        )

        # 5. Outcomes (priority nmac > los > boundary > success) and named rewards.
        for m in range(M):
            if not acting[m]:
                continue
            i = B + m
            x, y = pos[e, i, 0], pos[e, i, 1]
            out = x < 0.0 or x > size or y < 0.0 or y > size
            code = SUCCESS if flags[e, m, F_REACHED] else RUNNING
            if out and fp[P_BOUNDARY_TERMINATES] != 0.0:
                code = BOUNDARY
            if n_los[m] > 0 and fp[P_LOS_TERMINATES] != 0.0:
                code = LOS
            if n_nmac[m] > 0:
                code = NMAC
            term = code != RUNNING
            trunc = not term and steps[e] >= max_steps
            if trunc:
                code = TIMEOUT
            gx = ac_goal[e, m, 0] - x
            gy = ac_goal[e, m, 1] - y
            terms[e, m, R_GOAL] = fp[P_W_GOAL] if code == SUCCESS else 0.0
            terms[e, m, R_PATH] = path_w * (gx * gx + gy * gy)
            terms[e, m, R_BOUNDARY] = -fp[P_W_BOUNDARY] if out else 0.0
            terms[e, m, R_STEP] = -fp[P_W_STEP]
            terms[e, m, R_TIMEOUT] = -fp[P_W_TIMEOUT] if trunc else 0.0
            terms[e, m, R_LOS] = -fp[P_W_LOS] * (n_los[m] - n_nmac[m])
            terms[e, m, R_NMAC] = -fp[P_W_NMAC] * n_nmac[m]
            flags[e, m, F_OUTSIDE] = out
            flags[e, m, F_TERMINATED] = term
            flags[e, m, F_TRUNCATED] = trunc
            outcome[e, m] = code
            if term or trunc:
                ac_outcome[e, m] = code
                active[e, i] = False
                vel[e, i, 0] = 0.0
                vel[e, i, 1] = 0.0
            total = 0.0
            for t in range(N_TERMS):
                total += terms[e, m, t]
            reward[e, m] = total
        still = False
        for m in range(M):
            still |= active[e, B + m]
        if not still:
            done[e] = True
            n_done += 1
        _observe_episode(
            e,
            obs,
            masks,
            pos,
            vel,
            level,
            active,
            ac_dir,
            ac_speed,
            ac_goal,
            steps,
            fp,
            low,
            high,
            row,
            best_d,
            best_n,
        )
    return n_done


# ----------------------------------------------------------------------------------------------
# Observe


@njit(cache=True)
def observe_episodes(
    episodes, out, masks, pos, vel, level, active, ac_dir, ac_speed, ac_goal, steps, fp, low, high
):
    """Observations (E, M, F) float32 and action masks (E, M, 27) int8 of every controlled
    aircraft of episodes ``episodes``, written into ``out`` and ``masks``; the layout is
    :mod:`cdr_bench.sim.observation`'s table.

    Neighbours are the K nearest other aircraft in the sky (horizontal distance, any level;
    ties to the lower index); empty slots are zero. Every value is clipped to [low, high].
    """
    row = np.zeros(out.shape[2])
    best_d = np.empty(max((out.shape[2] - 12) // 10, 1))
    best_n = np.empty(best_d.shape[0], dtype=np.int64)
    for ie in range(episodes.shape[0]):
        _observe_episode(
            episodes[ie],
            out,
            masks,
            pos,
            vel,
            level,
            active,
            ac_dir,
            ac_speed,
            ac_goal,
            steps,
            fp,
            low,
            high,
            row,
            best_d,
            best_n,
        )


@njit(cache=True)
def _observe_episode(
    e,
    out,
    masks,
    pos,
    vel,
    level,
    active,
    ac_dir,
    ac_speed,
    ac_goal,
    steps,
    fp,
    low,
    high,
    row,
    best_d,
    best_n,
):
    """:func:`observe_episodes` of episode ``e`` (``row``, ``best_*``: scratch space)."""
    M = ac_dir.shape[1]
    N = pos.shape[1]
    B = N - M
    F = out.shape[2]
    K = (F - 12) // 10
    size = fp[P_SIZE]
    rng_km = fp[P_RANGE]
    look = fp[P_LOOKAHEAD]
    los_km = fp[P_LOS]
    lo_v, hi_v = fp[P_MIN_SPEED], fp[P_MAX_SPEED]
    mid = 0.5 * (lo_v + hi_v)
    half = max(0.5 * (hi_v - lo_v), 1e-9)
    inv_steps = 1.0 / fp[P_MAX_STEPS]
    for m in range(M):
        i = B + m
        x, y = pos[e, i, 0], pos[e, i, 1]
        ux, uy = ac_dir[e, m, 0], ac_dir[e, m, 1]
        gx = ac_goal[e, m, 0] - x
        gy = ac_goal[e, m, 1] - y
        gd = math.sqrt(gx * gx + gy * gy)
        inv_gd = 1.0 / max(gd, 1e-9)
        row[0] = x * (2.0 / size) - 1.0
        row[1] = y * (2.0 / size) - 1.0
        row[2] = ux  # sin(heading)
        row[3] = uy  # cos(heading)
        row[4] = (ac_speed[e, m] - mid) / half
        row[5] = level[e, i] - 1.0
        row[6] = gx / size
        row[7] = gy / size
        row[8] = gd / size
        row[9] = (gx * uy - gy * ux) * inv_gd  # sin(bearing - heading): + goal to the right
        row[10] = (gx * ux + gy * uy) * inv_gd  # cos(bearing - heading)
        row[11] = steps[e] * inv_steps

        # K nearest others by insertion on squared distances (strict <: the lower index
        # wins a tie); the square root is taken for the K chosen only.
        found = 0
        for n in range(N):
            if n == i or not active[e, n]:
                continue
            dx = pos[e, n, 0] - x
            dy = pos[e, n, 1] - y
            d = dx * dx + dy * dy
            if found < K:
                j = found
                found += 1
            elif d < best_d[K - 1]:
                j = K - 1
            else:
                continue
            while j > 0 and d < best_d[j - 1]:
                best_d[j] = best_d[j - 1]
                best_n[j] = best_n[j - 1]
                j -= 1
            best_d[j] = d
            best_n[j] = n
        for k in range(K):
            base = 12 + 10 * k
            if k >= found:
                for f in range(10):
                    row[base + f] = 0.0
                continue
            n = best_n[k]
            px = pos[e, n, 0] - x
            py = pos[e, n, 1] - y
            vx = vel[e, n, 0] - vel[e, i, 0]
            vy = vel[e, n, 1] - vel[e, i, 1]
            dlevel = float(level[e, n] - level[e, i])
            d_cpa, t_cpa = closest_approach(px, py, vx, vy, look)
            row[base] = 1.0
            row[base + 1] = px / rng_km
            row[base + 2] = py / rng_km
            row[base + 3] = vx / VEL_SCALE_KM_S
            row[base + 4] = vy / VEL_SCALE_KM_S
            row[base + 5] = dlevel / 2.0
            row[base + 6] = math.sqrt(best_d[k]) / rng_km
            row[base + 7] = t_cpa / look
            row[base + 8] = d_cpa / rng_km
            row[base + 9] = 1.0 if dlevel == 0.0 and d_cpa < los_km else 0.0
        for f in range(F):
            out[e, m, f] = min(max(row[f], low[f]), high[f])
        lv = level[e, i]
        for a in range(27):
            a_h = a % 3 - 1
            masks[e, m, a] = 0 <= lv + a_h < N_LEVELS
