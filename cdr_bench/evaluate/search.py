"""Search over ownship action sequences: which first actions, which manoeuvre families can
still lead to success?

Used to certify the tactical scenarios (docs/model.md §8.3: holding fails, several manoeuvre
families succeed in every episode, the MVP resolver solves some but not all; :func:`certify`,
``cdr-bench scenarios certify``) and to name the manoeuvre families of first actions in the
multimodality analysis (docs/model.md §10.4).

The search is a fixed family of *follow-on* policies played after a given first action, all
rolled out in parallel in one :class:`~cdr_bench.vector_env.VectorEnv` (one episode per
candidate sequence, each reset with the seed of the episode it searches). A follow-on policy is

1. **turn**: ``turn_steps`` steps of a constant heading change ``turn`` (-1 left, +1 right),
2. **hold**: ``hold_steps`` steps keeping the heading reached,
3. **steer**: until the end, turn toward the goal (one heading step whenever the goal bearing is
   more than half a heading step off the nose),

while climbing or descending one level per step toward ``level`` during phases 1 and 2 and
toward ``final_level`` during phase 3, and changing speed one speed step per step toward
``speed_kt`` throughout. A first action is *successful* when at least one follow-on makes the
ownship reach its goal (outcome ``SUCCESS``); the realised action sequence is the witness.
Failing to find one is evidence, not proof, that no continuation exists.

:func:`successful_first_actions` searches every first action of one episode;
:func:`search_families` searches the manoeuvre families (:func:`manoeuvre_family`, each with the
follow-ons that continue it, :func:`family_follow_ons`) of many episodes at once.

Only the ownship (controlled aircraft 0) is searched; learning intruders, if any, hold.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from cdr_bench.actions import HOLD, N_ACTIONS, decode, encode
from cdr_bench.errors import UserError
from cdr_bench.evaluate.rollout import Decisions, fly
from cdr_bench.evaluate.seeds import episode_seeds
from cdr_bench.scenarios.schema import ScenarioConfig
from cdr_bench.sim.core import OUTCOME_NAMES, SUCCESS
from cdr_bench.sim.geometry import exact_unit_vector
from cdr_bench.vector_env import VectorEnv

TURN_STEPS = (1, 2, 3, 4, 6, 8)
"""Lengths of the turn phase, steps (a turn of k steps changes the heading by 5 k deg)."""
HOLD_STEPS = (0, 2, 4, 8)
"""Lengths of the hold phase, steps."""
SPEEDS_KT = (330.0, 380.0, 430.0, 480.0, 530.0)
"""Target speeds, kt."""
LEVELS = (0, 1, 2)
"""Target levels of the manoeuvre and of the return phase."""


def follow_on_family(
    turn_steps: tuple[int, ...] = TURN_STEPS,
    hold_steps: tuple[int, ...] = HOLD_STEPS,
    speeds_kt: tuple[float, ...] = SPEEDS_KT,
    levels: tuple[int, ...] = LEVELS,
) -> dict[str, NDArray[np.float64]]:
    """The grid of follow-on policies, simplest first.

    Returns:
        Arrays of shape (F,) keyed ``turn`` (-1, 0, +1), ``turn_steps`` (steps), ``hold_steps``
        (steps), ``speed_kt`` (kt), ``level`` and ``final_level`` (level indices). ``turn = 0``
        (with ``turn_steps = 0``) keeps the heading left by the first action. With the defaults
        F = 13 * 4 * 5 * 3 * 3 = 2340.
    """
    lateral = [(0, 0)] + [(d, k) for d in (-1, 1) for k in turn_steps]
    rows = [
        (d, k, h, s, lv, fl)
        for (d, k), h, s, lv, fl in itertools.product(
            lateral, hold_steps, speeds_kt, levels, levels
        )
    ]
    grid = np.array(rows, dtype=float)
    # Simplest first: short manoeuvres, cruise speed, level 1, no second level change.
    effort = grid[:, 1] + grid[:, 2]
    order = np.lexsort(
        (np.abs(grid[:, 5] - grid[:, 4]), np.abs(grid[:, 4] - 1), np.abs(grid[:, 3] - 430), effort)
    )
    grid = grid[order]
    names = ("turn", "turn_steps", "hold_steps", "speed_kt", "level", "final_level")
    return {n: grid[:, i] for i, n in enumerate(names)}


def _follow_on_actions(
    env: VectorEnv, family: dict[str, NDArray[np.float64]], j: int
) -> NDArray[np.int64]:
    """Ownship action of every episode ``j`` steps after the first action, shape (E,)."""
    return manoeuvre_actions(env, {k: v[:, None] for k, v in family.items()}, j)[:, 0]


def manoeuvre_actions(
    env: VectorEnv, family: dict[str, NDArray[np.float64]], j: int
) -> NDArray[np.int64]:
    """The follow-on policy's action of every controlled aircraft ``j`` steps into it, shape
    (E, M); ``family`` holds each parameter of :func:`follow_on_family` per aircraft, arrays
    broadcastable to (E, M)."""
    turning = j < family["turn_steps"]
    steering = j >= family["turn_steps"] + family["hold_steps"]
    own = env.config.ownship
    # Steer when the goal is more than half a heading step off the nose: with the goal vector g
    # and the heading vector u, cross = |g| sin(off) and dot = |g| cos(off), and off > half
    # exactly when sin(off - half) > 0 with sin(off) > 0 (no angle is computed).
    g = env.goals_km - env.positions_km
    u = env.heading_vectors
    cross = g[..., 0] * u[..., 1] - g[..., 1] * u[..., 0]  # + : goal to the right
    dot = g[..., 0] * u[..., 0] + g[..., 1] * u[..., 1]
    s_half, c_half = exact_unit_vector(0.5 * own.heading_step_deg)
    right = (cross > 0.0) & (cross * c_half - dot * s_half > 0.0)
    left = (cross < 0.0) & (-cross * c_half - dot * s_half > 0.0)
    steer = np.where(right, 1, np.where(left, -1, 0))
    a_psi = np.where(turning, family["turn"], np.where(steering, steer, 0))
    dv = family["speed_kt"] - env.speeds_kt
    a_v = np.where(np.abs(dv) > 0.5 * own.speed_step_kt, np.sign(dv), 0)
    target_level = np.where(steering, family["final_level"], family["level"])
    a_h = np.sign(target_level - env.levels)
    return (9 * (a_psi + 1) + 3 * (a_v + 1) + (a_h + 1)).astype(np.int64)


def search_batch(
    config: ScenarioConfig,
    first_actions: NDArray[np.integer],
    family: dict[str, NDArray[np.float64]],
    seed: int = 0,
    seeds: NDArray[np.integer] | None = None,
) -> tuple[NDArray[np.int64], NDArray[np.int8], NDArray[np.int64]]:
    """Roll out every (first action, follow-on) pair of one batch in parallel.

    Args:
        config: the scenario.
        first_actions: (E,) first action of each episode.
        family: (E,) follow-on parameters per episode, keys as in :func:`follow_on_family`.
        seed: episode seed shared by every episode (when ``seeds`` is None).
        seeds: (E,) episode seed of each episode.

    Returns:
        ``(actions, outcome, n_steps)``: (E, T) ownship actions played (T <= the scenario
        horizon), (E,) outcome code of the ownship, (E,) steps until it finished.
    """
    E = len(first_actions)
    env = VectorEnv(config, num_envs=E)
    obs, masks = env.reset(seeds=np.full(E, seed) if seeds is None else np.asarray(seeds))
    horizon = config.time.max_steps
    played = np.full((E, horizon), HOLD, dtype=np.int64)

    def decide(d: Decisions) -> NDArray[np.int64]:
        # The follow-on of every episode is played (recorded) as computed; the simulator
        # ignores those of the ownships that have finished.
        t = d.t
        a = np.asarray(first_actions) if t == 0 else _follow_on_actions(env, family, t - 1)
        played[:, t] = a
        return a[d.episodes]

    flown = fly(env, obs, masks, decide, drive="ownship", max_steps=horizon)
    if flown < horizon:
        played = played[:, :flown]
    return played, env.outcomes[:, 0].copy(), env.episode_steps.copy()


def successful_first_actions(
    config: ScenarioConfig,
    seed: int = 0,
    first_actions: list[int] | None = None,
    family: dict[str, NDArray[np.float64]] | None = None,
    max_batch: int = 1 << 15,
    first_pass: int = 256,
) -> dict[int, list[int] | None]:
    """For each first action, a successful action sequence starting with it, or None.

    The simplest ``first_pass`` follow-ons are tried for every first action; the rest of the
    family only for the first actions still without a witness.

    Args:
        config: the scenario (deterministic scenarios give seed-independent answers).
        seed: episode seed of every rollout.
        first_actions: first actions to try (default: all 27); actions masked at the start
            (a climb at level 2, a descent at level 0) are skipped.
        family: follow-on policies (default :func:`follow_on_family`), arrays shaped (F,).
        max_batch: most episodes simulated at once (bounds memory, about 1 kB per episode).
        first_pass: follow-ons of the first pass.

    Returns:
        ``{first action: witness}`` over the feasible first actions, in increasing order. A
        witness is the list of ownship actions, first action included, after which the ownship
        has reached its goal: the first success in family order (simplest manoeuvre first).
    """
    fam = follow_on_family() if family is None else family
    n_family = len(fam["turn"])
    candidates = list(range(N_ACTIONS)) if first_actions is None else list(first_actions)
    _, masks = VectorEnv(config).reset(seeds=[seed])
    mask = masks[0, 0]
    result: dict[int, list[int] | None] = {a: None for a in sorted(set(candidates)) if mask[a]}
    for lo, hi in ((0, min(first_pass, n_family)), (min(first_pass, n_family), n_family)):
        rows = {k: v[lo:hi] for k, v in fam.items()}
        n_rows = hi - lo
        open_ = [a for a, w in result.items() if w is None]
        per_batch = max(1, max_batch // max(n_rows, 1))
        for i in range(0, len(open_) if n_rows else 0, per_batch):
            group = np.array(open_[i : i + per_batch])
            tiled = {k: np.tile(v, len(group)) for k, v in rows.items()}
            played, outcome, n_steps = search_batch(
                config, np.repeat(group, n_rows), tiled, seed=seed
            )
            ok = (outcome == SUCCESS).reshape(len(group), n_rows)
            for g in np.flatnonzero(ok.any(axis=1)):
                e = g * n_rows + int(np.argmax(ok[g]))
                result[int(group[g])] = [int(x) for x in played[e, : n_steps[e]]]
    return result


# ----------------------------------------------------------------------------------------------
# Manoeuvre families (docs/model.md §8.3)

FAMILIES = ("left", "right", "climb", "descend", "speed")
"""The manoeuvre families, in report order."""


def manoeuvre_family(action: int) -> str | None:
    """The family of a first action: a level change is ``climb`` / ``descend`` (whatever it does
    to heading and speed), else a heading change is ``left`` / ``right``, else a speed change is
    ``speed``; hold (13) is none."""
    psi, v, h = decode(action)
    if h:
        return "climb" if h > 0 else "descend"
    if psi:
        return "right" if psi > 0 else "left"
    return "speed" if v else None


FAMILY_ACTIONS: dict[str, tuple[int, ...]] = {
    f: tuple(
        sorted(
            (a for a in range(N_ACTIONS) if manoeuvre_family(a) == f),
            key=lambda a: (sum(x != 0 for x in decode(a)), a),
        )
    )
    for f in FAMILIES
}
"""The first actions of each family, the purest first (e.g. ``climb``: climb alone, then climb
with a turn or a speed change, then both)."""


def family_follow_ons(
    family_name: str,
    first_action: int,
    level: int,
    speed_kt: float,
    grid: dict[str, NDArray[np.float64]],
) -> NDArray[np.int64]:
    """Indices into ``grid`` (a :func:`follow_on_family`) of the follow-ons that continue the
    manoeuvre of ``first_action`` from ``level`` and ``speed_kt`` (the ownship's at the start),
    so that a success is one of its family and not a later manoeuvre of another:

    * ``left`` / ``right``: the turn phase turns the same way (or not at all); the level stays.
    * ``climb`` / ``descend``: no turn phase; the manoeuvre phases stay above / below the start
      level (the return phase may come back).
    * ``speed``: no turn phase, the level stays, the target speed lies beyond the start speed in
      the direction of the first action.

    Speeds are free except for ``speed``. So a success of ``climb`` is not a turn flown one
    level up, nor one of ``left`` a climb after a turn.
    """
    psi, v, _ = decode(first_action)
    turn, lv, final = grid["turn"], grid["level"], grid["final_level"]
    same_level = (lv == level) & (final == level)
    if family_name in ("left", "right"):
        keep = same_level & ((turn == 0) | (turn == psi))
    elif family_name == "climb":
        keep = (turn == 0) & (lv > level)
    elif family_name == "descend":
        keep = (turn == 0) & (lv < level)
    elif family_name == "speed":
        keep = same_level & (turn == 0) & ((grid["speed_kt"] - speed_kt) * v > 0)
    else:
        raise ValueError(f"unknown manoeuvre family {family_name!r}; known: {FAMILIES}")
    return np.flatnonzero(keep)


@dataclass
class FamilySearch:
    """What :func:`search_families` found in one episode."""

    seed: int
    """the episode seed"""
    witnesses: dict[str, list[int]]
    """family -> a successful ownship action sequence of that family (first success found)"""
    searched: tuple[str, ...]
    """the families searched to the end of the follow-ons (others were skipped by ``enough``)"""

    @property
    def families(self) -> list[str]:
        """The families with a witness, in :data:`FAMILIES` order."""
        return [f for f in FAMILIES if f in self.witnesses]


CHUNKS = (1, 8, 64, 512)
"""Follow-ons per (episode, family, first action) in successive passes of
:func:`search_families` (then the rest): a family is dropped from later passes once found."""


def search_families(
    config: ScenarioConfig,
    seeds: list[int] | NDArray[np.integer],
    grid: dict[str, NDArray[np.float64]] | None = None,
    enough: int | None = None,
    max_batch: int = 1 << 15,
) -> list[FamilySearch]:
    """For each episode seed, the manoeuvre families with a successful continuation.

    Every (episode, family, feasible first action of the family, follow-on of the family,
    :func:`family_follow_ons`) is a candidate; all candidates of a pass run in parallel (every
    episode in the same :class:`VectorEnv` batches). Passes take the follow-ons in grid order
    (simplest first) in chunks (:data:`CHUNKS`) and stop a family at its first success.

    Args:
        config: the scenario.
        seeds: episode seeds (e.g. the evaluation's, from
            :func:`~cdr_bench.evaluate.seeds.episode_seeds`).
        grid: follow-on policies (default :func:`follow_on_family`).
        enough: stop searching an episode once this many families are found (its other
            families are then not in ``searched``); None searches every family to the end.
        max_batch: most rollouts simulated at once (about 1 kB each).

    Returns:
        One :class:`FamilySearch` per seed, in order.
    """
    fam = follow_on_family() if grid is None else grid
    seeds_arr = np.asarray([int(x) for x in seeds], dtype=np.uint64)
    n = len(seeds_arr)
    env = VectorEnv(config, num_envs=max(n, 1))
    masks = env.reset(seeds=seeds_arr)[1][:, 0] if n else np.zeros((0, N_ACTIONS), np.int8)
    level = env.levels[:n, 0].copy()
    speed = env.speeds_kt[:n, 0].copy()
    # The candidates of every (episode, family): (first action, follow-on index) in order.
    todo: dict[tuple[int, str], list[tuple[int, int]]] = {}
    for e in range(n):
        for f in FAMILIES:
            cands = []
            for a in FAMILY_ACTIONS[f]:
                if masks[e, a]:
                    js = family_follow_ons(f, a, int(level[e]), float(speed[e]), fam)
                    cands += [(a, int(j)) for j in js]
            if cands:
                todo[(e, f)] = cands
    found: list[dict[str, list[int]]] = [{} for _ in range(n)]
    bounds = [0, *itertools.accumulate(CHUNKS)]
    pass_ranges = list(itertools.pairwise(bounds)) + [(bounds[-1], None)]
    exhausted: set[tuple[int, str]] = set()
    for lo, hi in pass_ranges:
        open_ = [
            key
            for key in todo
            if key[1] not in found[key[0]] and (enough is None or len(found[key[0]]) < enough)
        ]
        if hi is None:
            exhausted = set(open_)
        rows = []  # (key, first action, follow-on) in candidate order
        for key in open_:
            per_action: dict[int, list[int]] = {}
            for a, j in todo[key]:
                per_action.setdefault(a, []).append(j)
            for a, follow in per_action.items():
                rows += [(key, a, j) for j in follow[lo:hi]]
        for i in range(0, len(rows), max_batch):
            part = rows[i : i + max_batch]
            ep = np.array([r[0][0] for r in part])
            sub = {k: v[np.array([r[2] for r in part])] for k, v in fam.items()}
            played, outcome, n_steps = search_batch(
                config, np.array([r[1] for r in part]), sub, seeds=seeds_arr[ep]
            )
            for r, (key, _, _) in enumerate(part):
                e, f = key
                if outcome[r] == SUCCESS and f not in found[e]:
                    found[e][f] = [int(x) for x in played[r, : n_steps[r]]]
    return [
        FamilySearch(
            int(seeds_arr[e]),
            found[e],
            tuple(
                f for f in FAMILIES if f in found[e] or (e, f) in exhausted or (e, f) not in todo
            ),
        )
        for e in range(n)
    ]


# ----------------------------------------------------------------------------------------------
# Multi-aircraft encounters (docs/model.md §8.4.1): the controlled aircraft searched together

JOINT_PATTERNS = (
    "all right",
    "all left",
    "ownship right",
    "ownship left",
    "others right",
    "others left",
    "ownship slower",
    "ownship faster",
    "others slower",
    "others faster",
)
"""Joint manoeuvre patterns: which controlled aircraft manoeuvre (every one, the ownship alone,
or every one but the ownship) and how (turn right or left, fly slower or faster); the others
fly straight on toward their goals at their start speed."""
JOINT_TURNS = tuple(itertools.product(TURN_STEPS, HOLD_STEPS))
"""(turn steps, hold steps) of the follow-ons of a turning pattern (24)."""
JOINT_SPEEDS = {"slower": (330.0, 380.0), "faster": (480.0, 530.0)}
"""Target speeds (kt) of the follow-ons of a speed pattern (:data:`SPEEDS_KT` below and above
the start speed of 430 kt)."""


def joint_grid(pattern: str, M: int) -> dict[str, NDArray[np.float64]]:
    """The follow-ons of a joint pattern for ``M`` controlled aircraft, arrays (G, M), one row
    per follow-on. A turning pattern: one row per (turn steps, hold steps) of
    :data:`JOINT_TURNS`, the same for every manoeuvring aircraft (turn that way, hold the
    heading reached, steer back to the goal). A speed pattern: one row per target speed of
    :data:`JOINT_SPEEDS` (the manoeuvring aircraft change speed one step per step toward it and
    steer to their goals). The others steer to their goals from the start. ``speed_kt`` is NaN
    where an aircraft keeps its start speed, and every aircraft keeps its start level (both
    filled in by :func:`search_joint`)."""
    if pattern not in JOINT_PATTERNS:
        raise UserError(f"unknown joint pattern {pattern!r}; known: {', '.join(JOINT_PATTERNS)}")
    who, how = pattern.split()
    m = np.arange(M)
    moving = m >= 0 if who == "all" else m == 0 if who == "ownship" else m > 0
    if how in JOINT_SPEEDS:
        speeds = np.array(JOINT_SPEEDS[how])[:, None]
        zero = np.zeros((len(speeds), M))
        return {
            "turn": zero,
            "turn_steps": zero,
            "hold_steps": zero,
            "speed_kt": np.where(moving[None, :], speeds, np.nan),
        }
    grid = np.array(JOINT_TURNS, dtype=float)
    on = np.broadcast_to(moving.astype(float), (len(grid), M))
    return {
        "turn": on * (-1.0 if how == "left" else 1.0),
        "turn_steps": on * grid[:, :1],
        "hold_steps": on * grid[:, 1:],
        "speed_kt": np.full((len(grid), M), np.nan),
    }


def joint_witness(pattern: str, row: int) -> dict[str, float]:
    """The parameters of follow-on ``row`` of a pattern (:func:`joint_grid`)."""
    how = pattern.split()[1]
    if how in JOINT_SPEEDS:
        return {"speed_kt": JOINT_SPEEDS[how][row]}
    k, h = JOINT_TURNS[row]
    return {"turn_steps": float(k), "hold_steps": float(h)}


def joint_follow_ons(
    env: VectorEnv, grid: dict[str, NDArray[np.float64]]
) -> dict[str, NDArray[np.float64]]:
    """``grid`` rows (E, M) of :func:`joint_grid` completed for ``env`` just reset: the start
    speed where none is given, the start level throughout (for :func:`manoeuvre_actions`)."""
    fam = {k: v for k, v in grid.items() if k != "speed_kt"}
    fam["speed_kt"] = np.where(np.isnan(grid["speed_kt"]), env.speeds_kt, grid["speed_kt"])
    fam["level"] = fam["final_level"] = env.levels.astype(float)
    return fam


@dataclass
class JointSearch:
    """What :func:`search_joint` found in one episode."""

    seed: int
    """the episode seed"""
    witnesses: dict[str, dict[str, float]]
    """pattern -> the parameters of its first follow-on after which every controlled aircraft
    reaches its goal (:func:`joint_witness`)"""
    searched: tuple[str, ...]
    """the patterns searched (all of them)"""

    @property
    def families(self) -> list[str]:
        """The patterns with a witness, in :data:`JOINT_PATTERNS` order."""
        return [p for p in JOINT_PATTERNS if p in self.witnesses]


def search_joint(
    config: ScenarioConfig,
    seeds: list[int],
    patterns: tuple[str, ...] = JOINT_PATTERNS,
    max_batch: int = 4096,
) -> list[JointSearch]:
    """For each episode seed, the joint patterns (:func:`joint_grid`) with a follow-on after
    which every controlled aircraft reaches its goal (outcome ``SUCCESS``; with
    ``separation.los_terminates`` a loss of separation ends a flight, so a success is clean).
    Every (episode, pattern, follow-on) is one episode of a :class:`VectorEnv`, rolled out
    ``max_batch`` at a time."""
    M = config.n_controlled
    grids = {p: joint_grid(p, M) for p in patterns}
    rows = [
        (i, p, g) for i in range(len(seeds)) for p in patterns for g in range(len(grids[p]["turn"]))
    ]
    ok = np.zeros(len(rows), dtype=bool)
    horizon = config.time.max_steps
    for lo in range(0, len(rows), max_batch):
        part = rows[lo : lo + max_batch]
        env = VectorEnv(config, num_envs=len(part))
        obs, masks = env.reset(seeds=np.asarray([seeds[i] for i, _, _ in part], dtype=np.uint64))
        grid = {k: np.stack([grids[p][k][g] for _, p, g in part]) for k in grids[patterns[0]]}
        fam = joint_follow_ons(env, grid)

        def decide(d: Decisions, env: VectorEnv = env, fam: dict = fam) -> NDArray[np.int64]:
            return manoeuvre_actions(env, fam, d.t)[d.episodes, d.aircraft]

        fly(env, obs, masks, decide, drive="all", max_steps=horizon)
        ok[lo : lo + len(part)] = (env.outcomes == SUCCESS).all(axis=1)
    found = [JointSearch(int(s), {}, tuple(patterns)) for s in seeds]
    for (i, p, g), good in zip(rows, ok, strict=True):
        if good and p not in found[i].witnesses:
            found[i].witnesses[p] = joint_witness(p, g)
    return found


def _episode_outcome(outcomes: NDArray[np.int8], joint: bool) -> NDArray[np.int8]:
    """(episodes,) outcome codes from (episodes, M): the ownship's, or with ``joint`` the
    episode's (``SUCCESS`` when every controlled aircraft succeeded, else the first other
    outcome in aircraft order)."""
    if not joint:
        return outcomes[:, 0]
    bad = outcomes != SUCCESS
    first = np.argmax(bad, axis=1)
    return np.where(bad.any(axis=1), outcomes[np.arange(len(outcomes)), first], SUCCESS).astype(
        np.int8
    )


# ----------------------------------------------------------------------------------------------
# Certification of a tactical family (docs/model.md §8.3)

HOLD_FAILS_AT_LEAST = 0.95
"""Holding must fail in at least this share of the episodes."""
MIN_FAMILIES = 2
"""Every searched episode needs at least this many manoeuvre families with a success."""
AGENT_SOLVES = (0.30, 0.90)
"""The reference resolver's success rate must lie in this range: hard, not impossible."""
DEFAULT_AGENT = "agents/mvp"
"""The reference resolver of the certification (a path in the repository)."""

