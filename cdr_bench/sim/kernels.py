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
from typing import NamedTuple

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
    P_BOUNDARY_MARGIN,
    P_MAX_STEPS,
    P_SPAWN,
    P_CONTROLLED_SPAWNS,
) = range(30)
N_FLOAT_PARAMS = 30

# Explicit ownship start (the ``own_fixed`` array; ``has`` = 0 for a random start).
O_HAS, O_X, O_Y, O_DIR_X, O_DIR_Y, O_SPEED, O_LEVEL, O_GOAL_X, O_GOAL_Y = range(9)

# Encounter of an explicit aircraft (a row of the ``x_enc`` array; ``has`` = 0 for a fixed one):
# [lo, hi] of the time to CPA (s), the angle to the ownship's heading (deg), the signed miss
# distance (km) and the speed (kt), and whether it may be mirrored.
(
    X_HAS,
    X_T_LO,
    X_T_HI,
    X_A_LO,
    X_A_HI,
    X_M_LO,
    X_M_HI,
    X_S_LO,
    X_S_HI,
    X_MIRROR,
) = range(10)
N_ENC_PARAMS = 10

VEL_SCALE_KM_S = 1000.0 * KM_PER_S_PER_KT
"""Velocity normalisation of the observation: 1000 kt in km/s."""


class State(NamedTuple):
    """The state arrays of a batch of episodes (the table above); the kernels write them."""

    pos: np.ndarray
    vel: np.ndarray
    level: np.ndarray
    active: np.ndarray
    ac_dir: np.ndarray
    ac_speed: np.ndarray
    ac_goal: np.ndarray
    ac_outcome: np.ndarray
    steps: np.ndarray
    bg_arc: np.ndarray
    route_last: np.ndarray
    route_count: np.ndarray
    route_waiting: np.ndarray


class Constants(NamedTuple):
    """What a scenario fixes, as the kernels read it."""

    fp: np.ndarray
    """float parameters, indices ``P_*``"""
    low: np.ndarray
    """(F,) lower observation bounds"""
    high: np.ndarray
    """(F,) upper observation bounds"""
    route_start: np.ndarray
    """(R, 2) airway entry points, km"""
    route_unit: np.ndarray
    """(R, 2) airway directions"""
    route_len: np.ndarray
    """(R,) airway lengths, km"""
    route_len_slot: np.ndarray
    """(R * C,) the length of each slot's airway, km"""
    route_end: np.ndarray
    """(R, 2) airway exit points, km (the goals of controlled airway aircraft)"""
    spacing: np.ndarray
    """(R,) arc between successive aircraft of an airway, km"""
    x_pos: np.ndarray
    """(X, 2) explicit aircraft: start positions, km"""
    x_dir: np.ndarray
    """(X, 2) their heading vectors"""
    x_speed: np.ndarray
    """(X,) their speeds, km/s"""
    x_level: np.ndarray
    """(X,) their levels"""
    x_enc: np.ndarray
    """(X, 10) their encounters, indices ``X_*`` (``X_HAS`` = 0: the fixed values above)"""
    x_enc_level: np.ndarray
    """(X, 4) the levels an encounter draws from: count, then the levels"""
    li_start: np.ndarray
    """(L, 2) the L learning intruders: starts (their airway's entry), km"""
    li_goal: np.ndarray
    """(L, 2) their goals (their airway's exit), km"""
    li_dir: np.ndarray
    """(L, 2) their heading vectors"""
    li_enc: np.ndarray
    """(L, 10) a learning intruder placed by an encounter with the ownship instead (indices
    ``X_*``; ``X_HAS`` = 0: on its airway, the three rows above)"""
    li_enc_level: np.ndarray
    """(L, 4) the levels its encounter draws from: count, then the levels"""
    own_fixed: np.ndarray
    """(9,) an explicit ownship start, indices ``O_*``"""
    per_route: int
    """aircraft per airway in steady state"""
    C: int
    """slots per airway"""


class StepOutput(NamedTuple):
    """The arrays one step writes (see :func:`step_episodes`)."""

    terms: np.ndarray
    flags: np.ndarray
    outcome: np.ndarray
    min_sep: np.ndarray
    events: np.ndarray
    reward: np.ndarray
    done: np.ndarray
    obs: np.ndarray
    masks: np.ndarray


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


# Sine and cosine of an angle in degrees from + - * / only (the angles of encounters, drawn per
# episode): the angle is reduced to [-45, 45] degrees around a multiple of 90, and Taylor
# series to x^17 / x^18 (terms below 1e-19 left out) are summed by Horner's rule in a fixed
# order. Within 2 ulp of sin and cos, and the same bits on every CPU.
_DEG = 3.141592653589793 / 180.0
_S3, _S5, _S7, _S9 = -1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0, 1.0 / 362880.0
_S11, _S13 = -1.0 / 39916800.0, 1.0 / 6227020800.0
_S15, _S17 = -1.0 / 1307674368000.0, 1.0 / 355687428096000.0
_C2, _C4, _C6, _C8 = -0.5, 1.0 / 24.0, -1.0 / 720.0, 1.0 / 40320.0
_C10, _C12 = -1.0 / 3628800.0, 1.0 / 479001600.0
_C14, _C16 = -1.0 / 87178291200.0, 1.0 / 20922789888000.0
_C18 = -1.0 / 6402373705728000.0
_SIN = (_S17, _S15, _S13, _S11, _S9, _S7, _S5, _S3)  # sin x = x + x (x^2 p(x^2)), highest first
_COS = (_C18, _C16, _C14, _C12, _C10, _C8, _C6, _C4, _C2, 1.0)  # cos x = q(x^2), highest first


@njit(cache=True)
def _horner(coefs, x2):
    """The polynomial in ``x2`` with coefficients ``coefs`` (highest power first) by Horner's
    rule: ``coefs[i] + x2 * (...)`` from the highest power down."""
    acc = coefs[0]
    for i in range(1, len(coefs)):
        acc = coefs[i] + x2 * acc
    return acc


