"""The batched environment: ``num_envs`` episodes of one scenario in lock-step, arrays in and out.

Everything steps through it: the PettingZoo :class:`~cdr_bench.env.CDREnv` and the Gymnasium
``Ownship-v0`` are its batch of one, the Gymnasium vector env (``gymnasium.make_vec(...,
vectorization_mode="vector_entry_point")``) a batch of N with auto-reset, and the evaluator,
the trainers, the tactical search and the first-action analysis use it directly.

============  ===================================================================================
what          shape and meaning
============  ===================================================================================
agents        ``M`` controlled aircraft: ``ownship_0`` (m = 0), ``intruder_*``, ``aircraft_*``
actions       ``(E, M)`` integers 0..26 (:mod:`cdr_bench.actions`); ignored for aircraft not flying
observations  ``(E, M, F)`` float32, the layout of :mod:`cdr_bench.sim.observation`
action masks  ``(E, M, 27)`` int8, 1 = feasible
rewards       ``(E, M)`` float64, the sum of the 7 named terms (``step.result.terms``)
auto-reset    optional: an episode whose last aircraft finished restarts within the same step;
              what it ended with is in ``final_obs``, ``final_action_mask`` and
              ``final_episode_seeds``, the slots in ``restarted``
============  ===================================================================================

Episode seeds: :meth:`VectorEnv.reset` takes one seed per episode (``seeds=``), or draws them from
a stream seeded by ``seed=``; auto-reset draws from the same stream. The seed of the episode in
slot ``e`` is ``episode_seeds[e]``. No mutable state is shared between instances.

Auto-reset is the one restart of every face that restarts episodes as they end: the Gymnasium
vector env, the trainers' :class:`~cdr_bench.rl.curriculum.CurriculumEnv` and the
Stable-Baselines3 adapter (:func:`cdr_bench.wrappers.vector_env_to_sb3`) all use it. Two
arguments adapt it: ``autoreset_when`` decides which episodes end with the step (the Gymnasium
vector env ends an episode with its ownship's flight; the training env cuts long episodes and
holds the restarts back on a promotion), ``autoreset_seeds`` supplies the seeds of the restarted
episodes (the training env draws them from its own stream).

State: besides what a step returns, the current state is public through read-only properties,
so that nothing outside the environments reads the simulator (a test enforces it). They are
*live views*: they follow the episodes as they step and restart (``.copy()`` one to keep its
values), and writing to them raises. ``flying`` alone is a fresh copy.

=====================  ======================================================================
property               shape and meaning
=====================  ======================================================================
flying                 ``(E, M)`` bool: the controlled aircraft in the sky now (a copy)
positions_km           ``(E, M, 2)`` float64: position (x east, y north) in km
goals_km               ``(E, M, 2)`` float64: goal position in km
heading_vectors        ``(E, M, 2)`` float64: unit vector of the heading (east, north)
speeds_kt              ``(E, M)`` float64: airspeed in kt
levels                 ``(E, M)`` int64: flight level index 0..2
outcomes               ``(E, M)`` int8: outcome code (:data:`cdr_bench.sim.OUTCOME_NAMES`) of a
                       finished flight, 0 while flying
episode_steps          ``(E,)`` int64: steps taken by the episode since it started
n_background           ``B``: background aircraft slots per episode
n_aircraft             ``N = B + M``: every aircraft slot, background first, then the controlled
                       aircraft (slot ``B + m``): the last axis of ``conflicts()`` and of the
                       step's ``los_with`` / ``nmac_with``
aircraft_positions_km  ``(E, N, 2)`` float64: position of every aircraft slot, in km
aircraft_levels        ``(E, N)`` int64: level of every aircraft slot
aircraft_in_sky        ``(E, N)`` bool: the slot holds an aircraft in the sky now
=====================  ======================================================================
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Generic, TypeVar, overload

import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray

from cdr_bench.actions import N_ACTIONS
from cdr_bench.errors import ActionError, ArgumentError, ResetNeeded, short_repr
from cdr_bench.scenarios import ScenarioConfig, load_scenario
from cdr_bench.sim import Simulator, StepResult, observation_bounds
from cdr_bench.sim.core import TIMEOUT
from cdr_bench.sim.kernels import conflicts_episodes

SEED_BOUND = 2**63
"""Episode seeds drawn from a stream are integers in 0..2**63-1."""


def _checked_seeds(seeds: Any, n: int, source: str = "reset(seeds=...)") -> NDArray[np.uint64]:
    """``reset(seeds=...)`` (or what ``source`` names): ``n`` integers in 0..2**64-1 (one per
    started episode)."""
    try:
        values = list(np.asarray(seeds, dtype=object).reshape(-1))
    except (ValueError, TypeError):
        values = [seeds]
    if len(values) != n:
        raise ArgumentError(f"{source} expects {n} seed(s), got {short_repr(seeds)}")
    for i, s in enumerate(values):
        if not _is_int(s, 0) or int(s) >= 2**64:
            raise ArgumentError(
                f"{source}[{i}] = {short_repr(s)}: expected an integer in 0..2**64-1"
            )
    return np.asarray([int(s) for s in values], dtype=np.uint64)


def _is_int(value: object, least: int) -> bool:
    """A Python or numpy integer (not a bool) >= ``least``."""
    return (
        isinstance(value, (int, np.integer))
        and not isinstance(value, (bool, np.bool_))
        and bool(value >= least)
    )


def _read_only(a: NDArray[Any]) -> NDArray[Any]:
    """A view of ``a`` that cannot be written (``a`` itself stays writable)."""
    view = a.view()
    view.flags.writeable = False
    return view


_D = TypeVar("_D", bound=np.generic)


class _SimView(Generic[_D]):
    """An attribute of :class:`VectorEnv`: the simulator's array ``name`` as a live read-only
    view (:func:`_read_only`); the docstring under the attribute documents it."""

    def __init__(self, name: str) -> None:
        self.name = name

    def __set_name__(self, owner: type, attr: str) -> None:
        self.attr = attr

    @overload
    def __get__(self, env: None, owner: type) -> _SimView[_D]: ...
    @overload
    def __get__(self, env: VectorEnv, owner: type) -> NDArray[_D]: ...
    def __get__(self, env: VectorEnv | None, owner: type) -> _SimView[_D] | NDArray[_D]:
        return self if env is None else _read_only(getattr(env.sim, self.name))

    def __set__(self, env: VectorEnv, value: object) -> None:
        raise AttributeError(f"VectorEnv.{self.attr} is read-only")


def agent_ids(config: ScenarioConfig) -> list[str]:
    """Agent names of the controlled aircraft, in simulator order (m = 0, 1, ...)."""
    return (
        ["ownship_0"]
        + [f"intruder_{i}" for i in range(config.n_learning_intruders)]
        + [
            f"aircraft_{i}"
            for i in range(config.traffic.controlled + config.traffic.controlled_spawns)
        ]
    )


def observation_space(config: ScenarioConfig) -> spaces.Dict:
    """The per-agent observation space: ``observation`` Box(F,) float32 and ``action_mask``
    Box(27,) int8."""
    low, high = observation_bounds(config)
    return spaces.Dict(
        {
            "observation": spaces.Box(low, high, dtype=np.float32),
            "action_mask": spaces.Box(0, 1, (N_ACTIONS,), dtype=np.int8),
        }
    )


def random_feasible_actions(masks: NDArray[np.int8], rng: np.random.Generator) -> NDArray[np.int64]:
    """One uniformly random feasible action per row of (..., 27) action masks (a batched
    ``action_space.sample(mask)``)."""
    # Masks differ only in the level part: three patterns (no descent, all, no climb), keyed by
    # whether action 0 (descend) and action 2 (climb) are feasible.
    key = masks[..., 0] + 2 * masks[..., 2]
    pick = rng.integers(0, _FEASIBLE_LCM, key.shape) % _FEASIBLE_COUNT[key]
    return _FEASIBLE_TABLE[key, pick]


def _feasible_table() -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    table = np.zeros((4, N_ACTIONS), dtype=np.int64)
    count = np.ones(4, dtype=np.int64)
    for key, (descend, climb) in enumerate(((0, 0), (1, 0), (0, 1), (1, 1))):
        feasible = [
            a for a in range(N_ACTIONS) if (a % 3 != 0 or descend) and (a % 3 != 2 or climb)
        ]
        table[key, : len(feasible)] = feasible
        count[key] = len(feasible)
    return table, count


_FEASIBLE_TABLE, _FEASIBLE_COUNT = _feasible_table()
_FEASIBLE_LCM = 27 * 18 * 9 * 2**40  # a multiple of every count: no modulo bias


@dataclass(slots=True)
class VectorStep:
    """What :meth:`VectorEnv.step` returns: the simulator's :class:`StepResult` of the step and,
    with auto-reset, what the episodes that restarted ended with. Every array is fresh."""

    result: StepResult
    """everything the simulator reports of the step (named reward terms, events, outcomes);
    its ``obs`` and ``action_mask`` are those of the new episode where one restarted"""
    final_obs: NDArray[np.float32]
    """(E, M, F) observations at the end of the step, before any auto-reset (``obs`` itself
    when nothing was reset)"""
    final_action_mask: NDArray[np.int8]
    """(E, M, 27) feasible actions at the end of the step, before any auto-reset
    (``action_mask`` itself when nothing was reset)"""
    final_episode_seeds: NDArray[np.uint64]
    """(E,) seed of the episode each slot held during the step"""
    restarted: NDArray[np.bool_]
    """(E,) the episode ended with this step and auto-reset restarted the slot (all False
    without auto-reset)"""

    obs = property(lambda self: self.result.obs, doc="(E, M, F) observations now")
    action_mask = property(lambda self: self.result.action_mask, doc="(E, M, 27) feasible now")
    reward = property(lambda self: self.result.reward, doc="(E, M) reward of the step")
    terminated = property(
        lambda self: self.result.terminated,
        doc="(E, M) the flight ended this step (success, LoS, NMAC, boundary)",
    )
    truncated = property(
        lambda self: self.result.truncated, doc="(E, M) the horizon ended the flight (timeout)"
    )
    episode_done = property(
        lambda self: self.result.episode_done, doc="(E,) the episode's last aircraft finished"
    )


class VectorEnv:
    """``num_envs`` episodes of one scenario in lock-step (see the module docstring).

    What a step returns is in :class:`VectorStep`; the current state (positions, goals,
    headings, speeds, levels, outcomes, step counters, every aircraft slot) in read-only
    properties, listed in the module docstring's *State* table. They are the public face of the
    state: code outside the environments does not read ``sim``.

    Args:
        scenario: a registry name, a YAML path or a :class:`ScenarioConfig`.
        num_envs: episodes stepped together (E).
        autoreset: restart an episode in the step it ends (by default, when its last aircraft
            finishes).
        seed: seeds the stream of episode seeds (``reset(seed=...)`` re-seeds it).
        autoreset_seeds: ``n -> n`` seeds (integers in 0..2**64-1) of the episodes auto-reset
            starts in a step, in slot order; default: the next ``n`` of the stream
            (:meth:`draw_seeds`).
        autoreset_when: ``result -> (E,) bool``, the episodes that end with the step (and
            restart), called in every step after the simulator and before any restart with the
            step's :class:`StepResult`; it may end episodes first (:meth:`end_episodes`).
            Default: the episodes whose last aircraft finished (``result.episode_done``).
        overrides: nested scenario fields, validated like YAML.

    The three auto-reset settings are public attributes (``autoreset``, ``autoreset_seeds``,
    ``autoreset_when``) that an adapter may set on an env it is given.
    """

    # class defaults too: a VectorEnv pickled before these settings existed unpickles without them
    autoreset_seeds: Callable[[int], Any] | None = None
    autoreset_when: Callable[[StepResult], NDArray[np.bool_]] | None = None

    def __init__(
        self,
        scenario: str | ScenarioConfig = "medium",
        num_envs: int = 1,
        *,
        autoreset: bool = False,
        seed: int | None = None,
        autoreset_seeds: Callable[[int], Any] | None = None,
        autoreset_when: Callable[[StepResult], NDArray[np.bool_]] | None = None,
        **overrides: Any,
    ):
        if not _is_int(num_envs, 1):
            raise ArgumentError(f"num_envs must be an integer >= 1, got {short_repr(num_envs)}")
        if not isinstance(autoreset, (bool, np.bool_)):
            raise ArgumentError(f"autoreset must be True or False, got {short_repr(autoreset)}")
        for name, hook in (
            ("autoreset_seeds", autoreset_seeds),
            ("autoreset_when", autoreset_when),
        ):
            if hook is not None and not callable(hook):
                raise ArgumentError(f"{name} must be None or a callable, got {short_repr(hook)}")
        if seed is not None and not _is_int(seed, 0):
            raise ArgumentError(f"seed must be None or an integer >= 0, got {short_repr(seed)}")
        num_envs = int(num_envs)
        self.config = load_scenario(scenario, **overrides)
        self.sim = Simulator(self.config, n_episodes=num_envs)
        self.num_envs = num_envs
        self.n_agents = self.sim.M
        self.agent_ids = agent_ids(self.config)
        self.autoreset = autoreset
        self.autoreset_seeds = autoreset_seeds
        self.autoreset_when = autoreset_when
        self.single_observation_space = observation_space(self.config)
        self.single_action_space = spaces.Discrete(N_ACTIONS)
        self.observation_size = 12 + 10 * self.config.observation.neighbours
        self.episode_seeds = np.zeros(num_envs, dtype=np.uint64)
        self._seed_stream = np.random.default_rng(seed)
        self._started = np.zeros(num_envs, dtype=bool)  # slots reset at least once
        self._ready = False  # every slot started: step() may run

    # -- episodes --------------------------------------------------------------------------------

    def draw_seeds(self, n: int) -> NDArray[np.uint64]:
        """The next ``n`` episode seeds of the stream."""
        return self._seed_stream.integers(0, SEED_BOUND, n, dtype=np.int64).astype(np.uint64)

    def reset(
        self,
        *,
        seed: int | None = None,
        seeds: NDArray[np.integer] | list[int] | None = None,
        episodes: NDArray[np.integer] | None = None,
    ) -> tuple[NDArray[np.float32], NDArray[np.int8]]:
        """Start episodes (default all) and return every episode's observations and masks.

        Args:
            seed: re-seed the stream of episode seeds, then draw from it.
            seeds: one seed per started episode (integers in 0..2**64-1), instead of the stream.
            episodes: which slots to restart (default all).
        """
        idx = self.sim.all_episodes if episodes is None else self._checked_slots(episodes)
        if seed is not None and not _is_int(seed, 0):
            raise ArgumentError(
                f"reset(seed=...) expects None or an integer >= 0, got {short_repr(seed)}"
            )
        chosen = None if seeds is None else _checked_seeds(seeds, idx.shape[0])
        if seed is not None:
            self._seed_stream = np.random.default_rng(seed)
        if chosen is None:
            chosen = self.draw_seeds(idx.shape[0])
        self.sim.reset(chosen, episodes=idx)
        self.episode_seeds[idx] = chosen
        if not self._ready:
            self._started[idx] = True
            self._ready = bool(self._started.all())
        return self.sim.observe()

    def _checked_slots(self, episodes: Any, call: str = "reset") -> NDArray[np.int64]:
        """``reset(episodes=...)`` (or ``call``'s): distinct slot indices in 0..num_envs-1."""
        try:
            raw = np.asarray(episodes).reshape(-1)
        except (ValueError, TypeError):
            raw = np.asarray([None], dtype=object)
        ok = raw.dtype.kind in "iu" and raw.size == np.unique(raw).size
        if not ok or (raw.size and (raw.min() < 0 or raw.max() >= self.num_envs)):
            raise ArgumentError(
                f"{call}(episodes=...) expects distinct slot indices in 0..{self.num_envs - 1}, "
                f"got {short_repr(episodes)}"
            )
        return raw.astype(np.int64)

    def end_episodes(self, episodes: NDArray[np.integer]) -> None:
        """End the given episodes now: every aircraft still flying gets the ``timeout`` outcome
        (a training-only horizon; the step returned nothing for it). ``episodes``: distinct
        slot indices in 0..num_envs-1 (a negative index is refused, not counted from the end)."""
        self._require_reset("end_episodes")
        idx = self._checked_slots(episodes, "end_episodes")
        flying = self.sim.ac_active[idx]
        self.sim.ac_outcome[idx] = np.where(flying, TIMEOUT, self.sim.ac_outcome[idx])
        self.sim.active[idx, self.sim.B :] = False
        self.sim.vel_km_s[idx, self.sim.B :] = 0.0

    # -- stepping --------------------------------------------------------------------------------

    def step(self, actions: NDArray[np.integer]) -> VectorStep:
        """Advance every episode by one step with (E, M) actions: integers in 0..26, one per
        controlled aircraft slot (a slot whose aircraft is not flying is ignored, but its value
        must still be an action; :data:`cdr_bench.actions.HOLD` is the usual filler). Anything
        else raises :class:`cdr_bench.errors.ActionError` naming the first bad entry."""
        return self._step(self._checked(actions))

    def _step(self, actions: NDArray[np.int64]) -> VectorStep:
        """:meth:`step` with actions already checked: the faces that validate their own actions
        (``CDREnv``, ``OwnshipVectorEnv``) call this, so a PettingZoo step is not checked twice."""
        if not self._ready:
            self._require_reset("step")
        sim = self.sim
        res = sim.step(actions)
        obs, masks = res.obs, res.action_mask
        if not self.autoreset:
            restart = np.zeros(self.num_envs, dtype=bool)
        elif self.autoreset_when is None:
            restart = res.episode_done
        else:
            restart = self._restart_mask(self.autoreset_when(res))
        if not restart.any():
            return VectorStep(res, obs, masks, self.episode_seeds, restart)
        # The one restart of every auto-resetting face (module docstring).
        final = VectorStep(res, obs.copy(), masks.copy(), self.episode_seeds.copy(), restart)
        ended = np.flatnonzero(restart)
        if self.autoreset_seeds is None:
            chosen = self.draw_seeds(ended.shape[0])
        else:
            chosen = _checked_seeds(
                self.autoreset_seeds(ended.shape[0]), ended.shape[0], "autoreset_seeds(n)"
            )
        sim.reset(chosen, episodes=ended)
        self.episode_seeds[ended] = chosen
        sim.observe(ended, obs=obs, masks=masks)
        return final

    def _restart_mask(self, mask: Any) -> NDArray[np.bool_]:
        """What ``autoreset_when`` returned, as an (E,) bool array (or an ArgumentError)."""
        out = np.asarray(mask)
        if out.dtype != np.bool_ or out.shape != (self.num_envs,):
            raise ArgumentError(
                f"autoreset_when must return a ({self.num_envs},) bool array, got "
                f"{short_repr(mask)}"
            )
        return out

    def _require_reset(self, call: str) -> None:
        """:class:`~cdr_bench.errors.ResetNeeded` unless every slot has been started."""
        if not self._ready:
            waiting = np.flatnonzero(~self._started)
            raise ResetNeeded(
                f"{call}() before reset(): call reset() first (slot(s) "
                f"{short_repr(waiting.tolist())} of {self.num_envs} never started)"
            )

    def _checked(self, actions: Any) -> NDArray[np.int64]:
        """``actions`` as the (E, M) int64 array the simulator steps, or an :class:`ActionError`
        (wrong shape, not integers, a value outside 0..26). A few microseconds per step."""
        try:
            a = np.asarray(actions)
        except (ValueError, TypeError):  # ragged nested lists
            raise ActionError(f"actions: not an array: {short_repr(actions)}") from None
        shape = (self.num_envs, self.sim.M)
        if a.shape != shape and a.shape != (shape[0] * shape[1],):
            raise ActionError(f"actions: expected an integer array of shape {shape}, got {a.shape}")
        if a.dtype.kind not in "iu":
            raise ActionError(
                f"actions: expected integers in 0..{N_ACTIONS - 1}, got an array of {a.dtype}"
            )
        a = a.reshape(shape)
        if a.size and (a.min() < 0 or a.max() >= N_ACTIONS):  # in its own dtype: no wrap-around
            e, m = np.argwhere((a < 0) | (a >= N_ACTIONS))[0]
            raise ActionError(
                f"actions[{e}, {m}] = {a[e, m]}: expected an integer in 0..{N_ACTIONS - 1}"
            )
        return a.astype(np.int64, copy=False)

    # -- state (see the module docstring: live read-only views, except ``flying``) ----------------

    @property
    def flying(self) -> NDArray[np.bool_]:
        """(E, M) aircraft in the sky now (a copy)."""
        return self.sim.ac_active.copy()

    positions_km = _SimView[np.float64]("ac_pos_km")
    """(E, M, 2) position (x east, y north) of every controlled aircraft, km."""
    goals_km = _SimView[np.float64]("ac_goal_km")
    """(E, M, 2) goal position of every controlled aircraft, km."""
    heading_vectors = _SimView[np.float64]("ac_dir")
    """(E, M, 2) unit vector (east, north) of the heading of every controlled aircraft."""
    speeds_kt = _SimView[np.float64]("ac_speed_kt")
    """(E, M) airspeed of every controlled aircraft, kt."""
    levels = _SimView[np.int64]("ac_level")
    """(E, M) flight level index (0..2) of every controlled aircraft."""
    outcomes = _SimView[np.int8]("ac_outcome")
    """(E, M) outcome code of every controlled aircraft (:data:`cdr_bench.sim.OUTCOME_NAMES`):
    that of its finished flight, 0 while it flies."""
    episode_steps = _SimView[np.int64]("steps")
    """(E,) steps taken by each episode since it started (it stops counting when the
    episode's last aircraft finishes)."""

    @property
    def n_background(self) -> int:
        """B: background aircraft slots per episode (slots ``0..B-1`` of the aircraft axis)."""
        return int(self.sim.B)

    @property
    def n_aircraft(self) -> int:
        """N = B + M: aircraft slots per episode, background first, then controlled aircraft
        ``m`` in slot ``B + m`` (the last axis of :meth:`conflicts` and of ``los_with``)."""
        return int(self.sim.N)

    aircraft_positions_km = _SimView[np.float64]("pos_km")
    """(E, N, 2) position of every aircraft slot, km (a slot not in the sky keeps a stale
    value: see :attr:`aircraft_in_sky`)."""
    aircraft_levels = _SimView[np.int64]("level")
    """(E, N) flight level index of every aircraft slot."""
    aircraft_in_sky = _SimView[np.bool_]("active")
    """(E, N) the slot holds an aircraft in the sky now."""

    def observe(self) -> tuple[NDArray[np.float32], NDArray[np.int8]]:
        """(E, M, F) observations and (E, M, 27) masks of the current state."""
        return self.sim.observe()

    def conflicts(self, out: NDArray[np.bool_] | None = None) -> NDArray[np.bool_]:
        """(E, M, N) predicted conflicts of the current state (docs/model.md §10.1): aircraft
        ``n`` at the same level as controlled aircraft ``m`` (both in the sky) with a closest
        approach below the LoS threshold within the look-ahead. Written into ``out`` if given."""
        sim = self.sim
        if out is None:
            out = np.zeros((sim.E, sim.M, sim.N), dtype=bool)
        conflicts_episodes(out, sim.state, sim.constants)
        return out