SIMPLE_MANOEUVRES: dict[str, tuple[int, dict[str, float]]] = {
    "left": (encode((-1, 0, 0)), {"turn": -1, "turn_steps": 3, "hold_steps": 2}),
    "right": (encode((1, 0, 0)), {"turn": 1, "turn_steps": 3, "hold_steps": 2}),
    "climb": (encode((0, 0, 1)), {"level": +1, "final_level": +1}),
    "descend": (encode((0, 0, -1)), {"level": -1, "final_level": -1}),
    "speed": (encode((0, -1, 0)), {"speed_kt": -100.0}),
}
"""The plainest manoeuvre of each family (first action, follow-on relative to the start): a
20 deg turn held for 2 steps, then back to the goal; a climb or descent of one level, kept to
the end; slowing down by 100 kt. How often they fail shows how often a constraint bites."""


def _simple_follow_on(family_name: str, level: int, speed_kt: float) -> dict[str, float]:
    rel = SIMPLE_MANOEUVRES[family_name][1]
    row = {
        "turn": rel.get("turn", 0),
        "turn_steps": rel.get("turn_steps", 0),
        "hold_steps": rel.get("hold_steps", 0),
        "speed_kt": speed_kt + rel.get("speed_kt", 0.0),
        "level": level + rel.get("level", 0),
        "final_level": level + rel.get("final_level", 0),
    }
    return {k: float(v) for k, v in row.items()}