@njit(cache=True)
def sin_cos_deg(angle_deg):
    """(sin, cos) of ``angle_deg`` in [-720, 720] degrees (see the comment above)."""
    k = int(angle_deg / 90.0 + 8.5) - 8  # nearest multiple of 90 degrees (truncation >= 0)
    x = (angle_deg - 90.0 * k) * _DEG
    x2 = x * x
    sn = x + x * (x2 * _horner(_SIN, x2))
    cs = _horner(_COS, x2)
    q = (k + 8) % 4
    if q == 0:
        return sn, cs
    if q == 1:
        return cs, -sn
    if q == 2:
        return -sn, -cs
    return -cs, sn


# ----------------------------------------------------------------------------------------------
# Reset


@njit(cache=True, inline="always")
def _draw_encounter(rs, c, enc, enc_level):
    """An aircraft placed by its encounter (``enc``, ``enc_level``: a row of ``x_enc`` and
    ``x_enc_level``, or of ``li_enc`` and ``li_enc_level``) with the ownship's straight flight
    (docs/model.md §8.3). Six draws, always in this order: time to CPA, angle, miss distance,
    speed, level, mirror. Returns its start (x, y) km, velocity (vx, vy) km/s, level, time to
    CPA (s) and speed (kt)."""
    t = _uniform(rs, enc[X_T_LO], enc[X_T_HI])
    angle = _uniform(rs, enc[X_A_LO], enc[X_A_HI])
    miss = _uniform(rs, enc[X_M_LO], enc[X_M_HI])
    speed_kt = _uniform(rs, enc[X_S_LO], enc[X_S_HI])
    speed = speed_kt * KM_PER_S_PER_KT
    level = enc_level[1 + _below(rs, enc_level[0])]
    flip = _below(rs, 2)
    if enc[X_MIRROR] != 0.0 and flip == 1:
        angle = -angle
        miss = -miss
    ux, uy = c.own_fixed[O_DIR_X], c.own_fixed[O_DIR_Y]  # the ownship's heading vector
    v0 = c.own_fixed[O_SPEED] * KM_PER_S_PER_KT
    sa, ca = sin_cos_deg(angle)
    dx = ux * ca + uy * sa  # the heading rotated clockwise by the angle
    dy = uy * ca - ux * sa
    vx, vy = dx * speed, dy * speed
    wx, wy = vx - ux * v0, vy - uy * v0  # velocity relative to the ownship
    ww = math.sqrt(wx * wx + wy * wy)
    rx, ry = uy, -ux  # the ownship's right
    nx, ny = rx, ry  # no relative motion: the miss is measured to the right
    if ww > 1e-12:
        nx, ny = wy / ww, -wx / ww  # across the relative motion, to the ownship's right
        side = nx * rx + ny * ry
        if side < 0.0 or (side == 0.0 and nx * ux + ny * uy < 0.0):
            nx, ny = -nx, -ny
    # At time t the ownship is at start + v0 t and this aircraft ``miss`` across from it.
    cx = c.own_fixed[O_X] + ux * v0 * t + miss * nx
    cy = c.own_fixed[O_Y] + uy * v0 * t + miss * ny
    return cx - vx * t, cy - vy * t, vx, vy, level, t, speed_kt, dx, dy


@njit(cache=True)
def _place_encounter(e, rs, s, c, i, b):
    """Explicit aircraft ``i`` (background slot ``b``) by its encounter with the ownship's
    straight flight (:func:`_draw_encounter`)."""
    x, y, vx, vy, level, _, _, _, _ = _draw_encounter(rs, c, c.x_enc[i], c.x_enc_level[i])
    s.pos[e, b, 0] = x
    s.pos[e, b, 1] = y
    s.vel[e, b, 0] = vx
    s.vel[e, b, 1] = vy
    s.level[e, b] = level
    s.active[e, b] = True


@njit(cache=True)
def _populate_traffic(e, rs, s, c):
    """Steady state: each airway holds ``per_route`` aircraft one spacing apart, random phase;
    levels cyclic in spawn order. Then the explicitly placed aircraft, in their order (an
    encounter draws its geometry; a fixed aircraft draws nothing)."""
    R = c.route_start.shape[0]
    B = R * c.C + c.x_pos.shape[0]
    for b in range(B):
        s.active[e, b] = False
    for r in range(R):
        s.route_last[e, r] = _uniform(rs, 0.0, 1.0) * c.spacing[r]  # arc of the newest aircraft
    for r in range(R):
        s.route_count[e, r] = _below(rs, N_LEVELS) + 1  # the newest aircraft's level + 1
    speed = c.fp[P_TRAFFIC_SPEED]
    for r in range(R):
        newest_level = s.route_count[e, r] - 1
        s.route_waiting[e, r] = False
        for j in range(c.C):
            slot = r * c.C + j
            s.bg_arc[e, slot] = 0.0
            if j >= c.per_route:
                continue
            arc = s.route_last[e, r] + j * c.spacing[r]  # older aircraft spawned earlier
            s.bg_arc[e, slot] = arc
            s.pos[e, slot, 0] = c.route_start[r, 0] + arc * c.route_unit[r, 0]
            s.pos[e, slot, 1] = c.route_start[r, 1] + arc * c.route_unit[r, 1]
            s.vel[e, slot, 0] = c.route_unit[r, 0] * speed
            s.vel[e, slot, 1] = c.route_unit[r, 1] * speed
            s.level[e, slot] = (newest_level - j) % N_LEVELS
            s.active[e, slot] = arc < c.route_len[r]
    for i in range(c.x_pos.shape[0]):
        b = R * c.C + i
        if c.x_enc[i, X_HAS] != 0.0:
            _place_encounter(e, rs, s, c, i, b)
            continue
        s.pos[e, b, 0] = c.x_pos[i, 0]
        s.pos[e, b, 1] = c.x_pos[i, 1]
        s.vel[e, b, 0] = c.x_dir[i, 0] * c.x_speed[i]
        s.vel[e, b, 1] = c.x_dir[i, 1] * c.x_speed[i]
        s.level[e, b] = c.x_level[i]
        s.active[e, b] = True


@njit(cache=True)
def _clear_of_traffic(e, x, y, clearance, lv, s, B):
    """No background aircraft (at level ``lv``, or any level when ``lv < 0``) closer than
    ``clearance`` km to (x, y)."""
    for b in range(B):
        if not s.active[e, b] or (lv >= 0 and s.level[e, b] != lv):
            continue
        dx = s.pos[e, b, 0] - x
        dy = s.pos[e, b, 1] - y
        if math.sqrt(dx * dx + dy * dy) < clearance:
            return False
    return True


