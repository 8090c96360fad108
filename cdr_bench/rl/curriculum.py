"""The training environment of every trainer: a :class:`~cdr_bench.vector_env.VectorEnv` with the
DPSC curriculum and the training-only reward and horizon changes.

Pure numpy (no torch): the trainer modules import it at module level, and building the
``cdr-bench`` parser must stay torch-free.

* :class:`Curriculum` -- DPSC (paper §4.4.2): twelve stages, promotion on the rolling success of
  the ownship over the episodes of the current stage.
* :class:`CurriculumEnv` -- ``num_envs`` episodes of the training scenario, or of the current
  stage, in one :class:`VectorEnv`. It steps like a VectorEnv (same arrays; a
  :class:`TrainStep` with the face of :class:`~cdr_bench.vector_env.VectorStep`), so the off-policy
  loop and the Stable-Baselines3 adapter (:func:`cdr_bench.wrappers.vector_env_to_sb3`) both run
  on it.
"""

from __future__ import annotations

import copy
from collections import deque
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cdr_bench.sim.core import BOUNDARY, LOS, NMAC, REWARD_TERMS, SUCCESS, StepResult
from cdr_bench.vector_env import VectorEnv

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


@dataclass(frozen=True)
class TrainStep:
    """What :meth:`CurriculumEnv.step` returns: the face of
    :class:`~cdr_bench.vector_env.VectorStep` with the training changes, and more. ``reward``
    includes the failure penalty; ``truncated`` includes the training cut; ``episode_done``
    marks every episode that ended (finished, cut, or discarded by a promotion), and ``obs`` /
    ``action_mask`` are then those of the episode that replaced it."""

    result: StepResult
    """the simulator's report of the step (named reward terms, events, outcomes); its ``obs``
    and ``action_mask`` are those at the end of the step, before any restart"""
    obs: NDArray[np.float32]
    """(E, M, F) observations now"""
    action_mask: NDArray[np.int8]
    """(E, M, 27) feasible actions now"""
    terminated = property(lambda self: self.result.terminated, doc="(E, M) the flight ended")
    reward: NDArray[np.float64]
    """(E, M) reward of the step (0 for aircraft that did not fly)"""
    safety_reward: NDArray[np.float64]
    """(E, M) the safety part R_S of ``reward`` (terms los, nmac) minus the failure penalty"""
    goal_reward = property(lambda self: self.result.goal_reward, doc="(E, M) the goal part R_G")
    truncated: NDArray[np.bool_]
    """(E, M) the horizon or the training cut ended the flight this step"""
    flight_ended: NDArray[np.bool_]
    """(E, M) the aircraft flew this step and its flight ended: finished, cut, or its episode
    was discarded by a promotion (n-step returns stop there)"""
    episode_done: NDArray[np.bool_]
    """(E,) the episode ended this step (and restarted)"""
    restarted = property(lambda self: self.episode_done, doc="(E,) ``episode_done``")
    promoted: bool
    """the curriculum moved to the next stage at the end of this step (every episode restarted
    on the new stage)"""

    final_obs = property(lambda self: self.result.obs, doc="(E, M, F) before any restart")
    final_action_mask = property(
        lambda self: self.result.action_mask, doc="(E, M, 27) feasible before any restart"
    )