def hold_outcomes(config: ScenarioConfig, seeds: list[int]) -> NDArray[np.int8]:
    """Outcome codes of every controlled aircraft holding course, speed and level (action 13)
    every step, (episodes, M): one row per episode seed."""
    env = VectorEnv(config, num_envs=len(seeds))
    obs, masks = env.reset(seeds=np.asarray(seeds, dtype=np.uint64))
    fly(env, obs, masks, lambda d: HOLD, drive="all")
    return env.outcomes.copy()


def agent_outcomes(
    config: ScenarioConfig,
    agent_path: str,
    base_seed: int,
    n_episodes: int,
    batch_size: int,
    drive: Literal["all", "ownship"] = "ownship",
) -> NDArray[np.int8]:
    """Outcome codes of every controlled aircraft, (episodes, M), the ownship flown by the agent
    at ``agent_path`` on the first ``n_episodes`` episodes of the evaluation (same seeds, same
    batches, same ``reset`` seeds as ``cdr-bench evaluate``) and, with ``drive="all"``, every
    other controlled aircraft too (else they hold). The agent runs IN THIS PROCESS: only for
    trusted agents such as the shipped ``agents/mvp``."""
    from gymnasium import spaces

    from cdr_bench.evaluate.loader import load_agent
    from cdr_bench.evaluate.runner import batch_seed
    from cdr_bench.vector_env import observation_space

    agent = load_agent(agent_path, observation_space(config), spaces.Discrete(N_ACTIONS))
    chash = config.config_hash()
    out = []
    for b, start in enumerate(range(0, n_episodes, batch_size)):
        seeds = episode_seeds(
            base_seed, config.id, chash, start, min(start + batch_size, n_episodes)
        )
        env = VectorEnv(config, num_envs=len(seeds))
        obs, masks = env.reset(seeds=np.asarray(seeds, dtype=np.uint64))
        agent.reset(batch_seed(base_seed, config.id, chash, b))
        fly(env, obs, masks, lambda d: np.asarray(agent.act_batch(d.obs, d.masks)), drive=drive)
        out.append(env.outcomes.copy())
    return np.concatenate(out) if out else np.zeros((0, config.n_controlled), dtype=np.int8)