@njit(cache=True)
def _near_controlled(e, x, y, clearance, s, B, upto):
    """A learning intruder 1..upto-1 already placed closer than ``clearance`` km to (x, y)."""
    for p in range(1, upto):
        dx = x - s.pos[e, B + p, 0]
        dy = y - s.pos[e, B + p, 1]
        if math.sqrt(dx * dx + dy * dy) < clearance:
            return True
    return False


@njit(cache=True)
def _control_traffic(e, rs, s, c, B, first, M):
    """Controlled aircraft ``first..M-1`` take over airway aircraft of the steady state: a
    uniform draw of ``M - first`` of the ``per_route`` aircraft of every airway (partial
    Fisher-Yates over the slots in route order, one draw per aircraft; none when there are
    none to place). Each keeps its position and level, flies along its airway at the start
    speed with the airway's exit as its goal, and its background slot leaves the sky. False
    when fewer airway aircraft are in the sky than are to be controlled."""
    T = M - first
    if T <= 0:
        return True
    R = c.route_start.shape[0]
    cand = np.empty(R * c.per_route, dtype=np.int64)
    n = 0
    for r in range(R):
        for j in range(c.per_route):
            if s.active[e, r * c.C + j]:
                cand[n] = r * c.C + j
                n += 1
    if n < T:
        return False
    for i in range(T):
        j = i + _below(rs, n - i)
        cand[i], cand[j] = cand[j], cand[i]
        slot = cand[i]
        r = slot // c.C
        m = first + i
        s.pos[e, B + m, 0], s.pos[e, B + m, 1] = s.pos[e, slot, 0], s.pos[e, slot, 1]
        s.ac_dir[e, m, 0], s.ac_dir[e, m, 1] = c.route_unit[r, 0], c.route_unit[r, 1]
        s.ac_speed[e, m] = c.fp[P_START_SPEED]
        s.level[e, B + m] = s.level[e, slot]
        s.ac_goal[e, m, 0], s.ac_goal[e, m, 1] = c.route_end[r, 0], c.route_end[r, 1]
        s.active[e, slot] = False
    return True


