"""The airspace simulator: numpy, vectorised over aircraft and over a batch of episodes.

Two kinds of aircraft share the sky:

* **controlled** aircraft (index ``m`` in ``0..M-1``): the ownship (``m = 0``) and the learning
  intruders (``m = 1..``). They take one of the 27 actions every step.
* **background** aircraft (index ``b`` in ``0..B-1``): airway traffic (``R`` routes times ``C``
  slots each, first) and explicitly placed aircraft (last). They fly straight at constant speed
  and level and never react.

Arrays carry a leading episode axis ``E``; a single environment uses ``E = 1``. Every episode
owns its seed, so episode ``e`` evolves identically whatever else is in the batch.

One step (``dt_s``): the action is applied at the start (new heading, clipped speed, target
level); every aircraft then flies a straight segment. Separation is judged over the whole
segment (closest point of approach clipped to ``[0, dt_s]``); an aircraft changing level
occupies both levels for that step. The goal test is swept the same way. Then aircraft at the
end of their airway leave, and due spawns enter unless a controlled aircraft at the spawn
level is within ``spawn_clearance_km``.
"""

from __future__ import annotations

import operator
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from cdr_bench.actions import TRIPLES, action_mask
from cdr_bench.scenarios.schema import ScenarioConfig
from cdr_bench.sim.geometry import bearing_deg, heading_to_unit
from cdr_bench.sim.units import KM_PER_S_PER_KT

N_LEVELS = 3

# Outcome codes of a controlled aircraft (0 while it flies).
RUNNING, SUCCESS, NMAC, LOS, BOUNDARY, TIMEOUT = 0, 1, 2, 3, 4, 5
OUTCOME_NAMES = {
    SUCCESS: "success",
    NMAC: "nmac",
    LOS: "los",
    BOUNDARY: "boundary",
    TIMEOUT: "timeout",
}

_OUTCOME_CODES = [np.int8(c) for c in range(6)]  # as int8 scalars, so np.where keeps int8

REWARD_TERMS = ("goal", "path", "boundary", "step", "timeout", "los", "nmac")
"""Named reward terms. The goal part R_G sums the first five, the safety part R_S the last two."""
GOAL_TERMS = REWARD_TERMS[:5]
SAFETY_TERMS = REWARD_TERMS[5:]


@dataclass
class StepResult:
    """What happened to every controlled aircraft during one step; arrays shaped (E, M).

    ``los_with`` / ``nmac_with`` are (E, M, B + M): which other aircraft (background first, then
    controlled) were in LoS / NMAC with it during the step.
    """

    acting: NDArray[np.bool_]
    """aircraft that were flying at the start of the step"""
    rewards: dict[str, NDArray[np.float64]]
    """named reward terms, see :data:`REWARD_TERMS`"""
    los_with: NDArray[np.bool_]
    nmac_with: NDArray[np.bool_]
    invalid_action: NDArray[np.bool_]
    """a masked level change was requested (and not executed)"""
    outside: NDArray[np.bool_]
    """outside the sector at the end of the step"""
    reached_goal: NDArray[np.bool_]
    terminated: NDArray[np.bool_]
    truncated: NDArray[np.bool_]
    outcome: NDArray[np.int8]
    """outcome code if the aircraft finished this step, else RUNNING"""
    min_sep_km: NDArray[np.float64]
    """smallest swept horizontal distance to any same-level aircraft (inf if none)"""


@dataclass(frozen=True, slots=True)
class _EpisodeViews:
    """1-D views of episode 0 of a :class:`Simulator`'s arrays (single-episode path)."""

    pc: NDArray[np.complex128]
    vc: NDArray[np.complex128]
    pcg: NDArray[np.complex128]
    vcg: NDArray[np.complex128]
    own: NDArray[np.complex128]
    own_v: NDArray[np.complex128]
    kin: NDArray[np.complex128]
    """(2, N + M): positions, velocities"""
    own_kin: NDArray[np.complex128]
    """(2, M)"""
    goal: NDArray[np.complex128]
    level: NDArray[np.int64]
    active: NDArray[np.bool_]
    active_all: NDArray[np.bool_]
    row_offset: NDArray[np.int64]
    ac_active: NDArray[np.bool_]
    arc_all: NDArray[np.float64]
    bg_arc: NDArray[np.float64]
    last_arc: NDArray[np.float64]
    route_active: NDArray[np.bool_]
    count: NDArray[np.int64]
    pos: NDArray[np.float64]


@dataclass(slots=True)
class SingleStepResult:
    """A :class:`StepResult` of a single-episode simulator (``E = 1``) in Python scalars.

    Per-aircraft fields are lists of length ``M``; ``los_with`` / ``nmac_with`` keep the
    (1, M, B + M) arrays of :class:`StepResult` (a shared read-only array of ``False`` when the
    step had no event). Every value equals the one :meth:`Simulator.step` gives.
    """

    acting: list[bool]
    rewards: list[dict[str, float]]
    """named reward terms of each aircraft"""
    los_with: NDArray[np.bool_]
    nmac_with: NDArray[np.bool_]
    invalid_action: list[bool]
    outside: list[bool]
    reached_goal: list[bool]
    terminated: list[bool]
    truncated: list[bool]
    outcome: list[int]
    min_sep_km: list[float]