def certify(
    config: ScenarioConfig,
    episodes: int = 1000,
    search_episodes: int = 200,
    agent: str | None = DEFAULT_AGENT,
    base_seed: int = 0,
    enough: int | None = None,
    batch_size: int = 200,
) -> dict[str, Any]:
    """Certify a tactical family on the evaluation's episodes (docs/model.md §8.3).

    (a) holding (action 13 every step) fails in at least :data:`HOLD_FAILS_AT_LEAST` of the
    first ``episodes`` episodes; (b) in each of the first ``search_episodes`` episodes at least
    :data:`MIN_FAMILIES` manoeuvre families have a successful continuation
    (:func:`search_families`; with ``enough`` an episode's search stops once that many are found);
    (c) the agent at ``agent`` (default the MVP resolver, run in this process; None skips it)
    succeeds in a share of the first ``episodes`` episodes within :data:`AGENT_SOLVES`.

    Returns:
        A JSON-ready report: ``hold``, ``families`` (per episode, the families found), ``agent``
        (success rate and Wilson interval), each with ``ok``, and ``ok`` for all three.
    """
    import time

    from cdr_bench.evaluate.metrics import wilson_interval

    if episodes < 1 or search_episodes < 0:
        raise UserError(
            f"expected at least 1 episode and 0 or more search episodes, got {episodes} and "
            f"{search_episodes}"
        )
    chash = config.config_hash()
    seeds = episode_seeds(base_seed, config.id, chash, 0, max(episodes, search_episodes))
    report: dict[str, Any] = {
        "scenario": config.id,
        "version": config.version,
        "config_hash": chash,
        "base_seed": base_seed,
    }

    joint = config.n_controlled > 1
    t0 = time.perf_counter()
    hold = _episode_outcome(hold_outcomes(config, seeds[:episodes]), joint)
    k = int((hold != SUCCESS).sum())
    report["hold"] = {
        "episodes": episodes,
        "failures": k,
        "failure_rate": k / episodes,
        "ci95": list(wilson_interval(k, episodes)),
        "required": f">= {HOLD_FAILS_AT_LEAST}",
        "ok": k / episodes >= HOLD_FAILS_AT_LEAST,
        "seconds": round(time.perf_counter() - t0, 2),
    }

    t0 = time.perf_counter()
    found: list[FamilySearch | JointSearch]
    if joint:
        found = list(search_joint(config, seeds[:search_episodes]))
        names: tuple[str, ...] = JOINT_PATTERNS
        simple: dict[str, int] = {}
    else:
        found = list(search_families(config, seeds[:search_episodes], enough=enough))
        names = FAMILIES
        simple = _simple_successes(config, seeds[:search_episodes])
    counts = [len(r.families) for r in found]
    at_least = sum(c >= MIN_FAMILIES for c in counts)
    report["families"] = {
        "episodes": search_episodes,
        "enough": enough,
        "per_episode": [
            {"episode": i, "seed": r.seed, "families": r.families, "searched": list(r.searched)}
            for i, r in enumerate(found)
        ],
        "kind": "joint manoeuvre patterns" if joint else "manoeuvre families",
        "names": list(names),
        "distribution": {str(n): counts.count(n) for n in range(len(names) + 1)},
        "mean": float(np.mean(counts)) if counts else None,
        "found": {f: sum(f in r.witnesses for r in found) for f in names},
        "simple_manoeuvre_succeeds": simple,
        "share_at_least": at_least / search_episodes if search_episodes else None,
        "required": f"every episode >= {MIN_FAMILIES} "
        + ("joint patterns" if joint else "families"),
        "ok": at_least == search_episodes,
        "seconds": round(time.perf_counter() - t0, 2),
    }

    if agent is not None:
        t0 = time.perf_counter()
        outcome = _episode_outcome(
            agent_outcomes(
                config, agent, base_seed, episodes, batch_size, "all" if joint else "ownship"
            ),
            joint,
        )
        k = int((outcome == SUCCESS).sum())
        lo, hi = AGENT_SOLVES
        report["agent"] = {
            "path": str(agent),
            "flies": "every controlled aircraft" if joint else "the ownship",
            "episodes": episodes,
            "successes": k,
            "success_rate": k / episodes,
            "ci95": list(wilson_interval(k, episodes)),
            "outcomes": {
                name: int((outcome == code).sum()) for code, name in OUTCOME_NAMES.items()
            },
            "required": f"in [{lo}, {hi}]",
            "ok": lo <= k / episodes <= hi,
            "seconds": round(time.perf_counter() - t0, 2),
        }
    parts = [report["hold"], report["families"]] + ([report["agent"]] if agent else [])
    report["ok"] = all(p["ok"] for p in parts)
    return report