@njit(cache=True)
def _place_controlled(e, rs, s, c, B):
    """Learning intruders at the entry of their airway on a level clear of traffic, then the
    controlled airway aircraft (:func:`_control_traffic`), then the ownship (explicit, or on
    the boundary clear of traffic and of every controlled aircraft, heading for a random goal).
    False when no clear start was found (the caller redraws the traffic)."""
    clearance = c.fp[P_START_CLEARANCE]
    M = s.ac_dir.shape[1] - int(c.fp[P_CONTROLLED_SPAWNS])  # those in the sky at the start
    perm = np.empty(N_LEVELS, dtype=np.int64)
    for k in range(1, 1 + c.li_start.shape[0]):
        if c.li_enc[k - 1, X_HAS] != 0.0:
            # By its encounter with the ownship's straight flight; its goal lies on its track
            # as far past the encounter as it starts before it (twice the time to CPA). A start
            # within the start clearance of the ownship's at its level: draw again.
            x, y, vx, vy, lv, t, speed_kt, dx, dy = _draw_encounter(
                rs, c, c.li_enc[k - 1], c.li_enc_level[k - 1]
            )
            if lv == int(c.own_fixed[O_LEVEL]):
                ox, oy = x - c.own_fixed[O_X], y - c.own_fixed[O_Y]
                if math.sqrt(ox * ox + oy * oy) < clearance:
                    return False
            for p in range(1, k):  # the learning intruders placed before it, at its level
                if s.level[e, B + p] == lv:
                    px, py = x - s.pos[e, B + p, 0], y - s.pos[e, B + p, 1]
                    if math.sqrt(px * px + py * py) < clearance:
                        return False
            s.pos[e, B + k, 0], s.pos[e, B + k, 1] = x, y
            s.ac_dir[e, k, 0], s.ac_dir[e, k, 1] = dx, dy
            s.ac_speed[e, k] = speed_kt
            s.level[e, B + k] = lv
            s.ac_goal[e, k, 0] = x + vx * (2.0 * t)
            s.ac_goal[e, k, 1] = y + vy * (2.0 * t)
            continue
        sx, sy = c.li_start[k - 1, 0], c.li_start[k - 1, 1]
        for i in range(N_LEVELS):
            perm[i] = i
        for i in range(N_LEVELS - 1, 0, -1):  # Fisher-Yates
            j = _below(rs, i + 1)
            perm[i], perm[j] = perm[j], perm[i]
        found = -1
        if not _near_controlled(e, sx, sy, clearance, s, B, k):
            for i in range(N_LEVELS):
                if _clear_of_traffic(e, sx, sy, clearance, perm[i], s, B):
                    found = perm[i]
                    break
        if found < 0:
            return False
        s.pos[e, B + k, 0], s.pos[e, B + k, 1] = sx, sy
        s.ac_dir[e, k, 0], s.ac_dir[e, k, 1] = c.li_dir[k - 1, 0], c.li_dir[k - 1, 1]
        s.ac_speed[e, k] = c.fp[P_START_SPEED]
        s.level[e, B + k] = found
        s.ac_goal[e, k, 0], s.ac_goal[e, k, 1] = c.li_goal[k - 1, 0], c.li_goal[k - 1, 1]

    if not _control_traffic(e, rs, s, c, B, 1 + c.li_start.shape[0], M):
        return False

    if c.own_fixed[O_HAS] != 0.0:
        s.pos[e, B, 0], s.pos[e, B, 1] = c.own_fixed[O_X], c.own_fixed[O_Y]
        s.ac_dir[e, 0, 0], s.ac_dir[e, 0, 1] = c.own_fixed[O_DIR_X], c.own_fixed[O_DIR_Y]
        s.ac_speed[e, 0] = c.own_fixed[O_SPEED]
        s.level[e, B] = int(c.own_fixed[O_LEVEL])
        s.ac_goal[e, 0, 0], s.ac_goal[e, 0, 1] = c.own_fixed[O_GOAL_X], c.own_fixed[O_GOAL_Y]
        # An encounter drawn within the start clearance at the ownship's level: draw again.
        X = c.x_pos.shape[0]
        for i in range(X):
            b = B - X + i
            if c.x_enc[i, X_HAS] != 0.0 and s.level[e, b] == s.level[e, B]:
                dx = s.pos[e, b, 0] - c.own_fixed[O_X]
                dy = s.pos[e, b, 1] - c.own_fixed[O_Y]
                if math.sqrt(dx * dx + dy * dy) < clearance:
                    return False
        return True

    size = c.fp[P_SIZE]
    margin = c.fp[P_GOAL_MARGIN]
    gx = _uniform(rs, margin, size - margin)
    gy = _uniform(rs, margin, size - margin)
    own_level = _below(rs, N_LEVELS)
    n_candidates = 64
    perims = np.empty(n_candidates)
    for q in range(n_candidates):
        perims[q] = _uniform(rs, 0.0, 4.0 * size)
    for q in range(n_candidates):
        side = min(int(perims[q] // size), 3)
        u = perims[q] - side * size
        if side == 0:
            x, y = u, 0.0
        elif side == 1:
            x, y = size, u
        elif side == 2:
            x, y = size - u, size
        else:
            x, y = 0.0, size - u
        if not _clear_of_traffic(e, x, y, clearance, -1, s, B):
            continue
        if _near_controlled(e, x, y, clearance, s, B, M):
            continue
        s.pos[e, B, 0], s.pos[e, B, 1] = x, y
        dx, dy = gx - x, gy - y
        norm = math.sqrt(dx * dx + dy * dy)
        if norm > 0.0:
            s.ac_dir[e, 0, 0], s.ac_dir[e, 0, 1] = dx / norm, dy / norm
        else:
            s.ac_dir[e, 0, 0], s.ac_dir[e, 0, 1] = 0.0, 1.0
        s.ac_speed[e, 0] = c.fp[P_START_SPEED]
        s.level[e, B] = own_level
        s.ac_goal[e, 0, 0], s.ac_goal[e, 0, 1] = gx, gy
        return True
    return False


@njit(cache=True)
def reset_episodes(episodes, seeds, s, c):
    """Start episode ``episodes[i]`` from ``seeds[i]`` (uint64) for every i.

    Returns -1, or the position ``i`` of the first episode for which no start with the
    required clearance was found in 200 draws of the traffic.
    """
    M = s.ac_dir.shape[1]
    B = s.pos.shape[1] - M
    rs = np.empty(1, dtype=np.uint64)
    for i in range(episodes.shape[0]):
        e = episodes[i]
        rs[0] = seeds[i]
        placed = False
        for _attempt in range(200):
            _populate_traffic(e, rs, s, c)
            if _place_controlled(e, rs, s, c, B):
                placed = True
                break
        if not placed:
            return i
        s.steps[e] = 0
        first_spawn = M - int(c.fp[P_CONTROLLED_SPAWNS])
        for m in range(M):
            s.ac_outcome[e, m] = RUNNING
            if m >= first_spawn:  # enters when an airway spawns it (_spawn_traffic)
                _clear_controlled(e, s, B, m)
                continue
            s.active[e, B + m] = True
            v = s.ac_speed[e, m] * KM_PER_S_PER_KT
            s.vel[e, B + m, 0] = s.ac_dir[e, m, 0] * v
            s.vel[e, B + m, 1] = s.ac_dir[e, m, 1] * v
    return -1


@njit(cache=True)
def _clear_controlled(e, s, B, m):
    """Controlled aircraft ``m`` of episode ``e`` out of the sky, its state zero (a flight that
    has not entered yet: not flying, outcome RUNNING)."""
    s.active[e, B + m] = False
    s.pos[e, B + m, 0], s.pos[e, B + m, 1] = 0.0, 0.0
    s.vel[e, B + m, 0], s.vel[e, B + m, 1] = 0.0, 0.0
    s.level[e, B + m] = 0
    s.ac_dir[e, m, 0], s.ac_dir[e, m, 1] = 0.0, 0.0
    s.ac_speed[e, m] = 0.0
    s.ac_goal[e, m, 0], s.ac_goal[e, m, 1] = 0.0, 0.0


@njit(cache=True)
def _next_entering(e, s, B, first):
    """The first controlled aircraft from ``first`` on that has not entered yet (not in the
    sky, no outcome), or -1."""
    M = s.ac_dir.shape[1]
    for m in range(first, M):
        if not s.active[e, B + m] and s.ac_outcome[e, m] == RUNNING:
            return m
    return -1


# ----------------------------------------------------------------------------------------------
# Step


@njit(cache=True)
def _spawn_traffic(e, s, c, acting):
    """A due airway spawn enters unless a controlled aircraft that flew this step is within the
    spawn clearance at the spawn level (it then waits, and enters at the airway start later).
    While controlled aircraft remain to enter (``traffic.controlled_spawns``), a spawn is the
    next of them (routes in order within a step); then a background aircraft, unless spawns
    are off."""
    R = c.route_start.shape[0]
    M = acting.shape[0]
    B = R * c.C + c.x_pos.shape[0]
    step_km = c.fp[P_TRAFFIC_STEP]
    speed = c.fp[P_TRAFFIC_SPEED]
    clearance = c.fp[P_SPAWN_CLEARANCE]
    first_spawn = M - int(c.fp[P_CONTROLLED_SPAWNS])
    entering = _next_entering(e, s, B, first_spawn) if first_spawn < M else -1
    if c.fp[P_SPAWN] == 0.0 and entering < 0:
        return
    for r in range(R):
        s.route_last[e, r] += step_km
        if s.route_last[e, r] < c.spacing[r]:
            continue
        arc = 0.0 if s.route_waiting[e, r] else s.route_last[e, r] - c.spacing[r]
        lv = s.route_count[e, r] % N_LEVELS
        x = c.route_start[r, 0] + arc * c.route_unit[r, 0]
        y = c.route_start[r, 1] + arc * c.route_unit[r, 1]
        blocked = False
        for m in range(M):
            if acting[m] and s.level[e, B + m] == lv:
                dx = x - s.pos[e, B + m, 0]
                dy = y - s.pos[e, B + m, 1]
                if math.sqrt(dx * dx + dy * dy) < clearance:
                    blocked = True
        s.route_waiting[e, r] = blocked
        if blocked:
            continue
        if entering >= 0:  # a controlled aircraft enters, flying to the airway's end
            m = entering
            s.pos[e, B + m, 0], s.pos[e, B + m, 1] = x, y
            s.ac_dir[e, m, 0], s.ac_dir[e, m, 1] = c.route_unit[r, 0], c.route_unit[r, 1]
            s.ac_speed[e, m] = c.fp[P_START_SPEED]
            v = c.fp[P_START_SPEED] * KM_PER_S_PER_KT
            s.vel[e, B + m, 0] = c.route_unit[r, 0] * v
            s.vel[e, B + m, 1] = c.route_unit[r, 1] * v
            s.level[e, B + m] = lv
            s.ac_goal[e, m, 0], s.ac_goal[e, m, 1] = c.route_end[r, 0], c.route_end[r, 1]
            s.active[e, B + m] = True
            s.route_last[e, r] = arc
            s.route_count[e, r] += 1
            entering = _next_entering(e, s, B, m + 1)
            continue
        if c.fp[P_SPAWN] == 0.0:
            return
        slot = -1
        for j in range(c.C):
            if not s.active[e, r * c.C + j]:
                slot = r * c.C + j
                break
        if slot < 0:  # pragma: no cover - capacity per_route + 2 suffices
            raise RuntimeError("airway slot capacity exceeded")
        s.active[e, slot] = True
        s.bg_arc[e, slot] = arc
        s.pos[e, slot, 0], s.pos[e, slot, 1] = x, y
        s.vel[e, slot, 0] = c.route_unit[r, 0] * speed
        s.vel[e, slot, 1] = c.route_unit[r, 1] * speed
        s.level[e, slot] = lv
        s.route_last[e, r] = arc
        s.route_count[e, r] += 1


@njit(cache=True, inline="always")
def _approach_of(e, n, px, py, vx, vy, dt, s):
    """The closest approach (km) over the next ``dt`` s of slot ``n`` of episode ``e`` to an
    aircraft at (px, py) km flying (vx, vy) km/s: :func:`closest_approach` of their relative
    motion (the one judgement of a pair in :func:`step_episodes`, background or controlled)."""
    d, _ = closest_approach(
        s.pos[e, n, 0] - px,
        s.pos[e, n, 1] - py,
        s.vel[e, n, 0] - vx,
        s.vel[e, n, 1] - vy,
        dt,
    )
    return d


@njit(cache=True)
def step_episodes(actions, s, c, o):
    """Advance every episode by one step (docs/model.md §3-§6).

    Args:
        actions: (E, M) action indices 0..26 (validated by the caller); aircraft that are not
            flying hold.
        s, c: the state (written) and the scenario's constants.
        o: the outputs, written:

        terms: (E, M, 7) out, the named reward terms of the step.
        flags: (E, M, 6) out, bool: acting, invalid action, outside, reached goal, terminated,
            truncated.
        outcome: (E, M) out, int8: the outcome code of an aircraft that finished this step.
        min_sep: (E, M) out, smallest swept distance to a same-level aircraft (inf if none).
        events: (2, E, M, N) out, bool, zero on entry: LoS with / NMAC with aircraft n.
        reward: (E, M) out, zero on entry: the sum of the terms.
        done: (E,) out, zero on entry: the episode's last aircraft finished this step.
        obs, masks: (E, M, F) float32 and (E, M, 27) int8 out: observations and action masks
            after the step (:func:`observe_episodes`).

    Returns:
        The number of episodes done this step.
    """
    E, M = s.ac_dir.shape[0], s.ac_dir.shape[1]
    N = s.pos.shape[1]
    B = N - M
    dt = c.fp[P_DT]
    los_km, nmac_km = c.fp[P_LOS], c.fp[P_NMAC]
    size = c.fp[P_SIZE]
    turn_c, turn_s = c.fp[P_TURN_COS], c.fp[P_TURN_SIN]
    path_w = -c.fp[P_W_PATH] / (size * size)
    max_steps = int(c.fp[P_MAX_STEPS])
    new_level = np.empty(M, dtype=np.int64)
    acting = np.empty(M, dtype=np.bool_)
    n_los = np.empty(M, dtype=np.int64)
    n_nmac = np.empty(M, dtype=np.int64)
    occ = np.empty(M, dtype=np.int64)
    row = np.zeros(o.obs.shape[2])
    best_d = np.empty(max((o.obs.shape[2] - 12) // 10, 1))
    best_n = np.empty(best_d.shape[0], dtype=np.int64)
    in_sky = np.arange(N)  # scratch: the slots in the sky, ascending (see _slots_in_sky)
    n_done = 0
    for e in range(E):
        live = False
        for m in range(M):
            acting[m] = s.active[e, B + m]
            live |= acting[m]
            o.flags[e, m, F_ACTING] = acting[m]
            o.min_sep[e, m] = np.inf
            new_level[m] = s.level[e, B + m]
        if not live:
            _observe_episode(e, o.obs, o.masks, s, c, row, best_d, best_n, in_sky)
            continue

        # 1. Apply the actions at the start of the step: turn, clipped speed, target level.
        for m in range(M):
            if not acting[m]:
                continue
            a = actions[e, m]
            a_psi = a // 9 - 1
            a_v = (a // 3) % 3 - 1
            a_h = a % 3 - 1
            target = s.level[e, B + m] + a_h
            if target < 0 or target >= N_LEVELS:
                o.flags[e, m, F_INVALID] = True  # masked: the level change is not executed
            else:
                new_level[m] = target
            if a_psi != 0:  # rotate the heading vector clockwise by a_psi heading steps
                sin_turn = turn_s * a_psi
                ux, uy = s.ac_dir[e, m, 0], s.ac_dir[e, m, 1]
                rx = ux * turn_c + uy * sin_turn
                ry = uy * turn_c - ux * sin_turn
                norm = math.sqrt(rx * rx + ry * ry)
                s.ac_dir[e, m, 0], s.ac_dir[e, m, 1] = rx / norm, ry / norm
            sp = s.ac_speed[e, m] + a_v * c.fp[P_SPEED_STEP]
            s.ac_speed[e, m] = min(max(sp, c.fp[P_MIN_SPEED]), c.fp[P_MAX_SPEED])
            v = s.ac_speed[e, m] * KM_PER_S_PER_KT
            s.vel[e, B + m, 0] = s.ac_dir[e, m, 0] * v
            s.vel[e, B + m, 1] = s.ac_dir[e, m, 1] * v

        # 2. Swept separation over [0, dt] against every aircraft in the sky; a level change
        #    occupies the old and the new level for the step.
        for m in range(M):
            occ[m] = ((1 << s.level[e, B + m]) | (1 << new_level[m])) if acting[m] else 0
        n_sky = _slots_in_sky(e, s, in_sky)
        one = M == 1
        n_bg = B  # the background slots in ``in_sky[:n_bg]``, the controlled ones after them
        if not one:
            n_bg = 0
            while n_bg < n_sky and in_sky[n_bg] < B:
                n_bg += 1
        for m in range(M):
            n_los[m] = 0
            n_nmac[m] = 0
        for m in range(M):
            if not acting[m]:
                continue
            i = B + m
            occ_m = occ[m]
            px, py = s.pos[e, i, 0], s.pos[e, i, 1]
            vx, vy = s.vel[e, i, 0], s.vel[e, i, 1]
            best = o.min_sep[e, m]  # locals, not array elements: kept in registers
            n_l = 0
            n_n = 0
            for j in range(n_bg):  # the background (first in ``in_sky``)
                n = j if one else in_sky[j]  # ``one``: no list, every slot (_slots_in_sky)
                if not s.active[e, n] or occ_m & (1 << s.level[e, n]) == 0:
                    continue
                d = _approach_of(e, n, px, py, vx, vy, dt, s)
                if d < best:
                    best = d
                if d < los_km:  # an NMAC (d < nmac_km < los_km) is also a LoS
                    o.events[0, e, m, n] = True
                    n_l += 1
                    if d < nmac_km:
                        o.events[1, e, m, n] = True
                        n_n += 1
            # The controlled aircraft above m: a pair of controlled aircraft is judged once,
            # from its lower index. The distance is the same bits from either side (a - b =
            # -(b - a) exactly, and every later operation is odd or even in it), and the
            # minimum and the counts do not depend on the order in which pairs are judged.
            for jj in range(n_bg, n_sky):
                n = in_sky[jj]
                if n <= i or not s.active[e, n]:
                    continue
                m2 = n - B
                if occ_m & occ[m2] == 0:
                    continue
                d = _approach_of(e, n, px, py, vx, vy, dt, s)
                if d < best:
                    best = d
                if d < o.min_sep[e, m2]:
                    o.min_sep[e, m2] = d
                if d < los_km:
                    o.events[0, e, m, n] = True
                    o.events[0, e, m2, i] = True
                    n_l += 1
                    n_los[m2] += 1
                    if d < nmac_km:
                        o.events[1, e, m, n] = True
                        o.events[1, e, m2, i] = True
                        n_n += 1
                        n_nmac[m2] += 1
            o.min_sep[e, m] = best
            n_los[m] += n_l
            n_nmac[m] += n_n

        # 4. Move the background (every slot: one not in the sky is placed again when it
        #    spawns); airway aircraft leave at the end of their airway, explicit ones at the
        #    sector edge.
        n_airway = s.bg_arc.shape[1]
        step_km = c.fp[P_TRAFFIC_STEP]
        for n in range(B):
            x = s.pos[e, n, 0] + s.vel[e, n, 0] * dt
            y = s.pos[e, n, 1] + s.vel[e, n, 1] * dt
            s.pos[e, n, 0] = x
            s.pos[e, n, 1] = y
            if n < n_airway:
                arc = s.bg_arc[e, n] + step_km
                s.bg_arc[e, n] = arc
                if arc >= c.route_len_slot[n]:
                    s.active[e, n] = False
            elif x < 0.0 or x > size or y < 0.0 or y > size:
                s.active[e, n] = False

        # 3. Swept goal test: the goal is a fixed point.
        for m in range(M):
            if acting[m]:
                i = B + m
                d, _ = closest_approach(
                    s.ac_goal[e, m, 0] - s.pos[e, i, 0],
                    s.ac_goal[e, m, 1] - s.pos[e, i, 1],
                    -s.vel[e, i, 0],
                    -s.vel[e, i, 1],
                    dt,
                )
                o.flags[e, m, F_REACHED] = d < c.fp[P_GOAL_RADIUS]

        # 4. Move the controlled aircraft (a controlled aircraft that has left has zero
        #    velocity); due airway spawns enter.
        for n in range(B, N):
            s.pos[e, n, 0] += s.vel[e, n, 0] * dt
            s.pos[e, n, 1] += s.vel[e, n, 1] * dt
        for m in range(M):
            s.level[e, B + m] = new_level[m]
        s.steps[e] += 1
        _spawn_traffic(e, s, c, acting)

        # 5. Outcomes (priority nmac > los > boundary > success) and named rewards.
        for m in range(M):
            if not acting[m]:
                continue
            i = B + m
            x, y = s.pos[e, i, 0], s.pos[e, i, 1]
            out = x < 0.0 or x > size or y < 0.0 or y > size
            code = SUCCESS if o.flags[e, m, F_REACHED] else RUNNING
            margin = c.fp[P_BOUNDARY_MARGIN]  # inf: the boundary never ends the episode
            if x < -margin or x > size + margin or y < -margin or y > size + margin:
                code = BOUNDARY
            if n_los[m] > 0 and c.fp[P_LOS_TERMINATES] != 0.0:
                code = LOS
            if n_nmac[m] > 0:
                code = NMAC
            term = code != RUNNING
            trunc = not term and s.steps[e] >= max_steps
            if trunc:
                code = TIMEOUT
            gx = s.ac_goal[e, m, 0] - x
            gy = s.ac_goal[e, m, 1] - y
            o.terms[e, m, R_GOAL] = c.fp[P_W_GOAL] if code == SUCCESS else 0.0
            o.terms[e, m, R_PATH] = path_w * (gx * gx + gy * gy)
            o.terms[e, m, R_BOUNDARY] = -c.fp[P_W_BOUNDARY] if out else 0.0
            o.terms[e, m, R_STEP] = -c.fp[P_W_STEP]
            o.terms[e, m, R_TIMEOUT] = -c.fp[P_W_TIMEOUT] if trunc else 0.0
            o.terms[e, m, R_LOS] = -c.fp[P_W_LOS] * (n_los[m] - n_nmac[m])
            o.terms[e, m, R_NMAC] = -c.fp[P_W_NMAC] * n_nmac[m]
            o.flags[e, m, F_OUTSIDE] = out
            o.flags[e, m, F_TERMINATED] = term
            o.flags[e, m, F_TRUNCATED] = trunc
            o.outcome[e, m] = code
            if term or trunc:
                s.ac_outcome[e, m] = code
                s.active[e, i] = False
                s.vel[e, i, 0] = 0.0
                s.vel[e, i, 1] = 0.0
            total = 0.0
            for t in range(N_TERMS):
                total += o.terms[e, m, t]
            o.reward[e, m] = total
        still = False
        for m in range(M):
            still |= s.active[e, B + m]
        if not still:
            o.done[e] = True
            n_done += 1
        _observe_episode(e, o.obs, o.masks, s, c, row, best_d, best_n, in_sky)
    return n_done


@njit(cache=True, inline="always")
def _slots_in_sky(e, s, out):
    """The slots the pair loops visit, ascending: ``out[:k]``, ``k`` returned. With several
    controlled aircraft, the slots of episode ``e`` in the sky, written into ``out``: the loops
    then visit the same pairs in the same order (so the same bits) without the empty slots
    (most of them in ``marl/*-all``). With one, ``out`` is left as it came (``arange``) and
    every slot is visited: listing them would cost as much as the one pass it saves. The loops
    test ``active`` either way."""
    if s.ac_dir.shape[1] == 1:
        return s.active.shape[1]
    k = 0
    for n in range(s.active.shape[1]):  # branch-free: every slot written, the empty overwritten
        out[k] = n
        k += 1 if s.active[e, n] else 0
    return k


# ----------------------------------------------------------------------------------------------
# Observe


@njit(cache=True)
def observe_episodes(episodes, obs, masks, s, c):
    """Observations (E, M, F) float32 and action masks (E, M, 27) int8 of every controlled
    aircraft of episodes ``episodes``, written into ``obs`` and ``masks``; the layout is
    :mod:`cdr_bench.sim.observation`'s table.

    Neighbours are the K nearest other aircraft in the sky (horizontal distance, any level;
    ties to the lower index); empty slots are zero. Every value is clipped to [low, high].
    """
    row = np.zeros(obs.shape[2])
    best_d = np.empty(max((obs.shape[2] - 12) // 10, 1))
    best_n = np.empty(best_d.shape[0], dtype=np.int64)
    in_sky = np.arange(s.pos.shape[1])
    for ie in range(episodes.shape[0]):
        _observe_episode(episodes[ie], obs, masks, s, c, row, best_d, best_n, in_sky)


@njit(cache=True)
def _observe_episode(e, obs, masks, s, c, row, best_d, best_n, in_sky):
    """:func:`observe_episodes` of episode ``e`` (``row``, ``best_*``, ``in_sky``: scratch
    space)."""
    M = s.ac_dir.shape[1]
    N = s.pos.shape[1]
    B = N - M
    F = obs.shape[2]
    K = (F - 12) // 10
    size = c.fp[P_SIZE]
    rng_km = c.fp[P_RANGE]
    look = c.fp[P_LOOKAHEAD]
    los_km = c.fp[P_LOS]
    lo_v, hi_v = c.fp[P_MIN_SPEED], c.fp[P_MAX_SPEED]
    mid = 0.5 * (lo_v + hi_v)
    half = max(0.5 * (hi_v - lo_v), 1e-9)
    inv_steps = 1.0 / c.fp[P_MAX_STEPS]
    n_sky = _slots_in_sky(e, s, in_sky)
    one = M == 1
    for m in range(M):
        i = B + m
        x, y = s.pos[e, i, 0], s.pos[e, i, 1]
        ux, uy = s.ac_dir[e, m, 0], s.ac_dir[e, m, 1]
        gx = s.ac_goal[e, m, 0] - x
        gy = s.ac_goal[e, m, 1] - y
        gd = math.sqrt(gx * gx + gy * gy)
        inv_gd = 1.0 / max(gd, 1e-9)
        row[0] = x * (2.0 / size) - 1.0
        row[1] = y * (2.0 / size) - 1.0
        row[2] = ux  # sin(heading)
        row[3] = uy  # cos(heading)
        row[4] = (s.ac_speed[e, m] - mid) / half
        row[5] = s.level[e, i] - 1.0
        row[6] = gx / size
        row[7] = gy / size
        row[8] = gd / size
        row[9] = (gx * uy - gy * ux) * inv_gd  # sin(bearing - heading): + goal to the right
        row[10] = (gx * ux + gy * uy) * inv_gd  # cos(bearing - heading)
        row[11] = s.steps[e] * inv_steps

        # K nearest others by insertion on squared distances (strict <: the lower index
        # wins a tie); the square root is taken for the K chosen only.
        found = 0
        for jn in range(n_sky):
            n = jn if one else in_sky[jn]  # ``one``: no list, every slot (_slots_in_sky)
            if n == i or not s.active[e, n]:
                continue
            dx = s.pos[e, n, 0] - x
            dy = s.pos[e, n, 1] - y
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
            px = s.pos[e, n, 0] - x
            py = s.pos[e, n, 1] - y
            vx = s.vel[e, n, 0] - s.vel[e, i, 0]
            vy = s.vel[e, n, 1] - s.vel[e, i, 1]
            dlevel = float(s.level[e, n] - s.level[e, i])
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
            obs[e, m, f] = min(max(row[f], c.low[f]), c.high[f])
        lv = s.level[e, i]
        for a in range(27):
            a_h = a % 3 - 1
            masks[e, m, a] = 0 <= lv + a_h < N_LEVELS


# ----------------------------------------------------------------------------------------------
# Conflicts (a metric of the evaluator, docs/model.md §10.1; not used by the dynamics)


@njit(cache=True)
def conflicts_episodes(out, s, c):
    """Predicted conflicts of every flying controlled aircraft: ``out[e, m, n]`` is set when
    aircraft ``n`` is in the sky at the same level as controlled aircraft ``m`` and their
    closest approach over the look-ahead ``[0, observation.lookahead_s]``, at the current
    velocities, is below the LoS threshold (the observation's ``conflict`` flag, §7, for every
    other aircraft rather than the nearest K). Other entries are cleared."""
    E, M, N = out.shape
    B = N - M
    look = c.fp[P_LOOKAHEAD]
    los_km = c.fp[P_LOS]
    for e in range(E):
        for m in range(M):
            i = B + m
            for n in range(N):
                out[e, m, n] = False
            if not s.active[e, i]:
                continue
            x, y = s.pos[e, i, 0], s.pos[e, i, 1]
            vx0, vy0 = s.vel[e, i, 0], s.vel[e, i, 1]
            lv = s.level[e, i]
            for n in range(N):
                if n == i or not s.active[e, n] or s.level[e, n] != lv:
                    continue
                px, py = s.pos[e, n, 0] - x, s.pos[e, n, 1] - y
                qx, qy = s.vel[e, n, 0] - vx0, s.vel[e, n, 1] - vy0
                d_cpa, _ = closest_approach(px, py, qx, qy, look)
                out[e, m, n] = d_cpa < los_km


@njit(cache=True, inline="always")
def _count_entry(before, counts, k, e, m, n, first_controlled):
    """The pair (m, n) of episode ``e`` is in LoS (``k`` = 0) or NMAC (``k`` = 1) now: an event
    of kind ``k`` if it was not at the previous step (``before``), and of kind ``k + 2`` too when
    ``n`` is a controlled aircraft (see :func:`pair_events`)."""
    if not before[e, m, n]:
        counts[k, e, m] += 1
        if n >= first_controlled:
            counts[k + 2, e, m] += 1


@njit(cache=True)
def accumulate_step(
    actions, terms, flags, outcome_now, min_sep_now, before_km, after_km, goal_km, radius_km,
    dt_s, counts, manoeuvres, steps, path_km, flight_s, goal_r, safety_r, invalid, min_sep,
    outcome, los, nmac,
):  # fmt: skip
    """One step's part of an evaluation's per-aircraft accumulators (the runner's; after
    :func:`pair_events` has set ``counts[6]`` and ``counts[7]``, in LoS / NMAC now), in place,
    with the arithmetic of the numpy expressions it replaced, operation for operation (the same
    bits): manoeuvres (actions other than hold), steps flown, path and flight time (of a step
    that reached the goal, the fraction in [0, 1] of the straight step flown when it first
    comes within ``radius_km`` of the goal: 0 if it started inside), the goal and
    safety reward parts (the terms summed in order), invalid actions, the smallest separation
    (``np.minimum``: a NaN stays), the outcome of aircraft that finished, LoS and NMAC ever."""
    E, M = actions.shape
    rr = radius_km * radius_km
    for e in range(E):
        for m in range(M):
            if actions[e, m] != HOLD:
                manoeuvres[e, m] += 1
            acting = flags[e, m, F_ACTING]
            if acting:
                steps[e, m] += 1
            bx, by = before_km[e, m, 0], before_km[e, m, 1]
            dx, dy = after_km[e, m, 0] - bx, after_km[e, m, 1] - by
            part = 1.0
            if flags[e, m, F_REACHED]:
                px, py = bx - goal_km[e, m, 0], by - goal_km[e, m, 1]
                a = dx * dx + dy * dy
                b = px * dx + py * dy
                c = px * px + py * py - rr
                disc = b * b - a * c
                t = 1.0
                if a > 0 and disc >= 0:
                    t = (-b - math.sqrt(max(disc, 0.0))) / a
                if c <= 0:
                    part = 0.0
                else:
                    part = min(max(t, 0.0), 1.0)
            if acting:
                path_km[e, m] += part * math.sqrt(dx * dx + dy * dy)
                flight_s[e, m] += part * dt_s
            goal_r[e, m] += (
                terms[e, m, 0] + terms[e, m, 1] + terms[e, m, 2] + terms[e, m, 3] + terms[e, m, 4]
            )
            safety_r[e, m] += terms[e, m, 5] + terms[e, m, 6]
            if flags[e, m, F_INVALID]:
                invalid[e, m] += 1
            x = min_sep_now[e, m]
            if min_sep[e, m] == min_sep[e, m] and (x != x or x < min_sep[e, m]):
                min_sep[e, m] = x
            if outcome_now[e, m] != 0:
                outcome[e, m] = outcome_now[e, m]
            if counts[6, e, m]:
                los[e, m] = True
            if counts[7, e, m]:
                nmac[e, m] = True


@njit(cache=True)
def pair_events(
    los_with, nmac_with, prev_los, prev_nmac, conflict_now, in_conflict, first_controlled, counts
):
    """One step's separation events of every controlled aircraft, in one pass over its pairs
    (``(E, M, N)`` booleans: LoS and NMAC with each aircraft now and at the previous step,
    predicted conflict now and before). ``counts`` (``(8, E, M)`` int64) is added to in place:
    0 LoS events (pairs entering LoS), 1 NMAC events, 2 and 3 the same with controlled aircraft
    only (columns from ``first_controlled`` on), 4 steps in LoS, 5 conflict events (pairs
    entering a predicted conflict); and set: 6 in LoS now, 7 in NMAC now (0/1)."""
    E, M, N = los_with.shape
    for e in range(E):
        for m in range(M):
            # Most rows hold no event and no conflict: one pass that the compiler vectorises
            # (the bytes of the three rows or-ed together) finds them, and they count nothing.
            hot = 0
            for n in range(N):
                hot |= los_with[e, m, n] | nmac_with[e, m, n] | conflict_now[e, m, n]
            if not hot:
                counts[6, e, m] = 0
                counts[7, e, m] = 0
                continue
            los_any = 0
            nmac_any = 0
            for n in range(N):
                lw = los_with[e, m, n]
                nw = nmac_with[e, m, n]
                if lw:
                    los_any = 1
                    _count_entry(prev_los, counts, 0, e, m, n, first_controlled)
                if nw:
                    nmac_any = 1
                    _count_entry(prev_nmac, counts, 1, e, m, n, first_controlled)
                if conflict_now[e, m, n] and not in_conflict[e, m, n]:
                    counts[5, e, m] += 1
            counts[4, e, m] += los_any
            counts[6, e, m] = los_any
            counts[7, e, m] = nmac_any
