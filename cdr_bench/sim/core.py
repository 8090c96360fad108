"""The airspace simulator: a batch of ``E`` independent episodes of one scenario.

Two kinds of aircraft share the sky:

* **controlled** aircraft (index ``m`` in ``0..M-1``): the ownship (``m = 0``), the learning
  intruders (``m = 1..L``) and the controlled airway aircraft (``m = L+1..``,
  ``traffic.controlled``, then the ``traffic.controlled_spawns`` that enter later, in the order
  they enter: not in the sky, with no outcome, until then). They take one of the 27 actions
  every step.
* **background** aircraft (index ``b`` in ``0..B-1``): airway traffic (``R`` routes times ``C``
  slots each, first) and explicitly placed aircraft (last). They fly straight at constant speed
  and level and never react.

Every array carries a leading episode axis ``E``; the PettingZoo env is ``E = 1``, evaluation
and training use hundreds. Every episode owns its seed, so episode ``e`` evolves identically
whatever else is in the batch. The loops themselves are compiled (:mod:`cdr_bench.sim.kernels`);
this class owns the arrays and the constants derived from the scenario.

One step (``dt_s``, docs/model.md §3-§6): the action is applied at the start (new heading,
clipped speed, target level); every aircraft then flies a straight segment. Separation is
judged over the whole segment (closest point of approach clipped to ``[0, dt_s]``); an aircraft
changing level occupies both levels for that step. The goal test is swept the same way. Then
aircraft at the end of their airway leave, and due spawns enter unless a controlled aircraft at
the spawn level is within ``spawn_clearance_km``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cdr_bench.actions import N_ACTIONS, action_mask
from cdr_bench.errors import ScenarioError
from cdr_bench.scenarios.schema import Encounter, ScenarioConfig, range_bounds
from cdr_bench.sim import kernels as k
from cdr_bench.sim.geometry import exact_unit_vector, heading_deg
from cdr_bench.sim.observation import observation_bounds
from cdr_bench.sim.units import KM_PER_S_PER_KT

N_LEVELS = k.N_LEVELS

RUNNING, SUCCESS, NMAC, LOS, BOUNDARY, TIMEOUT = (
    k.RUNNING,
    k.SUCCESS,
    k.NMAC,
    k.LOS,
    k.BOUNDARY,
    k.TIMEOUT,
)
"""Outcome codes of a controlled aircraft (0 while it flies)."""
OUTCOME_NAMES = {
    SUCCESS: "success",
    NMAC: "nmac",
    LOS: "los",
    BOUNDARY: "boundary",
    TIMEOUT: "timeout",
}

REWARD_TERMS = ("goal", "path", "boundary", "step", "timeout", "los", "nmac")
"""Named reward terms, in the order of :attr:`StepResult.terms`. The goal part R_G sums the first
five, the safety part R_S the last two (docs/model.md §6)."""
GOAL_TERMS = REWARD_TERMS[:5]
SAFETY_TERMS = REWARD_TERMS[5:]


@dataclass(slots=True)
class StepResult:
    """What happened to every controlled aircraft during one step.

    Fresh arrays every step (a result stays valid after later steps).
    """

    terms: NDArray[np.float64]
    """(E, M, 7) named reward terms, in :data:`REWARD_TERMS` order"""
    flags: NDArray[np.bool_]
    """(E, M, 6): acting, invalid action, outside, reached goal, terminated, truncated"""
    outcome: NDArray[np.int8]
    """(E, M) outcome code of an aircraft that finished this step, else RUNNING"""
    min_sep_km: NDArray[np.float64]
    """(E, M) smallest swept horizontal distance to any same-level aircraft (inf if none)"""
    events: NDArray[np.bool_]
    """(2, E, M, N): LoS with / NMAC with aircraft n (background first, then controlled)"""
    reward: NDArray[np.float64]
    """(E, M) total reward R_G + R_S of the step (the terms summed in order; 0 if not flying)"""
    episode_done: NDArray[np.bool_]
    """(E,) the episode's last aircraft finished this step"""
    n_done: int
    """episodes done this step"""
    obs: NDArray[np.float32]
    """(E, M, F) observations after the step"""
    action_mask: NDArray[np.int8]
    """(E, M, 27) feasible actions after the step"""

    acting = property(lambda self: self.flags[..., k.F_ACTING], doc="(E, M) flew this step")
    invalid_action = property(
        lambda self: self.flags[..., k.F_INVALID],
        doc="(E, M) a masked level change was requested (and not executed)",
    )
    outside = property(
        lambda self: self.flags[..., k.F_OUTSIDE], doc="(E, M) outside the sector after the step"
    )
    reached_goal = property(lambda self: self.flags[..., k.F_REACHED], doc="(E, M)")
    terminated = property(lambda self: self.flags[..., k.F_TERMINATED], doc="(E, M)")
    truncated = property(lambda self: self.flags[..., k.F_TRUNCATED], doc="(E, M)")
    los_with = property(lambda self: self.events[0], doc="(E, M, N) LoS (an NMAC included)")
    nmac_with = property(lambda self: self.events[1], doc="(E, M, N) NMAC")

    @property
    def rewards(self) -> dict[str, NDArray[np.float64]]:
        """The named reward terms as (E, M) views."""
        return {name: self.terms[..., i] for i, name in enumerate(REWARD_TERMS)}

    @property
    def goal_reward(self) -> NDArray[np.float64]:
        """(E, M) goal part R_G of the step."""
        t = self.terms
        return t[..., 0] + t[..., 1] + t[..., 2] + t[..., 3] + t[..., 4]

    @property
    def safety_reward(self) -> NDArray[np.float64]:
        """(E, M) safety part R_S of the step."""
        return self.terms[..., 5] + self.terms[..., 6]