def _simple_successes(config: ScenarioConfig, seeds: list[int]) -> dict[str, int]:
    """Per family, the episodes in which its plain manoeuvre (:data:`SIMPLE_MANOEUVRES`)
    succeeds (where its first action is feasible)."""
    if not seeds:
        return {f: 0 for f in FAMILIES}
    n = len(seeds)
    env = VectorEnv(config, num_envs=n)
    masks = env.reset(seeds=np.asarray(seeds, dtype=np.uint64))[1][:, 0]
    level, speed = env.levels[:, 0], env.speeds_kt[:, 0]
    rows = [(e, f) for f in FAMILIES for e in range(n) if masks[e, SIMPLE_MANOEUVRES[f][0]]]
    result = {f: 0 for f in FAMILIES}
    if not rows:
        return result
    grid = [_simple_follow_on(f, int(level[e]), float(speed[e])) for e, f in rows]
    fam = {k: np.array([g[k] for g in grid]) for k in grid[0]}
    first = np.array([SIMPLE_MANOEUVRES[f][0] for _, f in rows])
    seed_arr = np.asarray(seeds, dtype=np.uint64)[[e for e, _ in rows]]
    _, outcome, _ = search_batch(config, first, fam, seeds=seed_arr)
    for (_, f), o in zip(rows, outcome, strict=True):
        result[f] += int(o == SUCCESS)
    return result


def rollout(config: ScenarioConfig, actions: list[int], seed: int = 0, pad: int = HOLD) -> str:
    """Outcome of the ownship flying ``actions`` (then ``pad`` until the episode ends).

    Returns:
        The outcome name (``"success"``, ``"los"``, ``"nmac"``, ``"boundary"``, ``"timeout"``).
    """
    env = VectorEnv(config)
    obs, masks = env.reset(seeds=[seed])
    fly(env, obs, masks, lambda d: actions[d.t] if d.t < len(actions) else pad, drive="ownship")
    return OUTCOME_NAMES[int(env.outcomes[0, 0])]
