"""Geometric resolvers on the observation vector: ``direct``'s pursuit of the goal and ``mvp``, a
resolver in the style of Modified Voltage Potential (Hoekstra's MVP, the resolution method of
BlueSky) adapted to the 27 discrete actions.

One implementation, three users: the reference agents ``agents/direct`` and ``agents/mvp`` are
thin wrappers of :func:`steer_to_goal` and :func:`mvp_actions`; the trainers' ``--mvp-input``
(a learned residual on top of ``mvp``) append :func:`mvp_onehot` to the observation, and so does
the agent that plays such a checkpoint. Pure numpy, imported by the agents' own processes.

**The same actions on every CPU.** Only ``+ - * /``, ``sqrt`` and comparisons are used (each
correctly rounded by IEEE 754), on float64: no ``sin``, ``cos`` or ``arctan2``, whose libm and
numpy kernels are chosen per CPU (see :mod:`cdr_bench.inference`). Headings come as (sin, cos)
in the observation; a 5 deg turn rotates them with the constants :data:`SIN_STEP` and
:data:`COS_STEP`; "is the goal more than 2.5 deg to the right" is a sign test against the
rotated half step. Every sum has two or K terms in a fixed order (no pairwise reduction).

The MVP decision, each step:

1. **Detection.** For every observed aircraft at the same level, the closest point of approach
   (CPA) under straight flight: time ``t_cpa`` (within :data:`LOOKAHEAD_S`) and distance
   ``d_cpa``. A conflict is ``d_cpa < PZ_KM`` (the LoS radius with a margin) - or already
   inside it.
2. **Vertical escape** (where feasible): if there is a conflict and an adjacent level is
   allowed by the mask and free (no observed aircraft there now or at CPA within
   :data:`LEVEL_PZ_KM`), climb or descend to it (the freer one), turning toward the goal as
   ``direct`` does.
3. **Horizontal MVP** otherwise: each conflict pushes the ownship's position at CPA straight
   away from the intruder's position at CPA by the intrusion ``PZ_KM - d_cpa``; the sum of the
   pushes, divided by the time left to CPA, is the velocity change wanted. The discrete heading
   (-5/0/+5 deg) and speed (-50/0/+50 kt) change whose new velocity is closest to the wanted
   one is flown.
4. No conflict: fly to the goal like ``direct`` and drift back to the nominal 430 kt.
   (Known limit, as for any pure pursuit with a 5 deg/step turn rate: after a large resolution
   manoeuvre a goal abeam inside the turning circle can be orbited until the horizon - the rare
   timeouts of the reference table.)

Assumes the default normalisation of the observation (:mod:`cdr_bench.sim.observation`:
430 kt +- 100 kt, 100 km range, neighbour velocities over 1000 kt) and 5 deg / 50 kt action
steps.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from cdr_bench.actions import N_ACTIONS

__all__ = ["mvp_actions", "mvp_onehot", "steer_to_goal", "with_mvp_input"]

KT_TO_KM_S = 1.852 / 3600.0
RANGE_KM = 100.0  # observation.range_km
VEL_SCALE_KM_S = 1000.0 * KT_TO_KM_S  # neighbour dvx/dvy are divided by 1000 kt
NOMINAL_KT, HALF_RANGE_KT = 430.0, 100.0
MIN_KT, MAX_KT = 330.0, 530.0
SPEED_STEP_KT = 50.0
DT_S = 30.0

SIN_STEP, COS_STEP = 0.08715574274765817, 0.9961946980917455
"""sin and cos of the 5 deg heading step (float64 literals; ``tests/test_resolvers.py`` checks
them against ``math``)"""
SIN_HALF_STEP, COS_HALF_STEP = 0.043619387365336, 0.9990482215818578
"""sin and cos of 2.5 deg, half a step: a goal closer to the nose than this is not turned to"""

PZ_KM = 14.0  # protected zone: 10 km LoS radius plus a margin for the 5 deg/step turn rate
LOOKAHEAD_S = 360.0  # conflicts further ahead are left to later steps
LEVEL_PZ_KM = 16.0  # an adjacent level is free if nothing there comes closer than this
LEVEL_LOOKAHEAD_S = 240.0

GOAL_SIN, GOAL_COS = 9, 10  # observation indices of sin/cos(bearing to goal - heading)

Array = NDArray[np.float64]


def _index(a_psi: NDArray[np.int64], a_v: NDArray[np.int64], a_h: NDArray[np.int64]) -> NDArray:
    """Action index of the factors in {-1, 0, +1} (:mod:`cdr_bench.actions`)."""
    return (9 * (a_psi + 1) + 3 * (a_v + 1) + (a_h + 1)).astype(np.int64)


def steer_to_goal(observations: NDArray) -> NDArray[np.int64]:
    """(N,) heading factor a_psi in {-1, 0, +1} that turns toward the goal: +1 when the goal is
    more than 2.5 deg to the right (``goal_sin_rel`` positive: clockwise), -1 more than 2.5 deg
    to the left, 0 within half a turn step of the nose. Directly behind counts as right."""
    gs = observations[:, GOAL_SIN].astype(np.float64)
    gc = observations[:, GOAL_COS].astype(np.float64)
    # sin(rel - 2.5 deg) > 0 on the right half-plane, sin(rel + 2.5 deg) < 0 on the left one
    right = (gs >= 0) & (gs * COS_HALF_STEP - gc * SIN_HALF_STEP > 0)
    left = (gs <= 0) & (gs * COS_HALF_STEP + gc * SIN_HALF_STEP < 0)
    return np.where(right, 1, np.where(left, -1, 0)).astype(np.int64)


def direct_actions(observations: NDArray) -> NDArray[np.int64]:
    """(N,) actions of ``direct``: turn toward the goal, hold speed and level."""
    a_psi = steer_to_goal(observations)
    zero = np.zeros_like(a_psi)
    return _index(a_psi, zero, zero)


def _cpa(rx: Array, ry: Array, vx: Array, vy: Array, horizon_s: float) -> tuple[Array, Array]:
    """t_cpa (s, clipped to [0, horizon]) and d_cpa (km) of relative positions/velocities."""
    vv = vx * vx + vy * vy
    t = np.clip(-(rx * vx + ry * vy) / np.maximum(vv, 1e-12), 0.0, horizon_s)
    cx, cy = rx + vx * t, ry + vy * t
    return t, np.sqrt(cx * cx + cy * cy)


def _sum_k(x: Array) -> Array:
    """Sum over the neighbour axis (1) in slot order, one addition at a time."""
    out = np.zeros(x.shape[0])
    for k in range(x.shape[1]):
        out = out + x[:, k]
    return out


def mvp_actions(
    observations: NDArray,
    masks: NDArray,
    reciprocal: bool = False,
    right_of_way: NDArray[np.bool_] | None = None,
) -> NDArray[np.int64]:
    """(N,) actions of ``mvp`` for (N, F) observations and (N, 27) action masks.

    ``reciprocal``: the cooperative variant ``mvp-reciprocal`` for sectors in which every
    aircraft runs it (each resolving on its own observation, no messages), in the spirit of
    reciprocal velocity obstacles (ORCA): each aircraft of a conflict takes half of the
    resolution, counting on the other to take the other half - the wanted velocity change is
    half of MVP's - and the vertical escape is shared by direction instead of being taken by
    both: an aircraft heading east (north-east through south-east, ``sin(heading) >= 0``) may
    only climb, one heading west only descend, so the two aircraft of a head-on or crossing
    conflict never escape to the same level. Without ``reciprocal`` the actions are exactly
    ``mvp``'s.

    ``right_of_way`` (N, K) bool, optional: the observed aircraft (neighbour slots) against which
    the aircraft keeps its course, because the other aircraft resolves the conflict (a joint
    controller assigns each conflict to one of its two aircraft, ``agents/mvp_priority``): they
    are left out of the conflicts, and still counted when a level is checked for an escape."""
    obs = np.asarray(observations, dtype=np.float64)
    masks = np.asarray(masks)
    n = obs.shape[0]
    k = (obs.shape[1] - 12) // 10
    nb = obs[:, 12 : 12 + 10 * k].reshape(n, k, 10)
    present = nb[..., 0] > 0.5
    rx, ry = nb[..., 1] * RANGE_KM, nb[..., 2] * RANGE_KM  # intruder minus own, km
    vx, vy = nb[..., 3] * VEL_SCALE_KM_S, nb[..., 4] * VEL_SCALE_KM_S  # km/s
    dlev = np.rint(nb[..., 5] * 2).astype(np.int64)
    now = nb[..., 6] * RANGE_KM

    # own heading (sin, cos) normalised to a unit vector, and velocity (east, north) in km/s
    hs, hc = obs[:, 2], obs[:, 3]
    norm = np.sqrt(hs * hs + hc * hc)
    ok = norm > 0
    hs = np.where(ok, hs / np.where(ok, norm, 1.0), 0.0)
    hc = np.where(ok, hc / np.where(ok, norm, 1.0), 1.0)
    speed_kt = NOMINAL_KT + HALF_RANGE_KT * obs[:, 4]
    speed = speed_kt * KT_TO_KM_S
    v_own_x, v_own_y = hs * speed, hc * speed

    # 1. detection at the own level
    t, d = _cpa(rx, ry, vx, vy, LOOKAHEAD_S)
    conflict = present & (dlev == 0) & ((d < PZ_KM) | (now < PZ_KM))
    if right_of_way is not None:
        conflict &= ~np.asarray(right_of_way, dtype=bool)
    any_conflict = conflict.any(1)

    # 2. vertical escape: a feasible adjacent level with nothing observed near it
    _, dl = _cpa(rx, ry, vx, vy, LEVEL_LOOKAHEAD_S)
    near = present & ((dl < LEVEL_PZ_KM) | (now < LEVEL_PZ_KM))
    climb_ok = masks[:, 9 * 1 + 3 * 1 + 2] > 0  # (0, 0, +1) feasible
    descend_ok = masks[:, 9 * 1 + 3 * 1 + 0] > 0
    up_free = climb_ok & ~(near & (dlev == 1)).any(1)
    down_free = descend_ok & ~(near & (dlev == -1)).any(1)
    # the freer level: larger distance to its closest observed aircraft
    up_gap = np.where(present & (dlev == 1), dl, np.inf).min(1)
    down_gap = np.where(present & (dlev == -1), dl, np.inf).min(1)
    if reciprocal:
        east = hs >= 0
        up_free, down_free = up_free & east, down_free & ~east
    a_h = np.where(
        up_free & down_free,
        np.where(up_gap >= down_gap, 1, -1),
        np.where(up_free, 1, np.where(down_free, -1, 0)),
    )
    a_h = np.where(any_conflict, a_h, 0)

    # 3. horizontal MVP for conflicts that no level change resolves
    cx, cy = rx + vx * t, ry + vy * t  # intruder relative to own at CPA
    dist_cpa = np.sqrt(cx * cx + cy * cy)
    # exact head-on (d_cpa < 0.1 km): no side to push away from; the intruder is taken to be
    # to the right of the relative velocity, so the ownship is pushed to the LEFT. (The rules of
    # the air turn right; this is the behaviour every published ``mvp`` result was scored with,
    # and tests/test_resolvers.py pins it.)
    px, py = vy, -vx
    perp = np.maximum(np.sqrt(px * px + py * py), 1e-9)
    far = dist_cpa > 0.1
    dcpa = np.maximum(dist_cpa, 1e-9)
    ux = np.where(far, cx / dcpa, -px / perp)
    uy = np.where(far, cy / dcpa, -py / perp)
    scale = np.maximum(PZ_KM - d, 0.0) / np.maximum(t, DT_S)
    if reciprocal:
        scale = 0.5 * scale  # each of the two takes half
    dvx = _sum_k(np.where(conflict, -ux * scale, 0.0))
    dvy = _sum_k(np.where(conflict, -uy * scale, 0.0))
    want_x, want_y = v_own_x + dvx, v_own_y + dvy

    # candidate (a_psi, a_v): new velocity of each of the 9 combinations
    a_psi = np.array([-1, -1, -1, 0, 0, 0, 1, 1, 1])
    a_v = np.array([-1, 0, 1, -1, 0, 1, -1, 0, 1])
    sin_d = np.array([-SIN_STEP, 0.0, SIN_STEP])[a_psi + 1]
    cos_d = np.array([COS_STEP, 1.0, COS_STEP])[a_psi + 1]
    s_new = hs[:, None] * cos_d[None] + hc[:, None] * sin_d[None]  # sin(h + delta)
    c_new = hc[:, None] * cos_d[None] - hs[:, None] * sin_d[None]  # cos(h + delta)
    sp_new = np.clip(speed_kt[:, None] + SPEED_STEP_KT * a_v[None], MIN_KT, MAX_KT) * KT_TO_KM_S
    ex, ey = s_new * sp_new - want_x[:, None], c_new * sp_new - want_y[:, None]
    best = np.argmin(ex * ex + ey * ey, axis=1)
    psi_res, v_res = a_psi[best], a_v[best]

    # 4. no conflict (or escaping vertically): fly to the goal at nominal speed
    psi_goal = steer_to_goal(obs)
    v_goal = np.where(speed_kt < NOMINAL_KT - 25, 1, np.where(speed_kt > NOMINAL_KT + 25, -1, 0))
    horizontal = any_conflict & (a_h == 0)
    psi = np.where(horizontal, psi_res, psi_goal)
    v = np.where(horizontal, v_res, v_goal)
    return _index(psi, v, a_h)


def mvp_onehot(observations: NDArray, masks: NDArray) -> NDArray[np.float32]:
    """(N, 27) float32 one-hot of :func:`mvp_actions`: the input a learned residual on top of
    ``mvp`` gets beside the observation (``--mvp-input``)."""
    a = mvp_actions(observations, masks)
    out = np.zeros((len(a), N_ACTIONS), np.float32)
    out[np.arange(len(a)), a] = 1.0
    return out


def with_mvp_input(observations: NDArray, masks: NDArray) -> NDArray[np.float32]:
    """(N, F + 27) float32: the observations with :func:`mvp_onehot` appended."""
    obs = np.asarray(observations, dtype=np.float32)
    return np.concatenate([obs, mvp_onehot(obs, masks)], axis=1)