def _encounter_rows(
    encounters: list[Encounter | None],
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The kernels' encounter tables (``x_enc`` and ``x_enc_level``, or ``li_enc`` and
    ``li_enc_level``): one row per aircraft, zero for one not placed by an encounter."""
    enc_rows = np.zeros((len(encounters), k.N_ENC_PARAMS))
    level_rows = np.zeros((len(encounters), 4), dtype=np.int64)
    for i, enc in enumerate(encounters):
        if enc is None:
            continue
        enc_rows[i, k.X_HAS] = 1.0
        enc_rows[i, k.X_T_LO], enc_rows[i, k.X_T_HI] = range_bounds(enc.time_to_cpa_s)
        enc_rows[i, k.X_A_LO], enc_rows[i, k.X_A_HI] = range_bounds(enc.angle_deg)
        enc_rows[i, k.X_M_LO], enc_rows[i, k.X_M_HI] = range_bounds(enc.miss_km)
        enc_rows[i, k.X_S_LO], enc_rows[i, k.X_S_HI] = range_bounds(enc.speed_kt)
        enc_rows[i, k.X_MIRROR] = float(enc.mirror)
        levels = enc.level if isinstance(enc.level, tuple) else (enc.level,)
        level_rows[i, 0] = len(levels)
        level_rows[i, 1 : 1 + len(levels)] = levels
    return enc_rows, level_rows


def _placed_aircraft(cfg: ScenarioConfig) -> dict[str, NDArray[Any]]:
    """The kernels' tables of the scenario's placed aircraft (the ``x_*`` fields of
    :class:`~cdr_bench.sim.kernels.Constants`), one row each: position, heading vector, speed
    (km/s) and level of a fixed one; the ranges and levels of one placed by an encounter with
    the ownship."""
    X = len(cfg.aircraft)
    x_pos = np.zeros((X, 2))
    x_dir = np.zeros((X, 2))
    x_speed = np.zeros(X)
    x_level = np.zeros(X, dtype=np.int64)
    for i, a in enumerate(cfg.aircraft):
        if a.encounter is None:  # fixed (the schema requires every value)
            assert a.position_km is not None and a.heading_deg is not None
            assert a.speed_kt is not None and a.level is not None
            x_pos[i] = a.position_km
            x_dir[i] = exact_unit_vector(a.heading_deg)
            x_speed[i] = a.speed_kt * KM_PER_S_PER_KT
            x_level[i] = a.level
    x_enc, x_enc_level = _encounter_rows([a.encounter for a in cfg.aircraft])
    return {
        "x_pos": x_pos,
        "x_dir": x_dir,
        "x_speed": x_speed,
        "x_level": x_level,
        "x_enc": x_enc,
        "x_enc_level": x_enc_level,
    }


class Simulator:
    """A batch of ``n_episodes`` independent episodes of one scenario.

    Call :meth:`reset` with one seed per episode (or a subset of episodes), then :meth:`step`
    with one action index per controlled aircraft; :func:`cdr_bench.sim.observe` gives the
    observations. Read state from the public arrays (views into them are stable).
    """

    def __init__(self, config: ScenarioConfig, n_episodes: int = 1):
        if n_episodes < 1:
            raise ValueError(f"n_episodes must be >= 1, got {n_episodes}")
        self.config = cfg = config
        self.E = E = n_episodes
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
        self.route_length_km = np.sqrt(vec[:, 0] * vec[:, 0] + vec[:, 1] * vec[:, 1])
        self.route_unit = vec / np.maximum(self.route_length_km, 1e-9)[:, None]
        self.route_spacing_km = self.route_length_km / max(n, 1)
        self.traffic_speed_km_s = cfg.traffic.speed_kt * KM_PER_S_PER_KT
        self.X = len(cfg.aircraft)
        self.B = B = R * self.C + self.X

        # Controlled aircraft: ownship, learning intruders, controlled airway aircraft.
        self.M = M = cfg.n_controlled
        self.N = N = B + M
        o = cfg.ownship
        self.min_speed_kt, self.max_speed_kt = o.min_speed_kt, o.max_speed_kt
        self.heading_step_deg, self.speed_step_kt = o.heading_step_deg, o.speed_step_kt
        self.los_km, self.nmac_km = cfg.separation.los_km, cfg.separation.nmac_km

        # State (see the table in cdr_bench.sim.kernels). Background first, controlled last.
        self.pos_km = np.zeros((E, N, 2))
        self.vel_km_s = np.zeros((E, N, 2))
        self.level = np.zeros((E, N), dtype=np.int64)
        self.active = np.zeros((E, N), dtype=bool)
        self.ac_dir = np.zeros((E, M, 2))
        self.ac_speed_kt = np.zeros((E, M))
        self.ac_goal_km = np.zeros((E, M, 2))
        self.ac_outcome = np.zeros((E, M), dtype=np.int8)
        self.steps = np.zeros(E, dtype=np.int64)
        self.bg_arc_km = np.zeros((E, R * self.C))
        self.route_last_arc_km = np.zeros((E, R))
        self.route_spawn_count = np.zeros((E, R), dtype=np.int64)
        self.route_waiting = np.zeros((E, R), dtype=bool)

        # Constants of the scenario, as the kernels take them.
        turn_sin, turn_cos = exact_unit_vector(o.heading_step_deg)  # rotation by one step
        w = cfg.reward
        fp = np.zeros(k.N_FLOAT_PARAMS)
        for index, value in (
            (k.P_DT, self.dt_s),
            (k.P_LOS, self.los_km),
            (k.P_NMAC, self.nmac_km),
            (k.P_GOAL_RADIUS, o.goal_radius_km),
            (k.P_SIZE, self.size_km),
            (k.P_TRAFFIC_STEP, self.traffic_speed_km_s * self.dt_s),
            (k.P_SPAWN_CLEARANCE, cfg.traffic.spawn_clearance_km),
            (k.P_TRAFFIC_SPEED, self.traffic_speed_km_s),
            (k.P_MIN_SPEED, o.min_speed_kt),
            (k.P_MAX_SPEED, o.max_speed_kt),
            (k.P_SPEED_STEP, o.speed_step_kt),
            (k.P_TURN_COS, turn_cos),
            (k.P_TURN_SIN, turn_sin),
            (k.P_W_GOAL, w.goal),
            (k.P_W_PATH, w.path),
            (k.P_W_BOUNDARY, w.boundary),
            (k.P_W_STEP, w.step),
            (k.P_W_TIMEOUT, w.timeout),
            (k.P_W_LOS, w.los),
            (k.P_W_NMAC, w.nmac),
            (k.P_RANGE, cfg.observation.range_km),
            (k.P_LOOKAHEAD, cfg.observation.lookahead_s),
            (k.P_GOAL_MARGIN, o.goal_margin_km),
            (k.P_START_CLEARANCE, o.start_clearance_km),
            (k.P_START_SPEED, o.speed_kt),
            (k.P_LOS_TERMINATES, float(cfg.separation.los_terminates)),
            (
                k.P_BOUNDARY_MARGIN,
                np.inf if cfg.sector.boundary_margin_km is None else cfg.sector.boundary_margin_km,
            ),
            (k.P_MAX_STEPS, float(self.max_steps)),
            (k.P_SPAWN, float(cfg.traffic.spawn)),
            (k.P_CONTROLLED_SPAWNS, float(cfg.traffic.controlled_spawns)),
        ):
            fp[index] = value
        fp.flags.writeable = False
        self.params = fp
        """Float parameters of the kernels (read-only; indices ``P_*`` of the kernels module)."""

        li = cfg.learning_intruders
        L = len(li)
        li_start = np.zeros((L, 2))
        li_goal = np.zeros((L, 2))
        for i, x in enumerate(li):
            if x.airway is not None:
                li_start[i] = cfg.airways[x.airway].start_km
                li_goal[i] = cfg.airways[x.airway].end_km
        li_enc, li_enc_level = _encounter_rows([x.encounter for x in li])
        li_vec = li_goal - li_start
        li_len = np.sqrt(li_vec[:, 0] * li_vec[:, 0] + li_vec[:, 1] * li_vec[:, 1])
        own = np.zeros(9)
        if o.start is not None:
            assert o.goal_km is not None
            own[k.O_HAS] = 1.0
            own[k.O_X], own[k.O_Y] = o.start.position_km
            own[k.O_DIR_X], own[k.O_DIR_Y] = exact_unit_vector(o.start.heading_deg)
            own[k.O_SPEED] = o.start.speed_kt
            own[k.O_LEVEL] = o.start.level
            own[k.O_GOAL_X], own[k.O_GOAL_Y] = o.goal_km
        low, high = observation_bounds(cfg)
        self.obs_bounds = (low.astype(np.float64), high.astype(np.float64))
        """(low, high) of the observation Box, float64 (F,) each"""
        self.constants = k.Constants(
            fp=fp,
            low=self.obs_bounds[0],
            high=self.obs_bounds[1],
            route_start=self.route_start_km,
            route_unit=self.route_unit,
            route_len=self.route_length_km,
            route_len_slot=np.repeat(self.route_length_km, self.C),
            route_end=route_end,
            spacing=self.route_spacing_km,
            **_placed_aircraft(cfg),
            li_start=li_start,
            li_goal=li_goal,
            li_dir=li_vec / np.maximum(li_len, 1e-9)[:, None],
            li_enc=li_enc,
            li_enc_level=li_enc_level,
            own_fixed=own,
            per_route=self.per_route,
            C=self.C,
        )
        """The scenario's constants as the kernels read them."""
        self.state = k.State(
            self.pos_km,
            self.vel_km_s,
            self.level,
            self.active,
            self.ac_dir,
            self.ac_speed_kt,
            self.ac_goal_km,
            self.ac_outcome,
            self.steps,
            self.bg_arc_km,
            self.route_last_arc_km,
            self.route_spawn_count,
            self.route_waiting,
        )
        """The state arrays (the same objects as the attributes above) as the kernels take them."""
        self.all_episodes = np.arange(E)
        self.all_episodes.flags.writeable = False

    def __setstate__(self, state: dict) -> None:
        """A copy (``pickle``, ``copy.deepcopy``) keeps ``params`` and ``all_episodes``
        read-only: the kernels are compiled for read-only arrays, and writable ones made the
        copy's first step compile them again for that type (tens of seconds)."""
        self.__dict__.update(state)
        self.params.flags.writeable = False
        self.all_episodes.flags.writeable = False

    # Views of the state arrays (in-place writes go through to them).
    bg_pos_km = property(lambda self: self.pos_km[:, : self.B], doc="(E, B, 2) km")
    bg_vel_km_s = property(lambda self: self.vel_km_s[:, : self.B], doc="(E, B, 2) km/s")
    bg_level = property(lambda self: self.level[:, : self.B], doc="(E, B) level index")
    bg_active = property(lambda self: self.active[:, : self.B], doc="(E, B) in the sky")
    ac_pos_km = property(lambda self: self.pos_km[:, self.B :], doc="(E, M, 2) km")
    ac_vel_km_s = property(
        lambda self: self.vel_km_s[:, self.B :], doc="(E, M, 2) km/s (zero once it has left)"
    )
    ac_level = property(lambda self: self.level[:, self.B :], doc="(E, M) level index")
    ac_active = property(lambda self: self.active[:, self.B :], doc="(E, M) still flying")

    @property
    def ac_heading_deg(self) -> NDArray[np.float64]:
        """(E, M) headings in degrees clockwise from north, from :attr:`ac_dir` (display only)."""
        return heading_deg(self.ac_dir[..., 0], self.ac_dir[..., 1])

    # ------------------------------------------------------------------------------------------

    def reset(
        self, seeds: list[int] | NDArray[np.integer], episodes: NDArray[np.integer] | None = None
    ) -> None:
        """Start episodes ``episodes`` (default: all) from ``seeds`` (one per episode, integers
        in 0..2**64-1)."""
        if episodes is None:
            idx = self.all_episodes
        else:
            idx = np.asarray(episodes, dtype=np.int64).reshape(-1)
            if idx.size and (idx.min() < 0 or idx.max() >= self.E):
                raise ValueError(f"episode indices must be in 0..{self.E - 1}, got {idx.tolist()}")
        seed_arr = np.asarray([int(s) for s in np.asarray(seeds).reshape(-1)], dtype=np.uint64)
        if seed_arr.shape[0] != idx.shape[0]:
            raise ValueError(f"expected {idx.shape[0]} seeds, got {seed_arr.shape[0]}")
        failed = k.reset_episodes(idx, seed_arr, self.state, self.constants)
        if failed >= 0:
            raise ScenarioError(
                self.config.id,
                "ownship.start_clearance_km",
                f"no start with this clearance found in 200 draws (seed {int(seed_arr[failed])}): "
                "the sector is too crowded; lower it, or use fewer traffic.routes / per_route",
            )

    def step(self, actions: NDArray[np.integer]) -> StepResult:
        """Advance every episode by one step; the result carries the observations and masks
        after it.

        Args:
            actions: (E, M) action indices in 0..26; entries of aircraft that are not flying
                are ignored. Validation of the values is the caller's job.
        """
        E, M = self.E, self.M
        act = np.asarray(actions, dtype=np.int64).reshape(E, M)
        low = self.obs_bounds[0]
        terms = np.zeros((E, M, k.N_TERMS))
        flags = np.zeros((E, M, k.N_FLAGS), dtype=bool)
        outcome = np.zeros((E, M), dtype=np.int8)
        min_sep = np.empty((E, M))
        events = np.zeros((2, E, M, self.N), dtype=bool)
        reward = np.zeros((E, M))
        done = np.zeros(E, dtype=bool)
        obs = np.empty((E, M, low.shape[0]), dtype=np.float32)
        masks = np.empty((E, M, N_ACTIONS), dtype=np.int8)
        out = k.StepOutput(terms, flags, outcome, min_sep, events, reward, done, obs, masks)
        n_done = k.step_episodes(act, self.state, self.constants, out)
        return StepResult(terms, flags, outcome, min_sep, events, reward, done, n_done, obs, masks)

    def observe(
        self,
        episodes: NDArray[np.integer] | None = None,
        obs: NDArray[np.float32] | None = None,
        masks: NDArray[np.int8] | None = None,
    ) -> tuple[NDArray[np.float32], NDArray[np.int8]]:
        """Observations (E, M, F) float32 and action masks (E, M, 27) int8 of the current state.

        Args:
            episodes: only these episodes (default all); rows of the others in ``obs`` and
                ``masks`` are left as they are.
            obs, masks: arrays to write into (default new ones, zero).

        Aircraft that are not flying get the observation of their last state.
        """
        low, high = self.obs_bounds
        if obs is None:
            obs = np.zeros((self.E, self.M, low.shape[0]), dtype=np.float32)
        if masks is None:
            masks = np.zeros((self.E, self.M, N_ACTIONS), dtype=np.int8)
        episodes = self.all_episodes if episodes is None else np.asarray(episodes, dtype=np.int64)
        k.observe_episodes(episodes, obs, masks, self.state, self.constants)
        return obs, masks

    # ------------------------------------------------------------------------------------------
    # Derived quantities

    def action_masks(self) -> NDArray[np.int8]:
        """(E, M, 27) feasibility flags of every controlled aircraft."""
        return action_mask(self.level[:, self.B :], N_LEVELS)

    def intruder_count(self) -> NDArray[np.int64]:
        """Active background aircraft per episode, (E,)."""
        return self.bg_active.sum(axis=1)
