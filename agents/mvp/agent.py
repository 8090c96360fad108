"""Reference agent ``mvp``: a geometric resolver in the style of Modified Voltage Potential
(Hoekstra's MVP, the resolution method of BlueSky) adapted to the 27 discrete actions.

It sees what every agent sees: the observation vector (own state, goal, the K nearest aircraft
with relative position, velocity and level) and the action mask. Each step:

1. **Detection.** For every observed aircraft at the same level, the closest point of approach
   (CPA) under straight flight: time ``t_cpa`` (within ``LOOKAHEAD_S``) and distance ``d_cpa``.
   A conflict is ``d_cpa < PZ_KM`` (the LoS radius with a margin) - or already inside it.
2. **Vertical escape** (where feasible): if there is a conflict and an adjacent level is
   allowed by the mask and free (no observed aircraft there now or at CPA within ``PZ_KM``),
   climb or descend to it (the freer one), turning toward the goal as ``direct`` does.
3. **Horizontal MVP** otherwise: each conflict pushes the ownship's position at CPA straight away
   from the intruder's position at CPA by the intrusion ``PZ_KM - d_cpa``; the sum of the pushes,
   divided by the time left to CPA, is the velocity change wanted. The discrete heading
   (-5/0/+5 deg) and speed (-50/0/+50 kt) change whose new velocity is closest to the wanted one
   is flown.
4. No conflict: fly to the goal like ``direct`` and drift back to the nominal 430 kt.
   (Known limit, as for any pure pursuit with a 5 deg/step turn rate: after a large resolution
   manoeuvre a goal abeam inside the turning circle can be orbited until the horizon - the rare
   timeouts of the reference table.)

Assumes the default normalisation of the observation (430 kt +- 100 kt, 100 km range) and
5 deg / 50 kt action steps.
"""

from __future__ import annotations

from typing import Any

import numpy as np

KT_TO_KM_S = 1.852 / 3600.0
RANGE_KM = 100.0  # observation.range_km
VEL_SCALE_KM_S = 1000.0 * KT_TO_KM_S  # neighbour dvx/dvy are divided by 1000 kt
NOMINAL_KT, HALF_RANGE_KT = 430.0, 100.0
MIN_KT, MAX_KT = 330.0, 530.0
HEADING_STEP_DEG, SPEED_STEP_KT = 5.0, 50.0
DT_S = 30.0

PZ_KM = 14.0  # protected zone: 10 km LoS radius plus a margin for the 5 deg/step turn rate
LOOKAHEAD_S = 360.0  # conflicts further ahead are left to later steps
LEVEL_PZ_KM = 16.0  # an adjacent level is free if nothing there comes closer than this
LEVEL_LOOKAHEAD_S = 240.0
HALF_TURN_DEG = 2.5


def _cpa(rel, vrel, horizon_s):
    """t_cpa (s, clipped to [0, horizon]) and d_cpa (km) of relative positions/velocities."""
    vv = (vrel**2).sum(-1)
    t = np.clip(-(rel * vrel).sum(-1) / np.maximum(vv, 1e-12), 0.0, horizon_s)
    d = np.linalg.norm(rel + vrel * t[..., None], axis=-1)
    return t, d


