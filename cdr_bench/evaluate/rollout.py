"""The one loop that flies the episodes of a :class:`~cdr_bench.vector_env.VectorEnv` to their end.

Every part of the evaluator that flies episodes to the end steps through :func:`fly`: the
episode runner (every controlled aircraft decides, :func:`cdr_bench.evaluate.runner.run_batch`),
the first-action analysis (:func:`cdr_bench.evaluate.analysis.first_action_distribution`), the
tactical search and certification (:mod:`cdr_bench.evaluate.search`: the follow-on policies,
holding, the reference resolver, a fixed action sequence) and the trainers' quick evaluation
(:func:`cdr_bench.rl.quick_eval.quick_eval`); the last four drive only the ownship.

Each step, ``decide`` is asked for the actions of the aircraft that decide (:class:`Decisions`:
their episode and aircraft indices, observations and masks; it is not called when none does);
every other slot holds (:data:`~cdr_bench.actions.HOLD`, which the simulator ignores for an
aircraft that is not flying). After the step, ``on_step`` sees the (E, M) actions flown and the
:class:`~cdr_bench.vector_env.VectorStep`; the env's read-only state properties give the state
after the step. Nothing here reads the simulator.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cdr_bench.actions import HOLD
from cdr_bench.errors import ArgumentError
from cdr_bench.vector_env import VectorEnv, VectorStep

__all__ = ["Decide", "Decisions", "OnStep", "fly"]


@dataclass(frozen=True, slots=True)
class Decisions:
    """The aircraft that decide at one step of :func:`fly`, one row each."""

    t: int
    """steps flown so far in this rollout (0 at the first decision)"""
    episodes: NDArray[np.int64]
    """(n,) episode slot of each row, increasing"""
    aircraft: NDArray[np.int64]
    """(n,) controlled aircraft ``m`` of each row (0: the ownship)"""
    obs: NDArray[np.float32]
    """(n, F) observations"""
    masks: NDArray[np.int8]
    """(n, 27) action masks"""

    @property
    def n(self) -> int:
        """Rows (aircraft deciding)."""
        return int(self.episodes.shape[0])


Decide = Callable[[Decisions], ArrayLike]
"""``decide(decisions) -> (n,) actions`` (or one action for every row)."""
OnStep = Callable[[NDArray[np.int64], VectorStep], None]
"""``on_step(actions, step)``: the (E, M) actions just flown (an array reused by the next step:
copy what you keep) and the step's result."""


def fly(
    env: VectorEnv,
    obs: NDArray[np.float32],
    masks: NDArray[np.int8],
    decide: Decide,
    *,
    drive: Literal["all", "ownship"] = "all",
    until: Literal["all", "ownship"] | None = None,
    max_steps: int = 0,
    on_step: OnStep | None = None,
) -> int:
    """Step ``env`` (episodes just started, without auto-reset; ``obs`` and ``masks`` those of
    :meth:`~cdr_bench.vector_env.VectorEnv.reset`) until its aircraft have finished.

    Args:
        env: the episodes.
        obs: (E, M, F) observations of the current state.
        masks: (E, M, 27) action masks of the current state.
        decide: the actions of the deciding aircraft (:class:`Decisions`).
        drive: ``"all"``: every flying controlled aircraft decides (rows in (episode,
            aircraft) order); ``"ownship"``: only flying ownships (aircraft 0) do, learning
            intruders hold.
        until: stop when no controlled aircraft (``"all"``) or no ownship (``"ownship"``) is
            flying any more; default: ``drive``.
        max_steps: stop after this many steps too (0: no limit).
        on_step: called after every step with the actions flown and the step's result.

    Returns:
        The steps flown.
    """
    if drive not in ("all", "ownship"):
        raise ArgumentError(f"drive: expected 'all' or 'ownship', got {drive!r}")
    until = drive if until is None else until
    if until not in ("all", "ownship"):
        raise ArgumentError(f"until: expected 'all' or 'ownship', got {until!r}")
    actions = np.full((env.num_envs, env.n_agents), HOLD, dtype=np.int64)
    flying = env.flying
    t = 0
    while (flying.any() if until == "all" else flying[:, 0].any()) and not (
        max_steps and t >= max_steps
    ):
        if drive == "all":
            rows_e, rows_m = np.nonzero(flying)
        else:
            rows_e = np.flatnonzero(flying[:, 0])
            rows_m = np.zeros_like(rows_e)
        actions[:] = HOLD
        if rows_e.size:
            rows = Decisions(t, rows_e, rows_m, obs[rows_e, rows_m], masks[rows_e, rows_m])
            actions[rows_e, rows_m] = decide(rows)
        step = env.step(actions)
        t += 1
        obs, masks = step.obs, step.action_mask
        flying = env.flying
        if on_step is not None:
            on_step(actions, step)
    return t
