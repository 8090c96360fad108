"""Search over ownship action sequences: which first actions can still lead to success?

Used to certify the tactical scenarios (docs/model.md §8: holding fails, several first actions
succeed) and to label first actions in the multimodality analysis (docs/model.md §10).

The search is a fixed family of *follow-on* policies played after a given first action, all
rolled out in parallel in one :class:`~cdr_bench.vector_env.VectorEnv` (one episode per
candidate sequence, every episode reset with the same seed). A follow-on policy is

1. **turn**: ``turn_steps`` steps of a constant heading change ``turn`` (-1 left, +1 right),
2. **hold**: ``hold_steps`` steps keeping the heading reached,
3. **steer**: until the end, turn toward the goal (one heading step whenever the goal bearing is
   more than half a heading step off the nose),

while climbing or descending one level per step toward ``level`` during phases 1 and 2 and
toward ``final_level`` during phase 3, and changing speed one speed step per step toward
``speed_kt`` throughout. A first action is *successful* when at least one follow-on makes the
ownship reach its goal (outcome ``SUCCESS``); the realised action sequence is the witness.
Failing to find one is evidence, not proof, that no continuation exists.

Only the ownship (controlled aircraft 0) is searched; learning intruders, if any, hold.
"""

from __future__ import annotations

import itertools

import numpy as np
from numpy.typing import NDArray

from cdr_bench.actions import HOLD, N_ACTIONS
from cdr_bench.scenarios.schema import ScenarioConfig
from cdr_bench.sim.core import OUTCOME_NAMES, SUCCESS, Simulator
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
    sim: Simulator, family: dict[str, NDArray[np.float64]], j: int
) -> NDArray[np.int64]:
    """Ownship action of every episode ``j`` steps after the first action, shape (E,)."""
    turning = j < family["turn_steps"]
    steering = j >= family["turn_steps"] + family["hold_steps"]
    # Steer when the goal is more than half a heading step off the nose: with the goal vector g
    # and the heading vector u, cross = |g| sin(off) and dot = |g| cos(off), and off > half
    # exactly when sin(off - half) > 0 with sin(off) > 0 (no angle is computed).
    g = sim.ac_goal_km[:, 0] - sim.ac_pos_km[:, 0]
    u = sim.ac_dir[:, 0]
    cross = g[:, 0] * u[:, 1] - g[:, 1] * u[:, 0]  # + : goal to the right
    dot = g[:, 0] * u[:, 0] + g[:, 1] * u[:, 1]
    s_half, c_half = exact_unit_vector(0.5 * sim.heading_step_deg)
    right = (cross > 0.0) & (cross * c_half - dot * s_half > 0.0)
    left = (cross < 0.0) & (-cross * c_half - dot * s_half > 0.0)
    steer = np.where(right, 1, np.where(left, -1, 0))
    a_psi = np.where(turning, family["turn"], np.where(steering, steer, 0))
    dv = family["speed_kt"] - sim.ac_speed_kt[:, 0]
    a_v = np.where(np.abs(dv) > 0.5 * sim.speed_step_kt, np.sign(dv), 0)
    target_level = np.where(steering, family["final_level"], family["level"])
    a_h = np.sign(target_level - sim.ac_level[:, 0])
    return (9 * (a_psi + 1) + 3 * (a_v + 1) + (a_h + 1)).astype(np.int64)


def search_batch(
    config: ScenarioConfig,
    first_actions: NDArray[np.integer],
    family: dict[str, NDArray[np.float64]],
    seed: int = 0,
) -> tuple[NDArray[np.int64], NDArray[np.int8], NDArray[np.int64]]:
    """Roll out every (first action, follow-on) pair of one batch in parallel.

    Args:
        config: the scenario.
        first_actions: (E,) first action of each episode.
        family: (E,) follow-on parameters per episode, keys as in :func:`follow_on_family`.
        seed: episode seed shared by every episode.

    Returns:
        ``(actions, outcome, n_steps)``: (E, T) ownship actions played (T <= the scenario
        horizon), (E,) outcome code of the ownship, (E,) steps until it finished.
    """
    E = len(first_actions)
    env = VectorEnv(config, num_envs=E)
    env.reset(seeds=np.full(E, seed))
    sim = env.sim
    played = np.full((E, sim.max_steps), HOLD, dtype=np.int64)
    act = np.full((E, sim.M), HOLD, dtype=np.int64)
    for t in range(sim.max_steps):
        if not sim.ac_active[:, 0].any():
            played = played[:, :t]
            break
        a = np.asarray(first_actions) if t == 0 else _follow_on_actions(sim, family, t - 1)
        act[:, 0] = a
        played[:, t] = a
        env.step(act)
    return played, sim.ac_outcome[:, 0].copy(), sim.steps.copy()


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


def rollout(config: ScenarioConfig, actions: list[int], seed: int = 0, pad: int = HOLD) -> str:
    """Outcome of the ownship flying ``actions`` (then ``pad`` until the episode ends).

    Returns:
        The outcome name (``"success"``, ``"los"``, ``"nmac"``, ``"boundary"``, ``"timeout"``).
    """
    env = VectorEnv(config)
    env.reset(seeds=[seed])
    act = np.full((1, env.n_agents), HOLD, dtype=np.int64)
    t = 0
    while env.flying[0, 0]:
        act[0, 0] = actions[t] if t < len(actions) else pad
        env.step(act)
        t += 1
    return OUTCOME_NAMES[int(env.sim.ac_outcome[0, 0])]