class Agent:
    def __init__(self, observation_space: Any, action_space: Any):
        self.k = (int(observation_space["observation"].shape[0]) - 12) // 10

    def act(self, observation: dict[str, np.ndarray]) -> int:
        o, m = observation["observation"][None], observation["action_mask"][None]
        return int(self.act_batch(o, m)[0])

    def act_batch(self, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
        obs = observations.astype(np.float64)
        n = obs.shape[0]
        nb = obs[:, 12 : 12 + 10 * self.k].reshape(n, self.k, 10)
        present = nb[..., 0] > 0.5
        rel = nb[..., 1:3] * RANGE_KM  # intruder minus own, km
        vrel = nb[..., 3:5] * VEL_SCALE_KM_S  # km/s
        dlev = np.rint(nb[..., 5] * 2).astype(int)
        now = nb[..., 6] * RANGE_KM

        # own velocity (east, north) in km/s
        heading = np.arctan2(obs[:, 2], obs[:, 3])
        speed_kt = NOMINAL_KT + HALF_RANGE_KT * obs[:, 4]
        v_own = np.stack([np.sin(heading), np.cos(heading)], -1) * (speed_kt * KT_TO_KM_S)[:, None]

        # 1. detection at the own level
        t, d = _cpa(rel, vrel, LOOKAHEAD_S)
        conflict = present & (dlev == 0) & ((d < PZ_KM) | (now < PZ_KM))
        any_conflict = conflict.any(1)

        # 2. vertical escape: a feasible adjacent level with nothing observed near it
        tl, dl = _cpa(rel, vrel, LEVEL_LOOKAHEAD_S)
        near = present & ((dl < LEVEL_PZ_KM) | (now < LEVEL_PZ_KM))
        climb_ok = masks[:, 9 * 1 + 3 * 1 + 2] > 0  # (0, 0, +1) feasible
        descend_ok = masks[:, 9 * 1 + 3 * 1 + 0] > 0
        up_free = climb_ok & ~(near & (dlev == 1)).any(1)
        down_free = descend_ok & ~(near & (dlev == -1)).any(1)
        # the freer level: larger distance to its closest observed aircraft
        up_gap = np.where(present & (dlev == 1), dl, np.inf).min(1)
        down_gap = np.where(present & (dlev == -1), dl, np.inf).min(1)
        a_h = np.where(
            up_free & down_free,
            np.where(up_gap >= down_gap, 1, -1),
            np.where(up_free, 1, np.where(down_free, -1, 0)),
        )
        a_h = np.where(any_conflict, a_h, 0)

        # 3. horizontal MVP for conflicts that no level change resolves
        r_cpa = rel + vrel * t[..., None]  # intruder relative to own at CPA
        dist_cpa = np.linalg.norm(r_cpa, axis=-1)
        # head-on (d_cpa ~ 0): push perpendicular to the relative velocity, to the right
        perp = np.stack([vrel[..., 1], -vrel[..., 0]], -1)
        direction = np.where(
            (dist_cpa > 0.1)[..., None],
            r_cpa / np.maximum(dist_cpa, 1e-9)[..., None],
            -perp / np.maximum(np.linalg.norm(perp, axis=-1), 1e-9)[..., None],
        )
        intrusion = np.maximum(PZ_KM - d, 0.0)
        push = -direction * intrusion[..., None] / np.maximum(t, DT_S)[..., None]
        dv = np.where(conflict[..., None], push, 0.0).sum(1)
        wanted = v_own + dv

        # candidate (a_psi, a_v): new velocity of each of the 9 combinations
        a_psi = np.array([-1, -1, -1, 0, 0, 0, 1, 1, 1])
        a_v = np.array([-1, 0, 1, -1, 0, 1, -1, 0, 1])
        h_new = heading[:, None] + np.radians(HEADING_STEP_DEG) * a_psi[None]
        s_new = np.clip(speed_kt[:, None] + SPEED_STEP_KT * a_v[None], MIN_KT, MAX_KT)
        v_new = np.stack([np.sin(h_new), np.cos(h_new)], -1) * (s_new * KT_TO_KM_S)[..., None]
        best = np.argmin(((v_new - wanted[:, None, :]) ** 2).sum(-1), axis=1)
        psi_res, v_res = a_psi[best], a_v[best]

        # 4. no conflict (or escaping vertically): fly to the goal at nominal speed
        rel_goal = np.degrees(np.arctan2(obs[:, 9], obs[:, 10]))
        psi_goal = np.where(rel_goal > HALF_TURN_DEG, 1, np.where(rel_goal < -HALF_TURN_DEG, -1, 0))
        v_goal = np.where(
            speed_kt < NOMINAL_KT - 25, 1, np.where(speed_kt > NOMINAL_KT + 25, -1, 0)
        )
        horizontal = any_conflict & (a_h == 0)
        psi = np.where(horizontal, psi_res, psi_goal)
        v = np.where(horizontal, v_res, v_goal)
        return 9 * (psi + 1) + 3 * (v + 1) + (a_h + 1)
