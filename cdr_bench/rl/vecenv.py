"""Batched training environment: E parallel episodes, auto-reset, optional DPSC curriculum.

Pure numpy (no torch). Transitions are per flying controlled aircraft; the reward is the total
of the goal and safety parts of the step (SPEC §2), plus an optional training-only failure
penalty (see :class:`TrainEnv`).
"""

from __future__ import annotations

from collections import deque

import numpy as np
from numpy.typing import NDArray

from cdr_bench.scenarios import load_scenario
from cdr_bench.sim import Simulator, observe
from cdr_bench.sim.core import LOS, NMAC, SUCCESS, TIMEOUT

N_STAGES = 12


def stage_scenario(k: int) -> str:
    return f"curriculum/stage-{k:02d}"


class Curriculum:
    """DPSC (§4.4.2): stage k = 1..12, promotion when the rolling success over the last
    ``window`` episodes *of the stage* reaches ``threshold``; after stage 12 training stays on
    stage 12 (= medium density with LoS at 10 km ending the episode)."""

    def __init__(self, window: int = 100, threshold: float = 0.9, start: int = 1):
        self.window, self.threshold, self.stage = window, threshold, start
        self.results: deque[bool] = deque(maxlen=window)

    def record(self, success: bool) -> bool:
        """Record one finished episode of the current stage; True if that promoted."""
        self.results.append(bool(success))
        if (
            self.stage < N_STAGES
            and len(self.results) == self.window
            and np.mean(self.results) >= self.threshold
        ):
            self.stage += 1
            self.results.clear()
            return True
        return False

    def success_rate(self) -> float:
        return float(np.mean(self.results)) if self.results else 0.0


class TrainEnv:
    """E episodes of one scenario in a batched :class:`Simulator`, auto-reset from a seeded stream.

    With a curriculum, the scenario is the current stage; on promotion the simulator is rebuilt
    for the new stage and every episode restarts (episodes in flight are discarded, not counted).

    ``failure_penalty`` (>= 0) is subtracted from the reward of a transition that ends the
    episode in LoS or NMAC. It is a training-only departure: with the paper's reward the path
    term (-(d_goal/400 km)^2 per step) sums to several units over a crossing, far more than the
    -0.5 of a LoS that ends a curriculum episode, so a literal agent is paid to end episodes by
    conflict. 0 reproduces the literal reward.
    """

    def __init__(
        self,
        n_envs: int,
        seed: int,
        scenario: str | None = "medium",
        curriculum: Curriculum | None = None,
        failure_penalty: float = 0.0,
        max_episode_steps: int = 0,
    ):
        self.E = n_envs
        self.rng = np.random.default_rng(seed)
        self.curriculum = curriculum
        self.fixed_scenario = scenario
        self.failure_penalty = failure_penalty
        self.max_episode_steps = max_episode_steps
        self.episodes = 0
        self.recent: deque[int] = deque(maxlen=100)  # outcome codes of the last episodes
        self._build()

    @property
    def scenario(self) -> str:
        if self.curriculum is not None:
            return stage_scenario(self.curriculum.stage)
        assert self.fixed_scenario is not None
        return self.fixed_scenario

    def _seeds(self, n: int) -> NDArray[np.int64]:
        return self.rng.integers(0, 2**62, n)

    def _build(self) -> None:
        self.sim = Simulator(load_scenario(self.scenario), n_episodes=self.E)
        self.sim.reset(self._seeds(self.E))
        self.M = self.sim.M

    def observe(self) -> tuple[NDArray[np.float32], NDArray[np.int8], NDArray[np.bool_]]:
        """(E*M, F) observations, (E*M, 27) masks, (E*M,) flying flags."""
        obs = observe(self.sim).reshape(self.E * self.M, -1)
        masks = self.sim.action_masks().reshape(self.E * self.M, -1)
        return obs, masks, self.sim.ac_active.reshape(-1).copy()

    def step(self, actions: NDArray[np.integer]) -> dict:
        """Advance all episodes with (E*M,) actions; return the transitions of flying aircraft.

        Returns a dict with ``obs, mask, action, reward, next_obs, next_mask, done`` (rows =
        aircraft that were flying), ``finished`` (list of outcome codes of episodes that ended)
        and ``promoted`` (bool).
        """
        obs, mask, flying = self.observe()
        res = self.sim.step(np.asarray(actions).reshape(self.E, self.M))
        reward = np.sum(list(res.rewards.values()), axis=0).reshape(-1)
        failed = np.isin(res.outcome, (LOS, NMAC)).reshape(-1)
        reward = reward - self.failure_penalty * failed
        next_obs, next_mask, _ = self.observe()
        # Truncation (1000-step horizon) bootstraps; only termination is a terminal state.
        done = res.terminated.reshape(-1).astype(np.float32)
        out = {
            "obs": obs[flying],
            "mask": mask[flying],
            "action": np.asarray(actions)[flying],
            "reward": reward[flying].astype(np.float32),
            "next_obs": next_obs[flying],
            "next_mask": next_mask[flying],
            "done": done[flying],
        }
        if self.max_episode_steps:
            # Training-only horizon: cut long episodes (not terminal, so transitions bootstrap).
            cut = (self.sim.steps >= self.max_episode_steps) & self.sim.ac_active.any(axis=1)
            self.sim.ac_outcome[cut] = np.where(
                self.sim.ac_active[cut], TIMEOUT, self.sim.ac_outcome[cut]
            )
            self.sim.active[cut, self.sim.B :] = False
        ended = np.flatnonzero(~self.sim.ac_active.any(axis=1))
        finished: list[int] = []
        promoted = False
        for e in ended:
            code = int(self.sim.ac_outcome[e, 0])  # the ownship decides the episode
            finished.append(code)
            self.recent.append(code)
            self.episodes += 1
            if self.curriculum is not None and not promoted:
                promoted = self.curriculum.record(code == SUCCESS)
        if promoted:
            self._build()
        elif ended.size:
            self.sim.reset(self._seeds(ended.size), episodes=ended)
        out["finished"], out["promoted"] = finished, promoted
        return out

    def success_rate(self) -> float:
        if self.curriculum is not None:
            return self.curriculum.success_rate()
        return float(np.mean(np.array(self.recent) == SUCCESS)) if self.recent else 0.0