def sq(x: float) -> float:
    """x * x, which is numpy's ``x ** 2``; Python's ``x ** 2`` calls ``pow`` (may round apart)."""
    return x * x


def _clip(x: float, lo: float, hi: float) -> float:
    """``np.minimum(np.maximum(x, lo), hi)`` on floats, ties resolved as numpy does (to the
    second argument, which matters for the sign of a zero)."""
    x = x if x > lo else lo
    return x if x < hi else hi


def _as_single(r: StepResult) -> SingleStepResult:
    return SingleStepResult(
        acting=r.acting[0].tolist(),
        rewards=[{k: v.item(0, m) for k, v in r.rewards.items()} for m in range(r.acting.shape[1])],
        los_with=r.los_with,
        nmac_with=r.nmac_with,
        invalid_action=r.invalid_action[0].tolist(),
        outside=r.outside[0].tolist(),
        reached_goal=r.reached_goal[0].tolist(),
        terminated=r.terminated[0].tolist(),
        truncated=r.truncated[0].tolist(),
        outcome=r.outcome[0].tolist(),
        min_sep_km=r.min_sep_km[0].tolist(),
    )


class Simulator:
    """A batch of ``n_episodes`` independent episodes of one scenario.

    Call :meth:`reset` with one seed per episode (or a subset of episodes), then :meth:`step`
    with one action index per controlled aircraft. Read state from the public arrays.
    """

    def __init__(self, config: ScenarioConfig, n_episodes: int = 1):
        if n_episodes < 1:
            raise ValueError(f"n_episodes must be >= 1, got {n_episodes}")
        self.config = config
        self.E = n_episodes
        cfg = config
        self.size_km = cfg.sector.size_km
        self.dt_s = cfg.time.dt_s
        self.max_steps = cfg.time.max_steps

        # Airways (the first `routes` of the network carry traffic).
        R = cfg.traffic.routes
        n = cfg.traffic.per_route
        self.R, self.per_route = R, n
        self.C = n + 2 if R else 0  # slots per route: n in steady state, spare for delayed spawns
        ways = cfg.airways[:R]
        self.route_start_km = np.array([w.start_km for w in ways], dtype=float).reshape(R, 2)
        route_end = np.array([w.end_km for w in ways], dtype=float).reshape(R, 2)
        vec = route_end - self.route_start_km
        self.route_length_km = np.linalg.norm(vec, axis=1)
        self.route_unit = vec / np.maximum(self.route_length_km, 1e-9)[:, None]
        self.route_spacing_km = self.route_length_km / max(n, 1)
        self.traffic_speed_km_s = cfg.traffic.speed_kt * KM_PER_S_PER_KT
        self.X = len(cfg.aircraft)
        self.B = R * self.C + self.X
        self.slot_route = np.repeat(np.arange(R), self.C)  # (R*C,)

        # Controlled aircraft: ownship + learning intruders.
        self.M = 1 + cfg.n_learning_intruders
        o = cfg.ownship
        self.min_speed_kt, self.max_speed_kt = o.min_speed_kt, o.max_speed_kt
        self.heading_step_deg, self.speed_step_kt = o.heading_step_deg, o.speed_step_kt
        self.los_km, self.nmac_km = cfg.separation.los_km, cfg.separation.nmac_km

        E, B, M = self.E, self.B, self.M
        N = B + M
        self.N = N
        # All aircraft in one set of arrays, background first (0..B-1), controlled last
        # (B..B+M-1); the bg_* / ac_* attributes are views into them.
        # Positions and velocities live in (E, N + M, 2) buffers whose last M entries are the
        # goals (a goal is a fixed point: velocity 0), so that the single-episode path sweeps
        # the goal test with the separation test; pos_km, vel_km_s and ac_goal_km are views.
        # Both in one (2, E, N + M, 2) buffer: the single-episode path forms relative positions
        # and velocities with one subtraction.
        self._kin_all = np.zeros((2, E, N + M, 2))
        self.level = np.zeros((E, N), dtype=np.int64)
        self._active_all = np.zeros((E, N + M), dtype=bool)  # the goals are never active
        # Arc flown by each airway slot, then by the newest aircraft of each route: one buffer,
        # so that the single-episode path advances both with one call (views below).
        self._arc_all = np.zeros((E, R * self.C + R))
        self.route_spawn_count = np.zeros((E, R), dtype=np.int64)
        self.route_waiting = np.zeros((E, R), dtype=bool)

        self.ac_heading_deg = np.zeros((E, M))
        self.ac_speed_kt = np.zeros((E, M))
        self.ac_outcome = np.zeros((E, M), dtype=np.int8)
        self.steps = np.zeros(E, dtype=np.int64)
        not_self = np.ones((M, N), dtype=bool)
        not_self[np.arange(M), B + np.arange(M)] = False
        self._not_self = not_self[None]  # (1, M, N): a controlled aircraft is not its own neighbour
        self._route_len_slot = self.route_length_km[self.slot_route]  # (R*C,)

        # Cached for speed: at E = 1 numpy's per-call overhead, not arithmetic, is the cost of a
        # step, so constant work is done once here.
        self._bind_views()
        # Per action index: heading change (deg), speed change (kt); per (level, action): the
        # level after the action and whether the level change is infeasible (not executed).
        self._turn_deg = self.heading_step_deg * TRIPLES[:, 0]
        self._speed_change_kt = self.speed_step_kt * TRIPLES[:, 1]
        lv = np.arange(N_LEVELS)[:, None]
        target = lv + TRIPLES[None, :, 2]
        self._level_change_invalid = (target < 0) | (target >= N_LEVELS)  # (levels, 27)
        self._level_after = np.where(self._level_change_invalid, lv, target)
        self._traffic_step_km = self.traffic_speed_km_s * self.dt_s
        self._route_vel_km_s = self.route_unit * self.traffic_speed_km_s  # (R, 2)
        # Flat offsets of row (e, m) in (E, M, N) arrays and of episode e in (E, N) arrays, for
        # gathering per-row neighbours with .take instead of three-array fancy indexing.
        self._pair_offset = (np.arange(E * M) * N).reshape(E, M, 1)
        self._episode_offset = (np.arange(E) * N).reshape(E, 1, 1)
        # Python-scalar copies for the single-episode path (:meth:`step_one`).
        self._turn_list = self._turn_deg.tolist()
        self._speed_change_list = self._speed_change_kt.tolist()
        self._level_after_list = self._level_after.tolist()
        self._invalid_list = self._level_change_invalid.tolist()
        self._route_xy = np.concatenate([self.route_start_km, self.route_unit], axis=1).tolist()
        self._no_events = np.zeros((1, M, N), dtype=bool)
        self._no_events.flags.writeable = False
        self._spacing_list = self.route_spacing_km.tolist()
        self._route_vel_c = self._route_vel_km_s.view(np.complex128)[:, 0].tolist()
        # _judge[mask, occ]: an aircraft occupying the levels in bit mask ``mask`` is judged
        # against one occupying ``occ`` (0 when not in the sky) when they share a level.
        self._judge = (np.arange(8)[:, None] & np.arange(8)[None, :]) != 0
        self._heading_trig: dict[float, tuple[complex, float, float, complex]] = {}

    _VIEWS = (
        "pos_km",
        "vel_km_s",
        "ac_goal_km",
        "bg_arc_km",
        "route_last_arc_km",
        "active",
        "_pc",
        "_vc",
        "_pcg",
        "_vcg",
        "_goal_c",
        "_ac_active",
        "_one",
    )

    def _bind_views(self) -> None:
        N = self.N
        pos_all, vel_all = self._kin_all
        self.pos_km = pos_all[:, :N]  # (E, N, 2) km
        self.vel_km_s = vel_all[:, :N]  # (E, N, 2) km/s
        self.ac_goal_km = pos_all[:, N:]  # (E, M, 2) km
        # As complex numbers (east = real, north = imag).
        kin_c = self._kin_all.view(np.complex128)[..., 0]  # (2, E, N + M)
        self._pcg = kin_c[0]  # (E, N + M): aircraft, then goals
        self._vcg = kin_c[1]
        self._pc = self._pcg[:, :N]
        self._vc = self._vcg[:, :N]
        self._goal_c = self._pcg[:, N:]
        self.active = self._active_all[:, :N]  # (E, N) in the sky
        self._ac_active = self.active[:, self.B :]
        RC = self.R * self.C
        self.bg_arc_km = self._arc_all[:, :RC]  # (E, R*C) km
        self.route_last_arc_km = self._arc_all[:, RC:]  # (E, R) km
        # Episode 0's 1-D views, for the single-episode path.
        self._one = _EpisodeViews(
            pc=self._pc[0],
            vc=self._vc[0],
            pcg=self._pcg[0],
            vcg=self._vcg[0],
            own=self._pcg[0, self.B : N],
            own_v=self._vcg[0, self.B : N],
            kin=kin_c[:, 0],
            own_kin=kin_c[:, 0, self.B : N],
            goal=self._goal_c[0],
            level=self.level[0],
            active=self.active[0],
            active_all=self._active_all[0],
            row_offset=np.arange(self.M)[:, None] * (N + self.M),
            ac_active=self._ac_active[0],
            arc_all=self._arc_all[0],
            bg_arc=self.bg_arc_km[0],
            last_arc=self.route_last_arc_km[0],
            route_active=self.active[0, :RC],
            count=self.route_spawn_count[0],
            pos=self.pos_km[0],
        )

    def __getstate__(self) -> dict[str, object]:
        # Copies and pickles must not carry the views (they would become independent arrays).
        drop = self._VIEWS
        return {k: v for k, v in self.__dict__.items() if k not in drop}

    def __setstate__(self, state: dict[str, object]) -> None:
        self.__dict__.update(state)
        self._bind_views()

    # Views of the combined arrays (in-place writes go through to them).
    bg_pos_km = property(lambda self: self.pos_km[:, : self.B], doc="(E, B, 2) km")
    bg_vel_km_s = property(lambda self: self.vel_km_s[:, : self.B], doc="(E, B, 2) km/s")
    bg_level = property(lambda self: self.level[:, : self.B], doc="(E, B) level index")
    bg_active = property(lambda self: self.active[:, : self.B], doc="(E, B) in the sky")
    ac_pos_km = property(lambda self: self.pos_km[:, self.B :], doc="(E, M, 2) km")
    ac_level = property(lambda self: self.level[:, self.B :], doc="(E, M) level index")
    ac_active = property(lambda self: self.active[:, self.B :], doc="(E, M) still flying")

    # ------------------------------------------------------------------------------------------
    # Reset

    def reset(
        self, seeds: list[int] | NDArray[np.integer], episodes: NDArray[np.integer] | None = None
    ) -> None:
        """Start episodes ``episodes`` (default: all) from ``seeds`` (one per episode)."""
        idx = np.arange(self.E) if episodes is None else np.asarray(episodes)
        seeds = list(np.asarray(seeds).reshape(-1))
        if len(seeds) != len(idx):
            raise ValueError(f"expected {len(idx)} seeds, got {len(seeds)}")
        for e, seed in zip(idx, seeds, strict=True):
            self._reset_one(int(e), np.random.default_rng(int(seed)))

    def _reset_one(self, e: int, rng: np.random.Generator) -> None:
        cfg = self.config
        for _attempt in range(200):
            self._populate_traffic(e, rng)
            if self._place_controlled(e, rng):
                break
        else:
            raise RuntimeError(
                f"scenario {cfg.id!r}: no start with the required clearance found in 200 draws"
            )
        self.ac_outcome[e] = RUNNING
        self.ac_active[e] = True
        self.steps[e] = 0
        ang = np.deg2rad(90.0 - self.ac_heading_deg[e])
        self.vel_km_s.view(np.complex128)[e, self.B :, 0] = np.exp(1j * ang) * (
            self.ac_speed_kt[e] * KM_PER_S_PER_KT
        )

    def _populate_traffic(self, e: int, rng: np.random.Generator) -> None:
        """Steady state: each route holds ``per_route`` aircraft one spacing apart, random phase."""
        R, C, n = self.R, self.C, self.per_route
        self.active[e] = False
        if R:
            phase = rng.uniform(0.0, 1.0, R) * self.route_spacing_km  # arc of the newest, km
            last_level = rng.integers(0, N_LEVELS, R)
            j = np.arange(n)
            arcs = phase[:, None] + j[None, :] * self.route_spacing_km[:, None]  # (R, n)
            levels = (last_level[:, None] - j[None, :]) % N_LEVELS  # older ones spawned earlier
            slot = (np.arange(R)[:, None] * C + j[None, :]).reshape(-1)
            arcs_f = arcs.reshape(-1)
            r_f = np.repeat(np.arange(R), n)
            self.bg_arc_km[e] = 0.0
            self.bg_arc_km[e, slot] = arcs_f
            self.bg_pos_km[e, slot] = (
                self.route_start_km[r_f] + arcs_f[:, None] * self.route_unit[r_f]
            )
            self.bg_vel_km_s[e, slot] = self.route_unit[r_f] * self.traffic_speed_km_s
            self.bg_level[e, slot] = levels.reshape(-1)
            self.bg_active[e, slot] = arcs_f < self.route_length_km[r_f]
            self.route_last_arc_km[e] = phase
            self.route_spawn_count[e] = last_level + 1
            self.route_waiting[e] = False
        for i, a in enumerate(self.config.aircraft):
            b = R * C + i
            self.bg_pos_km[e, b] = a.position_km
            self.bg_vel_km_s[e, b] = heading_to_unit(np.array(a.heading_deg)) * (
                a.speed_kt * KM_PER_S_PER_KT
            )
            self.bg_level[e, b] = a.level
            self.bg_active[e, b] = True

    def _clear_of_traffic(
        self,
        e: int,
        points_km: NDArray[np.float64],
        clearance_km: float,
        level: NDArray[np.integer] | None = None,
    ) -> NDArray[np.bool_]:
        """Which candidate points are at least ``clearance_km`` from every background aircraft
        (any level, or only those at ``level`` when given)."""
        act = self.bg_active[e]
        pos = self.bg_pos_km[e, act]
        if pos.shape[0] == 0:
            return np.ones(points_km.shape[0], dtype=bool)
        d = np.linalg.norm(points_km[:, None, :] - pos[None], axis=-1)
        if level is not None:
            d = np.where(self.bg_level[e, act][None, :] == np.asarray(level)[:, None], d, np.inf)
        return (d >= clearance_km).all(axis=1)

    def _place_controlled(self, e: int, rng: np.random.Generator) -> bool:
        cfg, o, size = self.config, self.config.ownship, self.size_km
        clearance = o.start_clearance_km
        # Learning intruders first: at the entry of their airway, on a level clear of traffic.
        placed: list[NDArray[np.float64]] = []
        for k, li in enumerate(cfg.learning_intruders, start=1):
            way = cfg.airways[li.airway]
            start = np.array(way.start_km, dtype=float)
            levels = rng.permutation(N_LEVELS)
            ok = self._clear_of_traffic(e, np.repeat(start[None], N_LEVELS, 0), clearance, levels)
            if placed:
                ok &= min(np.linalg.norm(start - p) for p in placed) >= clearance
            if not ok.any():
                return False
            vec = np.subtract(way.end_km, way.start_km)
            self.ac_pos_km[e, k] = start
            self.ac_heading_deg[e, k] = bearing_deg(vec[0], vec[1])
            self.ac_speed_kt[e, k] = o.speed_kt
            self.ac_level[e, k] = levels[np.argmax(ok)]
            self.ac_goal_km[e, k] = way.end_km
            placed.append(start)
        # Ownship.
        if o.start is not None:
            assert o.goal_km is not None
            self.ac_pos_km[e, 0] = o.start.position_km
            self.ac_heading_deg[e, 0] = o.start.heading_deg
            self.ac_speed_kt[e, 0] = o.start.speed_kt
            self.ac_level[e, 0] = o.start.level
            self.ac_goal_km[e, 0] = o.goal_km
            return True
        goal = rng.uniform(o.goal_margin_km, size - o.goal_margin_km, 2)
        level = rng.integers(0, N_LEVELS)
        n_cand = 64
        perim = rng.uniform(0.0, 4.0 * size, n_cand)
        side, u = np.divmod(perim, size)
        cand = np.select(
            [side[:, None] == 0, side[:, None] == 1, side[:, None] == 2],
            [
                np.stack([u, np.zeros_like(u)], 1),
                np.stack([np.full_like(u, size), u], 1),
                np.stack([size - u, np.full_like(u, size)], 1),
            ],
            np.stack([np.zeros_like(u), size - u], 1),
        )
        ok = self._clear_of_traffic(e, cand, clearance)
        for p in placed:
            ok &= np.linalg.norm(cand - p, axis=1) >= clearance
        if not ok.any():
            return False
        start = cand[np.argmax(ok)]
        self.ac_pos_km[e, 0] = start
        self.ac_heading_deg[e, 0] = bearing_deg(goal[0] - start[0], goal[1] - start[1])
        self.ac_speed_kt[e, 0] = o.speed_kt
        self.ac_level[e, 0] = level
        self.ac_goal_km[e, 0] = goal
        return True

    # ------------------------------------------------------------------------------------------
    # Step

    def velocities_km_s(self) -> NDArray[np.float64]:
        """Velocity of every controlled aircraft, (E, M, 2) km/s (zero once it has left)."""
        return self.vel_km_s[:, self.B :]

    def _set_controlled_velocity(self) -> None:
        # heading h clockwise from north: (east, north) = (sin h, cos h) = Re/Im of e^{i(90°-h)}
        ang = np.deg2rad(90.0 - self.ac_heading_deg)
        self._vc[:, self.B :] = np.exp(1j * ang) * (
            self.ac_speed_kt * KM_PER_S_PER_KT * self._ac_active
        )

    def step(self, actions: NDArray[np.integer]) -> StepResult:
        """Advance every episode by one step.

        Args:
            actions: (E, M) action indices in 0..26; entries of aircraft that are not flying
                are ignored. Validation of the values is the caller's job.
        """
        cfg, dt, B = self.config, self.dt_s, self.B
        acting = self._ac_active.copy()
        live = np.logical_or.reduce(acting, axis=1)  # (E,)
        # Aircraft that are not flying hold (index 13), which is never an invalid level change.
        act = np.where(acting, np.asarray(actions).reshape(self.E, self.M), 13)

        # 1. Apply the action at the start of the step (heading, clipped speed, target level).
        old_level = self.level[:, B:]
        invalid = self._level_change_invalid[old_level, act]
        new_level = self._level_after[old_level, act]
        self.ac_heading_deg = (self.ac_heading_deg + self._turn_deg[act]) % 360.0
        self.ac_speed_kt = np.minimum(
            np.maximum(self.ac_speed_kt + self._speed_change_kt[act], self.min_speed_kt),
            self.max_speed_kt,
        )
        self._set_controlled_velocity()

        # 2. Swept separation: closest approach over [0, dt] of every controlled aircraft
        #    against every other aircraft, complex numbers as 2-D vectors.
        pc, vc = self._pc, self._vc  # (E, N)
        rp = pc[:, None, :] - pc[:, B:, None]  # (E, M, N)
        rv = vc[:, None, :] - vc[:, B:, None]
        t = -(rp * rv.conj()).real / (np.abs(rv) ** 2 + 1e-300)
        d_min = np.abs(rp + rv * np.minimum(np.maximum(t, 0.0), dt))
        occ = 1 << self.level
        occ[:, B:] |= 1 << new_level  # a level change occupies both levels for the step
        judged = (occ[:, B:, None] & occ[:, None, :]) != 0
        judged &= self.active[:, None, :]
        judged &= self._not_self
        judged &= acting[:, :, None]
        d_judged = np.where(judged, d_min, np.inf)
        nmac_with = d_judged < self.nmac_km
        los_with = d_judged < self.los_km
        n_nmac = np.add.reduce(nmac_with, axis=2)
        n_los = np.add.reduce(los_with, axis=2)  # NMAC distance < LoS distance: includes NMACs

        # 3. Swept goal test (the goal is a fixed point).
        gc = self._goal_c - pc[:, B:]
        va = vc[:, B:]
        tg = np.minimum(np.maximum((gc * va.conj()).real / (np.abs(va) ** 2 + 1e-300), 0.0), dt)
        reached = acting & (np.abs(gc - va * tg) < cfg.ownship.goal_radius_km)

        # 4. Move.
        self.pos_km += self.vel_km_s * dt
        self.level[:, B:] = new_level
        self.steps += live
        self._advance_traffic(live)

        # 5. Outcomes (priority nmac > los > boundary > success) and named rewards. Every
        #    condition below is already False for aircraft that were not acting.
        size = self.size_km
        p = self.pos_km[:, B:]
        outside = acting & np.logical_or.reduce((p < 0.0) | (p > size), axis=2)
        code = _OUTCOME_CODES
        outcome = np.where(reached, code[SUCCESS], code[RUNNING])
        if cfg.sector.boundary_terminates:
            outcome = np.where(outside, code[BOUNDARY], outcome)
        if cfg.separation.los_terminates:
            outcome = np.where(n_los > 0, code[LOS], outcome)
        outcome = np.where(n_nmac > 0, code[NMAC], outcome)
        terminated = outcome != RUNNING
        at_horizon = self.steps >= self.max_steps  # (E,)
        if np.count_nonzero(at_horizon):
            truncated = acting & ~terminated & at_horizon[:, None]
            outcome[truncated] = TIMEOUT
        else:
            truncated = np.zeros_like(terminated)

        w = cfg.reward
        d_goal = np.abs(gc - va * dt)
        rewards = {
            "goal": w.goal * (outcome == SUCCESS),
            "path": (-w.path / size**2) * d_goal**2 * acting,
            "boundary": -w.boundary * outside,
            "step": -w.step * acting,
            "timeout": -w.timeout * truncated,
            "los": -w.los * (n_los - n_nmac),
            "nmac": -w.nmac * n_nmac,
        }

        finished = terminated | truncated
        if np.count_nonzero(finished):
            np.copyto(self.ac_outcome, outcome, where=finished)
            self._ac_active[...] = acting & ~finished
        vc[:, B:] *= self._ac_active  # aircraft that left stop moving
        return StepResult(
            acting=acting,
            rewards=rewards,
            los_with=los_with,
            nmac_with=nmac_with,
            invalid_action=invalid,
            outside=outside,
            reached_goal=reached,
            terminated=terminated,
            truncated=truncated,
            outcome=outcome,
            min_sep_km=np.minimum.reduce(d_judged, axis=2, initial=np.inf),
        )

    def _trig(self, heading_deg: float) -> tuple[complex, float, float, complex]:
        """Of a heading in degrees: the unit velocity e^{i(90° - h)} (east, north as real,
        imaginary), sin h, cos h and e^{i(h - 90°)}, computed by numpy exactly as :meth:`step`
        and :func:`observe` compute them, and cached (headings repeat: turns are steps)."""
        v = self._heading_trig.get(heading_deg)
        if v is None:
            hd = np.array([heading_deg])
            h = np.deg2rad(hd)
            v = (
                np.exp(1j * np.deg2rad(90.0 - hd)).item(),
                np.sin(h).item(),
                np.cos(h).item(),
                np.exp(1j * (h - np.pi / 2)).item(),
            )
            if heading_deg != 0.0:  # 0.0 and -0.0 share a key but not a sine
                if len(self._heading_trig) >= 65536:
                    self._heading_trig.clear()
                self._heading_trig[heading_deg] = v
        return v

    def step_one(self, actions: Sequence[int]) -> SingleStepResult:
        """:meth:`step` of a single-episode simulator (``E = 1``): what the PettingZoo env calls.

        The same model with bit-identical results (a test compares every state array, result
        and observation with :meth:`step` over thousands of random steps on every shipped
        scenario), faster: at ``E = 1`` numpy's fixed cost per call, not arithmetic, is the
        cost of a step, so the per-aircraft work of the controlled aircraft is done on Python
        floats and numpy is kept for the work over all aircraft. Operations whose result numpy
        may round differently from Python -- complex products and magnitudes (numpy's SIMD
        loops may fuse multiply-adds) and transcendental functions -- stay in numpy; only
        ``+ - * /``, ``%``, comparisons, min/max and degree-to-radian scaling, which IEEE 754
        rounds the same everywhere, move to Python.

        Args:
            actions: ``M`` action indices in 0..26, validated by the caller; aircraft that are
                not flying hold.
        """
        if self.E != 1:
            raise ValueError(f"step_one needs a single-episode simulator, this one has E={self.E}")
        B, M, dt = self.B, self.M, self.dt_s
        one = self._one
        acting = one.ac_active.tolist()
        if not any(acting):  # nothing flies: the general path (traffic still moves)
            return _as_single(self.step(np.asarray(actions).reshape(1, M)))
        cfg = self.config
        vc, lvl = one.vc, one.level

        # 1. Apply the actions (heading, clipped speed, target level).
        heading = self.ac_heading_deg[0].tolist()
        speed = self.ac_speed_kt[0].tolist()
        old_level = lvl[B:].tolist()
        invalid, new_level = [], []
        lo, hi = self.min_speed_kt, self.max_speed_kt
        for m in range(M):
            a = actions[m] if acting[m] else 13
            lv = old_level[m]
            invalid.append(self._invalid_list[lv][a])
            new_level.append(self._level_after_list[lv][a])
            h = (heading[m] + self._turn_list[a]) % 360.0
            heading[m] = h
            speed[m] = _clip(speed[m] + self._speed_change_list[a], lo, hi)
            vc[B + m] = self._trig(h)[0] * (speed[m] * KM_PER_S_PER_KT * acting[m])
        hd, sp = self.ac_heading_deg[0], self.ac_speed_kt[0]
        for m in range(M):
            hd[m] = heading[m]
            sp[m] = speed[m]

        # 2. Swept separation against every aircraft (as in step()).
        # Occupied levels as bit masks, 0 for aircraft not in the sky; the controlled aircraft
        # occupy their old and new level.
        occ = np.left_shift(one.active, lvl)
        masks = [(1 << old_level[m] | 1 << new_level[m]) * acting[m] for m in range(M)]
        for m in range(M):
            occ[B + m] = masks[m]
        if M == 1:
            judged = self._judge[masks[0]].take(occ)[None]  # (1, N)
        else:
            judged = self._judge[masks].take(occ, axis=1)  # (M, N)
        for m in range(M):
            judged[m, B + m] = False  # not its own neighbour
        # Swept over [0, dt] against every aircraft and, in the same arrays, against the goals
        # (the last M columns: fixed points), the goal test of step() to the last bit. With
        # q = -t of step(), u = clip(q, -dt, 0) = -clip(t, 0, dt) and rp - rv u = rp + rv t
        # exactly (IEEE rounding is symmetric in sign), one negation fewer.
        N = self.N
        rp, rv = one.kin[:, None, :] - one.own_kin[:, :, None]  # each (M, N + M)
        q = (rp * rv.conj()).real / (np.abs(rv) ** 2 + 1e-300)
        d_min = np.abs(rp - rv * np.maximum(np.minimum(q, 0.0), -dt))
        d_air = d_min[:, :N]
        min_sep = np.minimum.reduce(d_air, axis=1, initial=np.inf, where=judged).tolist()
        if min(min_sep) < self.los_km:
            d_judged = np.where(judged, d_air, np.inf)
            nmac_with = (d_judged < self.nmac_km)[None]
            los_with = (d_judged < self.los_km)[None]
            n_nmac = np.add.reduce(nmac_with[0], axis=1).tolist()
            n_los = np.add.reduce(los_with[0], axis=1).tolist()
        else:
            nmac_with = los_with = self._no_events
            n_nmac = n_los = [0] * M

        # 3. Swept goal test (above) and |goal - v dt| of the path term.
        reach = [d_min.item(m, N + m) for m in range(M)]
        own, goal, vel = one.own.tolist(), one.goal.tolist(), one.own_v.tolist()
        miss = np.abs([goal[m] - own[m] - vel[m] * dt for m in range(M)]).tolist()
        goal_r = cfg.ownship.goal_radius_km

        # 4. Move.
        self.pos_km += self.vel_km_s * dt
        for m in range(M):
            lvl[B + m] = new_level[m]
        self.steps[0] += 1
        self._advance_traffic_one()

        # 5. Outcomes and named rewards, aircraft by aircraft.
        size = self.size_km
        xy = one.pos[B:].tolist()
        w = cfg.reward
        path_w = -w.path / size**2
        at_horizon = self.steps.item(0) >= self.max_steps
        boundary_ends = cfg.sector.boundary_terminates
        los_ends = cfg.separation.los_terminates
        rewards, outside, reached, terminated, truncated, outcome = [], [], [], [], [], []
        for m in range(M):
            x, y = xy[m]
            on = acting[m]
            out = on and (x < 0.0 or x > size or y < 0.0 or y > size)
            hit = on and reach[m] < goal_r
            code = SUCCESS if hit else RUNNING
            if boundary_ends and out:
                code = BOUNDARY
            if los_ends and n_los[m] > 0:
                code = LOS
            if n_nmac[m] > 0:
                code = NMAC
            term = code != RUNNING
            trunc = on and not term and at_horizon
            if trunc:
                code = TIMEOUT
            rewards.append(
                {
                    "goal": w.goal * (code == SUCCESS),
                    "path": path_w * sq(miss[m]) * on,
                    "boundary": -w.boundary * out,
                    "step": -w.step * on,
                    "timeout": -w.timeout * trunc,
                    "los": -w.los * (n_los[m] - n_nmac[m]),
                    "nmac": -w.nmac * n_nmac[m],
                }
            )
            if term or trunc:
                self.ac_outcome[0, m] = code
                one.ac_active[m] = False
            outside.append(out)
            reached.append(hit)
            terminated.append(term)
            truncated.append(trunc)
            outcome.append(code)
        if not all(acting) or any(terminated) or any(truncated):
            vc[B:] *= one.ac_active  # aircraft that left stop moving (else a no-op)
        return SingleStepResult(
            acting=acting,
            rewards=rewards,
            los_with=los_with,
            nmac_with=nmac_with,
            invalid_action=invalid,
            outside=outside,
            reached_goal=reached,
            terminated=terminated,
            truncated=truncated,
            outcome=outcome,
            min_sep_km=min_sep,
        )

    def _advance_traffic_one(self) -> None:
        """:meth:`_advance_traffic` of a single live episode, spawns route by route."""
        R, C, B = self.R, self.C, self.B
        if self.X:
            p = self.pos_km[:, R * C : B]
            outside = ((p < 0.0) | (p > self.size_km)).any(axis=2)
            self.active[:, R * C : B] &= ~outside
        if not R:
            return
        one = self._one
        arc_all = one.arc_all
        arc_all += self._traffic_step_km  # every slot and every route's newest aircraft
        arr = one.route_active
        arr &= one.bg_arc < self._route_len_slot
        last = one.last_arc
        last_l = last.tolist()
        if not any(map(operator.ge, last_l, self._spacing_list)):
            return
        due = [r for r in range(R) if last_l[r] >= self._spacing_list[r]]
        B = self.B
        spacing = self._spacing_list
        waiting = self.route_waiting[0]
        count = one.count
        clearance = self.config.traffic.spawn_clearance_km
        flying = one.ac_active.tolist()
        ac_level = one.level[B:].tolist()
        own = one.own.tolist()
        spawns = []
        blocked_routes = []
        for r in due:
            arc = 0.0 if waiting[r] else last_l[r] - spacing[r]
            level = int(count[r]) % N_LEVELS
            sx, sy, ux, uy = self._route_xy[r]
            x, y = sx + arc * ux, sy + arc * uy
            near = [
                complex(x, y) - own[m] for m in range(self.M) if flying[m] and ac_level[m] == level
            ]
            if near and bool((np.abs(near) < clearance).any()):
                blocked_routes.append(r)
            else:
                spawns.append((r, arc, x, y, level))
        for r in due:  # a waiting route stays due until it spawns: others never wait
            waiting[r] = r in blocked_routes
        for r, arc, x, y, level in spawns:
            try:
                free = arr[r * C : (r + 1) * C].tolist().index(False)
            except ValueError:  # pragma: no cover - capacity n + 2 suffices
                raise RuntimeError("airway slot capacity exceeded") from None
            slot = r * C + free
            arr[slot] = True
            one.bg_arc[slot] = arc
            one.pc[slot] = complex(x, y)
            one.vc[slot] = self._route_vel_c[r]
            one.level[slot] = level
            last[r] = arc
            count[r] += 1

    def _advance_traffic(self, live: NDArray[np.bool_]) -> None:
        """Airway aircraft leave at the end of their route; due spawns enter when clear."""
        R, C, B = self.R, self.C, self.B
        if self.X:
            p = self.pos_km[:, R * C : B]
            outside = ((p < 0.0) | (p > self.size_km)).any(axis=2)
            self.active[:, R * C : B] &= ~outside
        if not R:
            return
        step_km = self._traffic_step_km
        self.bg_arc_km += step_km
        arr = self.active[:, : R * C]
        arr &= self.bg_arc_km < self._route_len_slot

        self.route_last_arc_km += step_km * live[:, None]
        due = (self.route_last_arc_km >= self.route_spacing_km) & live[:, None]
        if not np.count_nonzero(due):
            return
        arc = np.where(self.route_waiting, 0.0, self.route_last_arc_km - self.route_spacing_km)
        level = self.route_spawn_count % N_LEVELS
        pos = self.route_start_km + arc[..., None] * self.route_unit  # (E, R, 2)
        pc = pos.view(np.complex128)[..., 0]  # (E, R)
        d = np.abs(pc[:, :, None] - self._pc[:, None, B:])
        near = d < self.config.traffic.spawn_clearance_km
        near &= self._ac_active[:, None, :]
        near &= self.level[:, None, B:] == level[..., None]
        blocked = np.logical_or.reduce(near, axis=2)
        spawn = due & ~blocked
        self.route_waiting = due & blocked
        if not np.count_nonzero(spawn):
            return
        e_idx, r_idx = np.nonzero(spawn)
        free = np.argmin(arr.reshape(self.E, R, C)[e_idx, r_idx], axis=1)
        slot = r_idx * C + free
        if np.count_nonzero(arr[e_idx, slot]):  # pragma: no cover - capacity n + 2 suffices
            raise RuntimeError("airway slot capacity exceeded")
        self.active[e_idx, slot] = True
        self.bg_arc_km[e_idx, slot] = arc[e_idx, r_idx]
        self.pos_km[e_idx, slot] = pos[e_idx, r_idx]
        self.vel_km_s[e_idx, slot] = self._route_vel_km_s[r_idx]
        self.level[e_idx, slot] = level[e_idx, r_idx]
        np.copyto(self.route_last_arc_km, arc, where=spawn)
        self.route_spawn_count += spawn

    # ------------------------------------------------------------------------------------------
    # Derived quantities

    def action_masks(self) -> NDArray[np.int8]:
        """(E, M, 27) feasibility flags of every controlled aircraft."""
        return action_mask(self.level[:, self.B :], N_LEVELS)

    def intruder_count(self) -> NDArray[np.int64]:
        """Active background aircraft per episode, (E,)."""
        return self.bg_active.sum(axis=1)