class CurriculumEnv:
    """``num_envs`` episodes of ``scenario`` (or of the current DPSC stage; ``overrides``:
    nested scenario fields) in a :class:`VectorEnv`, restarted as they end, with episode seeds
    drawn from a stream seeded by ``seed``.

    The restart is the VectorEnv's auto-reset: its ``autoreset_when`` is this env's rule (the
    training cut, then the outcomes of the episodes that ended are recorded) and its
    ``autoreset_seeds`` this env's stream. With a curriculum, a promotion holds the restarts
    back, the VectorEnv is rebuilt for the new stage and every episode restarts (episodes in
    flight are discarded, not counted). The outcome of an episode is the ownship's.

    Training-only departures from the benchmark's environment (0 turns each off):

    * ``failure_penalty`` (>= 0) is subtracted from the reward of an aircraft whose flight ends
      in LoS, NMAC or ``boundary``. With the paper's reward the path term (-(d_goal/400 km)^2
      per step) sums to several units over a crossing, far more than the -0.5 of a LoS that
      ends a curriculum episode, so a literal agent is paid to end episodes by conflict.
    * ``los_penalty`` (>= 0) is subtracted, every step, per aircraft the controlled aircraft is
      in LoS or NMAC with (the counts of the step's ``los`` and ``nmac`` terms), on top of the
      scenario's own weights: a lever on the benchmark's headline, which counts any LoS.
    * ``max_episode_steps`` ends an episode after that many steps
      (:meth:`VectorEnv.end_episodes`: the aircraft still flying get the ``timeout`` outcome and
      a truncation, which bootstraps).
    """

    autoreset = True
    """the episodes that end restart in the same step (its VectorEnv's auto-reset)"""

    def __init__(
        self,
        num_envs: int,
        seed: int | None = None,
        scenario: str = "medium",
        curriculum: Curriculum | None = None,
        failure_penalty: float = 0.0,
        max_episode_steps: int = 0,
        los_penalty: float = 0.0,
        **overrides: Any,
    ):
        self.num_envs, self.overrides = num_envs, overrides
        self.rng = np.random.default_rng(seed)
        self.curriculum = curriculum
        self.fixed_scenario = scenario
        self.failure_penalty = failure_penalty
        self.max_episode_steps = max_episode_steps
        self.los_penalty = los_penalty
        self.episodes = 0
        self.recent: deque[int] = deque(maxlen=100)  # outcome codes of the last episodes
        self.outcomes: list[int] = []  # outcome codes of the episodes ended since the last read
        self.promotions: list[int] = []  # stages promoted to since the last read
        # what the auto-reset rule found in the step: training truncations, ended flights, promoted
        self._ends: tuple[NDArray[np.bool_], NDArray[np.bool_], bool] | None = None
        self._build()

    @property
    def scenario(self) -> str:
        if self.curriculum is not None:
            return stage_scenario(self.curriculum.stage)
        return self.fixed_scenario

    @property
    def stage(self) -> int | None:
        """The DPSC stage, None without a curriculum."""
        return self.curriculum.stage if self.curriculum is not None else None

    def _seeds(self, n: int) -> NDArray[np.int64]:
        return self.rng.integers(0, 2**62, n)

    def _build(self) -> tuple[NDArray[np.float32], NDArray[np.int8]]:
        self.env = self._attach(VectorEnv(self.scenario, self.num_envs, **self.overrides))
        self.config = self.env.config
        self.n_agents = self.env.n_agents
        self.observation_size = self.env.observation_size
        return self.env.reset(seeds=self._seeds(self.num_envs))

    # -- the VectorEnv face ----------------------------------------------------------------------

    def reset(self, *, seed: int | None = None) -> tuple[NDArray[np.float32], NDArray[np.int8]]:
        """Restart every episode (of the current stage); ``seed`` re-seeds the seed stream."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        return self.env.reset(seeds=self._seeds(self.num_envs))

    def observe(self) -> tuple[NDArray[np.float32], NDArray[np.int8]]:
        return self.env.observe()

    @property
    def flying(self) -> NDArray[np.bool_]:
        return self.env.flying

    def _attach(self, env: VectorEnv) -> VectorEnv:
        """``env`` with this env's auto-reset: its rule and its seed stream."""
        env.autoreset = True
        env.autoreset_when, env.autoreset_seeds = self._episodes_ended, self._seeds
        return env

    def _episodes_ended(self, res: StepResult) -> NDArray[np.bool_]:
        """The VectorEnv's auto-reset rule, called within its step: cut the episodes at the
        training horizon, record the outcomes of the episodes with no aircraft left; restart
        those, or none after a promotion (the VectorEnv is then rebuilt)."""
        env = self.env
        truncated = res.truncated
        flying = env.flying
        if self.max_episode_steps:
            cut = np.flatnonzero((env.episode_steps >= self.max_episode_steps) & flying.any(axis=1))
            if cut.size:
                truncated = truncated.copy()
                truncated[cut] |= flying[cut]
                env.end_episodes(cut)
                flying = env.flying
        ended = np.logical_not(flying.any(axis=1))
        outcomes = env.outcomes
        promoted = False
        for e in np.flatnonzero(ended):
            code = int(outcomes[e, 0])  # the ownship decides the episode
            self.outcomes.append(code)
            self.recent.append(code)
            self.episodes += 1
            if self.curriculum is not None and not promoted:
                promoted = self.curriculum.record(code == SUCCESS)
        self._ends = (truncated, res.acting & ~flying, promoted)
        return np.zeros(self.num_envs, dtype=bool) if promoted else ended

    def step(self, actions: NDArray[np.integer]) -> TrainStep:
        """Advance every episode by one step with (E, M) actions; the episodes that ended
        restart (on the next stage after a promotion)."""
        self._ends = None
        st = self.env.step(actions)  # its auto-reset calls _episodes_ended
        assert self._ends is not None
        truncated, flight_ended, promoted = self._ends
        res = st.result
        failed = (res.outcome == LOS) | (res.outcome == NMAC) | (res.outcome == BOUNDARY)
        penalty = self.failure_penalty * failed
        if self.los_penalty:
            penalty = penalty + self.los_penalty * self._separation_counts(res)
        if promoted:
            assert self.curriculum is not None
            self.promotions.append(self.curriculum.stage)
            obs, masks = self._build()
            episode_done = np.ones(self.num_envs, dtype=bool)
            flight_ended = res.acting.copy()
        else:
            obs, masks, episode_done = st.obs, st.action_mask, st.restarted
        return TrainStep(
            # the step's report with the observations it ended with (before any restart)
            result=replace(res, obs=st.final_obs, action_mask=st.final_action_mask),
            obs=obs,
            action_mask=masks,
            reward=st.reward - penalty,
            safety_reward=res.safety_reward - penalty,
            truncated=truncated,
            flight_ended=flight_ended,
            episode_done=episode_done,
            promoted=promoted,
        )

    def _separation_counts(self, res: StepResult) -> NDArray[np.float64]:
        """(E, M) aircraft each controlled aircraft was in LoS or NMAC with during the step,
        recovered from the step's ``los`` and ``nmac`` terms and the scenario's weights."""
        w = self.config.reward
        out = np.zeros(res.reward.shape)
        for term, weight in (("los", w.los), ("nmac", w.nmac)):
            if weight <= 0:
                raise ValueError(
                    f"los_penalty needs a positive reward.{term} weight in {self.scenario} to "
                    f"count the aircraft in conflict (got {weight})"
                )
            out += np.rint(-res.terms[..., REWARD_TERMS.index(term)] / weight)
        return out

    # -- statistics and state --------------------------------------------------------------------

    def success_rate(self) -> float:
        """Rolling ownship success: over the current stage's window with a curriculum, else
        over the last 100 episodes."""
        if self.curriculum is not None:
            return self.curriculum.success_rate()
        return float(np.mean(np.array(self.recent) == SUCCESS)) if self.recent else 0.0

    def take_outcomes(self) -> list[int]:
        """Outcome codes of the episodes ended since the last call."""
        out, self.outcomes = self.outcomes, []
        return out

    def take_promotions(self) -> list[int]:
        """Stages promoted to since the last call."""
        out, self.promotions = self.promotions, []
        return out

    def state_dict(self) -> dict[str, Any]:
        """Everything needed to continue exactly (the VectorEnv itself is pickled, without its
        auto-reset hooks, which point back here: :meth:`load_state_dict` attaches them)."""
        env = copy.copy(self.env)
        env.autoreset_when = env.autoreset_seeds = None
        return {
            "env": env,
            "rng": self.rng.bit_generator.state,
            "stage": self.stage,
            "results": list(self.curriculum.results) if self.curriculum is not None else [],
            "episodes": self.episodes,
            "recent": list(self.recent),
            "outcomes": list(self.outcomes),
            "promotions": list(self.promotions),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.env = self._attach(state["env"])
        self.config, self.n_agents = self.env.config, self.env.n_agents
        self.observation_size = self.env.observation_size
        self.rng.bit_generator.state = state["rng"]
        if self.curriculum is not None:
            self.curriculum.stage = state["stage"]
            self.curriculum.results.clear()
            self.curriculum.results.extend(state["results"])
        self.episodes = state["episodes"]
        self.recent.clear()
        self.recent.extend(state["recent"])
        self.outcomes, self.promotions = list(state["outcomes"]), list(state["promotions"])
