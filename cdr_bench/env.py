"""PettingZoo environment of the cdr-bench en-route sector. The env card is :class:`CDREnv`."""

from __future__ import annotations

import numbers
from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces
from numpy.typing import NDArray
from pettingzoo import ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec

from cdr_bench.actions import HOLD, N_ACTIONS
from cdr_bench.errors import ActionError, ArgumentError, short_repr
from cdr_bench.scenarios import ScenarioConfig
from cdr_bench.sim import OUTCOME_NAMES, REWARD_TERMS, StepResult
from cdr_bench.vector_env import VectorEnv

_STATE_AC = 8  # x, y, vx, vy, level, active, goal_x, goal_y
_STATE_BG = 6  # x, y, vx, vy, level, active


FLAT_INFO_KEYS = (
    *(f"reward_{t}" for t in REWARD_TERMS),
    "goal_reward",
    "safety_reward",
    "los_count",
    "nmac_count",
    "invalid_action",
    "outside",
    "min_separation_km",
    "step",
    "outcome",
    "episode_seed",
)
"""The keys of ``infos[agent]`` with ``flat_infos=True``: the same every step (reset included),
every value a number (``outcome``: 0 while flying, else the code of ``cdr_bench.sim``'s
``OUTCOME_NAMES``; ``los_count`` / ``nmac_count``: how many aircraft, instead of their ids)."""


class _ActionSpace(spaces.Discrete):
    """``Discrete(27)`` whose ``sample(mask)`` has a short path for the three masks the env
    gives (no descent, all, no climb): gymnasium's ``Discrete.sample`` checks the mask (five
    numpy reductions) and draws ``start + np_random.choice(np.where(mask == 1)[0])``; here the
    feasible indices are looked up by the mask's bytes and the same draw is made as
    ``feasible[np_random.integers(0, len(feasible))]``, which is what ``Generator.choice`` of
    a 1-d array does without ``p``: the same samples and the same stream as
    ``spaces.Discrete(27)`` (``tests/env/test_pettingzoo.py`` checks it). Any other mask or
    argument goes to gymnasium's own ``sample``. Most of the README's random loop at ~50
    agents was these checks and ``choice``'s own."""

    def sample(self, mask: Any = None, probability: Any = None) -> Any:
        if probability is None and type(mask) is np.ndarray and mask.dtype == np.int8:
            feasible = _FEASIBLE.get(mask.tobytes()) if mask.shape == (N_ACTIONS,) else None
            if feasible is not None and self.n == N_ACTIONS:
                return self.start + feasible[self.np_random.integers(0, feasible.shape[0])]
        return super().sample(mask, probability)


def _feasible_by_mask() -> dict[bytes, NDArray[np.int64]]:
    out = {}
    for level in range(3):
        mask = np.array([0 <= level + a % 3 - 1 < 3 for a in range(N_ACTIONS)], dtype=np.int8)
        out[mask.tobytes()] = np.where(mask == 1)[0]
    return out


_FEASIBLE = _feasible_by_mask()


def _flat(info: dict[str, Any], terms: list[float], outcome: int, seed: int) -> dict[str, Any]:
    flat: dict[str, Any] = {f"reward_{t}": v for t, v in zip(REWARD_TERMS, terms, strict=True)}
    flat["goal_reward"] = info["goal_reward"]
    flat["safety_reward"] = info["safety_reward"]
    flat["los_count"] = len(info["los_with"])
    flat["nmac_count"] = len(info["nmac_with"])
    flat["invalid_action"] = float(info["invalid_action"])
    flat["outside"] = float(info["outside"])
    flat["min_separation_km"] = info["min_separation_km"]
    flat["step"] = info["step"]
    flat["outcome"] = outcome
    flat["episode_seed"] = seed
    return flat


class CDREnv(ParallelEnv):
    """cdr-bench: conflict detection and resolution in a 3-level en-route sector.

    ## Description

    A 400 km x 400 km sector with three flight levels (0, 1, 2; 300 m apart) and a fixed network
    of 12 crossing airways carrying steady-state traffic (2, 3 or 4 aircraft per airway:
    24 / 36 / 48 intruders in ``low`` / ``medium`` / ``high``). The **ownship** starts on the
    sector boundary heading for a random goal in the interior and must reach it without losing
    separation. Optionally, some aircraft are **learning intruders** (``intruder_0``, ...): each
    flies its airway from start to end as its goal, under the same observation, action and reward
    definitions; in the ``marl/*-8``, ``-24`` and ``-all`` scenarios some or all of the airway
    aircraft are agents (``aircraft_0``, ...), each flying to its airway's end; in the
    ``marl/*-stream`` scenarios the aircraft the airways spawn during the episode are agents too.
    An agent is in ``agents`` from ``reset`` (or, for one spawned later, from the end of the step
    during which it entered the sky, with its first observation, reward 0 and not done) and
    leaves it on the step it finishes (docs/model.md §8.4).
    Background traffic is part of the environment, not agents.

    | | |
    |---|---|
    | Agents | ``ownship_0``, ``intruder_i`` (learning intruders), ``aircraft_i`` (airway agents) |
    | Action space | ``Discrete(27)`` per agent |
    | Observation | ``Dict(observation=Box(F,) float32, action_mask=Box(27,) int8)`` |
    | Observation size | F = 12 + 10 K (K = 3 nearest aircraft by default: F = 42) |
    | State | ``Box`` of all controlled and background aircraft, see :meth:`state` |
    | Import | ``cdr_bench.parallel_env(scenario="medium")``, ``cdr_bench.env(...)`` (AEC) |
    | Time step | 30 s; horizon 1000 steps |

    ## Action Space

    Index ``9 (a_psi + 1) + 3 (a_v + 1) + (a_h + 1)`` of the triple (a_psi, a_v, a_h) in
    {-1, 0, +1}^3: heading +-5 deg (+1 = right/clockwise), speed +-50 kt (clipped to
    [330, 530] kt), level +-1. 13 is *hold*. See :mod:`cdr_bench.actions`. The action is applied at
    the start of the step. ``action_mask`` flags climbing at level 2 and descending at level 0 as
    infeasible; a masked action does not crash the env: its level change is not executed (the
    heading and speed parts are) and ``infos[agent]["invalid_action"]`` is True. ``step`` takes a
    dict with one action per live agent: a Python or numpy integer (or 0-d integer array) in
    0..26. A value outside 0..26 or not such an integer, a missing live agent and a key that is
    not an agent of the env raise ``cdr_bench.errors.ActionError`` (a ``ValueError``) naming the
    agent and the value; actions for agents that already finished are ignored.

    ## Observation Space

    All values are clipped to the Box bounds. Distances are normalised by the sector size or by
    ``observation.range_km`` (100 km), velocities by 1000 kt.

    | idx | name | meaning |
    |---|---|---|
    | 0 | x | own x: 2 x / size - 1 (-1 west edge, +1 east edge); Box [-3, 3] |
    | 1 | y | own y: 2 y / size - 1; [-3, 3] |
    | 2 | sin_heading | sin(heading), heading clockwise from north |
    | 3 | cos_heading | cos(heading) |
    | 4 | speed | (speed - 430 kt) / 100 kt, in [-1, 1] |
    | 5 | level | level - 1, in {-1, 0, 1} |
    | 6 | goal_dx | (x_goal - x) / size; [-3, 3] |
    | 7 | goal_dy | (y_goal - y) / size; [-3, 3] |
    | 8 | goal_dist | distance to the goal / size; [0, 5] |
    | 9 | goal_sin_rel | sin(bearing to goal - heading); positive: goal to the right |
    | 10 | goal_cos_rel | cos(bearing to goal - heading) |
    | 11 | time | steps elapsed / max_steps |
    | 12 + 10k + 0 | present | 1 if neighbour slot k holds an aircraft (nearest first, any level) |
    | 12 + 10k + 1 | dx | (x_k - x) / 100 km; [-10, 10] |
    | 12 + 10k + 2 | dy | (y_k - y) / 100 km; [-10, 10] |
    | 12 + 10k + 3 | dvx | (vx_k - vx) / 1000 kt; [-2, 2] |
    | 12 + 10k + 4 | dvy | (vy_k - vy) / 1000 kt; [-2, 2] |
    | 12 + 10k + 5 | dlevel | (level_k - level) / 2, in [-1, 1] |
    | 12 + 10k + 6 | dist | horizontal distance / 100 km; [0, 10] |
    | 12 + 10k + 7 | t_cpa | time to closest approach / 600 s, in [0, 1] (0 if diverging) |
    | 12 + 10k + 8 | d_cpa | distance at closest approach within 600 s / 100 km; [0, 10] |
    | 12 + 10k + 9 | conflict | 1 if same level and d_cpa < LoS threshold (a predicted LoS) |

    Empty neighbour slots (fewer than K other aircraft) are all zero.

    ## Rewards

    Per agent and step, named terms in ``infos[agent]["reward_terms"]`` (weights in the
    scenario's ``reward`` section, paper values shown):

    * goal part R_G: ``goal`` +1 on reaching the goal; ``path`` -(d_goal / 400 km)^2 at the end of
      the step; ``boundary`` -0.5 while outside the sector; ``step`` -0.01; ``timeout`` -0.5 when
      the horizon is reached.
    * safety part R_S: ``los`` -0.5 per aircraft in LoS (but not NMAC) during the step; ``nmac``
      -1.0 per aircraft in NMAC during the step.

    The reward is R_G + R_S; ``infos[agent]["goal_reward"]`` and ``["safety_reward"]`` give the
    two parts (the paper's Table 2 reports their episode sums separately).

    ## Separation

    Judged over the whole step, not only at its end: for every pair, the minimum horizontal
    distance of the two straight segments (closest point of approach clipped to [0, 30 s]).
    Same level required; an aircraft changing level occupies both its old and its new level for
    that step. LoS: distance < ``separation.los_km`` (10 km); NMAC: < ``separation.nmac_km``
    (0.2 km). ``infos[agent]["los_with"]`` / ``["nmac_with"]`` list the aircraft involved
    (``bg_<slot>`` for background traffic, agent ids for learning aircraft).

    ## Starting State

    Airways start in steady state (each holds ``per_route`` aircraft one spacing apart, seeded
    random phase; levels assigned cyclically in spawn order). A route spawns its next aircraft
    when the previous one has covered 1 / per_route of it; a spawn waits while a controlled
    aircraft at the spawn level is within 20 km. The ownship starts at a uniform point of the
    boundary >= 20 km from every intruder (any level), at a uniform random level and 430 kt,
    heading for a goal uniform in [20, 380] km^2. Learning intruders start at the entry of their
    airway, at 430 kt, on a level clear of same-level traffic within 20 km. Controlled airway
    aircraft are airway aircraft of the steady state drawn per episode, at 430 kt along their
    airway. Tactical scenarios
    give explicit aircraft, start and goal instead.

    ## Episode End

    Termination (per agent; the agent then leaves ``agents`` and the sky):

    * ``success``: the goal (5 km radius, any level) is reached during the step (swept test);
    * ``nmac``: an NMAC during the step (always ends the agent's episode);
    * ``los``: a LoS during the step, only where ``separation.los_terminates`` (curriculum and
      tactical scenarios);
    * ``boundary``: more than ``sector.boundary_margin_km`` (50 km) outside the sector.

    Priority within one step: nmac > los > boundary > success (a step that reaches the goal and
    also loses separation that ends the episode is a failure). Truncation: ``timeout`` when
    ``max_steps`` (1000) is reached. ``infos[agent]["outcome"]`` names the outcome on the agent's
    last step. Leaving the sector is penalised every step outside; the margin bounds every
    return (docs/model.md §6), and ``sector={"boundary_margin_km": None}`` restores the paper's
    soft boundary (never ends; unbounded path penalty).

    ## Arguments

    ``parallel_env(scenario="medium", render_mode=None, flat_infos=False, **overrides)``:
    ``scenario`` is a registry name (``cdr-bench scenarios list``), a YAML path or a
    ``ScenarioConfig``; ``overrides`` are nested scenario fields, validated like YAML
    (``separation={"los_km": 8.0}``).
    ``reset(seed=None, options=None)``: a seed fixes the episode (traffic, start, goal) and seeds
    every agent's action space; later unseeded resets continue the seeded stream.
    ``options={"episode_seed": s}`` sets the simulator seed directly.
    ``flat_infos=True`` makes ``infos[agent]`` the same numeric keys every step
    (``FLAT_INFO_KEYS``: each reward term, the counts of aircraft in LoS / NMAC, ``outcome`` as a
    code), the form collectors such as TorchRL's ``PettingZooWrapper`` need: TorchRL makes a
    tensor of every info value and fails on the default infos' dict and string ("Could not infer
    dtype of dict"), so use ``PettingZooWrapper(parallel_env("medium", flat_infos=True),
    use_mask=True)``. With it, ``reset`` also returns an observation and an info for every
    possible agent, those still to enter included (TorchRL reads each agent's there); with
    several agents add ``done_on_any=False`` (the episode ends when every agent is done, not
    the first). ``render_mode``:
    ``"rgb_array"`` (512 x 512 x 3 uint8 top-down picture with legend, scale bar, time and
    outcome) or ``"human"`` (matplotlib window). The picture zooms to the encounter in scenarios
    that place aircraft around the ownship (the tactical ones) and shows the whole sector
    otherwise; the attribute ``render_zoom_km`` (``None``: that choice; a number: that many km
    around the ownship; ``math.inf``: the whole sector) overrides it.

    ## Departures from the paper (decided here)

    * Episodes are tens of steps long (a straight crossing takes ~60 steps at 430 kt and 30 s),
      not the ~300 the paper reports; its stated speed, step and sector cannot produce those.
    * Speed bounds [330, 530] kt, goal radius 5 km, the observation layout and the outcome
      priority are ours; the paper is silent on them.
    * Learning intruders fly in addition to the background traffic of the scenario.

    ## Version History

    * v0 (scenario version 1): initial release.
    * v0 (scenario version 2, cdr-bench 0.2.0): the same model on one compiled simulator; new
      episode streams (splitmix64) and headings carried as exactly rotated unit vectors, so every
      episode differs from version 1 (docs/model.md §12).
    * v0 (scenario version 3, cdr-bench 0.3.0): a controlled aircraft 50 km beyond the sector
      ends its episode as ``boundary`` (returns bounded; the paper's soft boundary is
      ``boundary_margin_km: null``); new config hashes, hence new episode seeds.
    """

    metadata: dict[str, Any] = {
        "name": "cdr_bench_v0",
        "render_modes": ["human", "rgb_array"],
        "render_fps": 8,
        "is_parallelizable": True,
    }

    def __init__(
        self,
        scenario: str | ScenarioConfig = "medium",
        render_mode: str | None = None,
        flat_infos: bool = False,
        **overrides: Any,
    ):
        if not isinstance(flat_infos, bool):
            raise ArgumentError(f"flat_infos must be True or False, got {short_repr(flat_infos)}")
        self.flat_infos = flat_infos
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ArgumentError(
                f"render_mode must be one of {self.metadata['render_modes']} or None, "
                f"got {short_repr(render_mode)}"
            )
        if render_mode == "human":
            try:
                import matplotlib  # noqa: F401
            except ImportError:
                raise ImportError(
                    "render_mode='human' draws in a matplotlib window: pip install matplotlib "
                    "(or use render_mode='rgb_array')"
                ) from None
        self.vector = VectorEnv(scenario, num_envs=1, **overrides)
        self.config = self.vector.config
        self.render_mode = render_mode
        self.render_zoom_km: float | None = None
        self.possible_agents = list(self.vector.agent_ids)
        self.agents: list[str] = []
        self._index = {a: i for i, a in enumerate(self.possible_agents)}
        space = self.vector.single_observation_space
        self.observation_spaces: dict[str, spaces.Dict] = {
            a: spaces.Dict(
                {
                    "observation": space["observation"],
                    "action_mask": spaces.Box(0, 1, (N_ACTIONS,), dtype=np.int8),
                }
            )
            for a in self.possible_agents
        }
        self.action_spaces = {a: _ActionSpace(N_ACTIONS) for a in self.possible_agents}
        sim = self.vector.sim
        B, M = sim.B, sim.M
        big = np.float32(1e4)
        self.state_space = spaces.Box(-big, big, (M * _STATE_AC + B * _STATE_BG,), np.float32)
        self._bg_ids = [f"bg_{b}" for b in range(B)]
        self._hold = np.full((1, M), HOLD, dtype=np.int64)
        self._seed_stream = np.random.default_rng()
        self._trail: list[tuple[float, float]] = []
        self._last_result: StepResult | None = None
        self._renderer: Any = None

    @property
    def sim(self) -> Any:
        """The simulator of the episode (a batch of one), for rendering and inspection."""
        return self.vector.sim

    # -- spaces (cached: the same object every call) ----------------------------------------

    def observation_space(self, agent: str) -> spaces.Space:
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Space:
        return self.action_spaces[agent]

    # -- API -----------------------------------------------------------------------------------

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, dict[str, NDArray[Any]]], dict[str, dict[str, Any]]]:
        episode_seed = _check_reset_args(seed, options)
        if seed is not None:
            self._seed_stream = np.random.default_rng(seed)
            for i, a in enumerate(self.possible_agents):
                self.action_spaces[a].seed(seed + i)
                self.observation_spaces[a].seed(seed + i)
        if episode_seed is None:
            episode_seed = int(self._seed_stream.integers(2**63))
        self.episode_seed = int(episode_seed)
        obs, masks = self.vector.reset(seeds=[self.episode_seed])
        flying = self.vector.flying[0]
        self.agents = [a for a, f in zip(self.possible_agents, flying, strict=True) if f]
        self._last_result = None
        self._trail = [tuple(self.vector.sim.ac_pos_km[0, 0].tolist())]
        # flat_infos (TorchRL's collectors): every possible agent has an observation and an info
        # from reset on, those still to enter too (TorchRL's wrapper reads each agent's there).
        first = self.possible_agents if self.flat_infos else self.agents
        out = self._observations(first, obs, masks)
        infos = {a: self._first_info(0) for a in first}
        if self.render_mode == "human":
            self.render()
        return out, infos

    def step(
        self, actions: dict[str, Any]
    ) -> tuple[dict[str, Any], dict[str, float], dict[str, bool], dict[str, bool], dict[str, Any]]:
        if not self.agents:
            raise RuntimeError("step() called with no live agents; call reset() first")
        act = self._hold.copy()
        if type(actions) is not dict and not isinstance(actions, Mapping):
            raise ActionError(
                f"step() takes a dict of agent id -> action, got {short_repr(actions)} of type "
                f"{type(actions).__name__}"
            )
        if not actions.keys() <= self._index.keys():
            key = next(k for k in actions if k not in self._index)
            raise ActionError(
                f"unknown agent {short_repr(key)} in the actions of step() (agents: "
                f"{', '.join(self.possible_agents)})"
            )
        for agent in self.agents:
            if agent not in actions:
                raise ActionError(f"missing action for live agent {agent!r}")
            act[0, self._index[agent]] = check_action(agent, actions[agent])
        acting = self.agents
        out = self.vector._step(act)  # checked above, agent by agent
        res = out.result
        self._last_result = res
        if self.render_mode is not None:
            own = self.vector.sim.ac_pos_km[0, 0].tolist()
            self._trail.append((own[0], own[1]))
        obs_rows, mask_rows = out.obs[0], out.action_mask[0]
        obs, rewards, terms, truncs, infos = {}, {}, {}, {}, {}
        step = int(self.vector.sim.steps[0])
        terms_rows = res.terms[0].tolist()
        flags = res.flags[0].tolist()
        min_sep = res.min_sep_km[0].tolist()
        finished = False
        for agent in acting:
            m = self._index[agent]
            obs[agent] = {"observation": obs_rows[m], "action_mask": mask_rows[m]}
            row = terms_rows[m]  # REWARD_TERMS: the first five are R_G, the last two R_S
            g = row[0] + row[1] + row[2] + row[3] + row[4]
            s = row[5] + row[6]
            rewards[agent] = g + s
            _, invalid, outside, _, term, trunc = flags[m]
            terms[agent] = term
            truncs[agent] = trunc
            info: dict[str, Any] = {
                "reward_terms": dict(zip(REWARD_TERMS, row, strict=True)),
                "goal_reward": g,
                "safety_reward": s,
                "los_with": self._partners(res.los_with[0, m] & ~res.nmac_with[0, m])
                if row[5]
                else [],
                "nmac_with": self._partners(res.nmac_with[0, m]) if row[6] else [],
                "invalid_action": invalid,
                "outside": outside,
                "min_separation_km": min_sep[m],
                "step": step,
            }
            if term or trunc:
                info["outcome"] = OUTCOME_NAMES[int(res.outcome[0, m])]
                finished = True
            if self.flat_infos:
                info = _flat(info, row, int(res.outcome[0, m]), self.episode_seed)
            infos[agent] = info
        entered = self._entered(res)
        for agent in entered:  # aircraft that entered the sky during the step: new agents
            m = self._index[agent]
            obs[agent] = {"observation": obs_rows[m], "action_mask": mask_rows[m]}
            rewards[agent] = 0.0
            terms[agent] = truncs[agent] = False
            infos[agent] = self._first_info(step)
        if finished or entered:
            self.agents = [a for a in acting if not (terms[a] or truncs[a])] + entered
        if self.render_mode == "human":
            self.render()
        return obs, rewards, terms, truncs, infos

    def _first_info(self, step: int) -> dict[str, Any]:
        """The info of an agent's first observation: at ``reset`` (step 0), or at the end of
        the step during which its aircraft entered (``entered: True``)."""
        if self.flat_infos:
            first = {k: 0.0 for k in FLAT_INFO_KEYS} | {"episode_seed": self.episode_seed}
            first["min_separation_km"] = float("inf")
            first["step"] = step if step else 0.0  # as in the infos of a step
            return first
        return {"episode_seed": self.episode_seed} | (
            {"entered": True, "step": step} if step else {}
        )

    def _entered(self, res: StepResult) -> list[str]:
        """The agents whose aircraft entered the sky during the step (spawned by an airway,
        ``traffic.controlled_spawns``), in agent order."""
        if not self.config.traffic.controlled_spawns:
            return []
        new = self.vector.flying[0] & ~res.acting[0]
        return [self.possible_agents[m] for m in np.flatnonzero(new)]

    def _partners(self, row: NDArray[np.bool_]) -> list[str]:
        idx = np.flatnonzero(row)
        B = self.vector.sim.B
        return [self._bg_ids[i] if i < B else self.possible_agents[i - B] for i in idx]

    def _observations(
        self, agents: list[str], obs: NDArray[np.float32], masks: NDArray[np.int8]
    ) -> dict[str, dict[str, NDArray[Any]]]:
        return {
            a: {"observation": obs[0, self._index[a]], "action_mask": masks[0, self._index[a]]}
            for a in agents
        }

    def state(self) -> NDArray[np.float32]:
        """Global state, float32: per controlled aircraft (x, y, vx, vy, level, active, goal x,
        goal y) then per background slot (x, y, vx, vy, level, active); km, km/s."""
        s = self.vector.sim
        ac = np.concatenate(
            [
                s.ac_pos_km[0],
                s.ac_vel_km_s[0],
                s.ac_level[0, :, None],
                s.ac_active[0, :, None],
                s.ac_goal_km[0],
            ],
            axis=1,
        )
        bg = np.concatenate(
            [s.bg_pos_km[0], s.bg_vel_km_s[0], s.bg_level[0, :, None], s.bg_active[0, :, None]],
            axis=1,
        )
        bg = np.where(s.bg_active[0, :, None], bg, 0.0)
        out = np.concatenate([ac.reshape(-1), bg.reshape(-1)]).astype(np.float32)
        return np.clip(out, self.state_space.low, self.state_space.high)

    def render(self) -> NDArray[np.uint8] | None:
        if self.render_mode is None:
            return None
        from cdr_bench.render import draw_frame

        frame = draw_frame(
            self.vector.sim, self._trail, self._last_result, zoom_km=self.render_zoom_km
        )
        if self.render_mode == "rgb_array":
            return frame
        from cdr_bench.render import HumanWindow

        if self._renderer is None:
            self._renderer = HumanWindow(fps=self.metadata["render_fps"])
        self._renderer.show(frame)
        return None

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


def check_action(agent: str, value: Any) -> int:
    """The action of ``agent`` as an int in 0..26: a Python or numpy integer or a 0-d integer
    array. Anything else raises :class:`~cdr_bench.errors.ActionError` naming the agent and the
    value. The one check of a single action (the Gymnasium ``Ownship-v0`` steps through it)."""
    if type(value) is int and 0 <= value < N_ACTIONS:  # the common cases, checked first
        return value
    if type(value) is np.int64 and 0 <= value < N_ACTIONS:  # what ``action_space.sample`` gives
        return int(value)
    v = value
    if isinstance(v, np.ndarray):
        if v.ndim != 0:
            raise ActionError(
                f"action for agent {agent!r} must be one integer in 0..{N_ACTIONS - 1}, got an "
                f"array of shape {v.shape}: {short_repr(value)}"
            )
        v = v[()]
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, numbers.Integral):
        raise ActionError(
            f"action for agent {agent!r} must be an integer in 0..{N_ACTIONS - 1}, got "
            f"{short_repr(value)} of type {type(value).__name__}"
        )
    iv = int(v)
    if not 0 <= iv < N_ACTIONS:
        raise ActionError(
            f"action for agent {agent!r} must be in 0..{N_ACTIONS - 1}, got {short_repr(iv)}"
        )
    return iv


def _check_reset_args(seed: Any, options: Any) -> int | None:
    """Check ``reset``'s arguments; the episode seed of ``options`` (None when not given)."""
    if seed is not None and (
        isinstance(seed, (bool, np.bool_)) or not isinstance(seed, numbers.Integral) or seed < 0
    ):
        raise ArgumentError(
            f"reset(seed=...) expects None or an integer >= 0, got {short_repr(seed)}"
        )
    if options is None:
        return None
    if not isinstance(options, Mapping):
        raise ArgumentError(f"reset(options=...) expects None or a dict, got {short_repr(options)}")
    episode_seed = options.get("episode_seed")
    if episode_seed is None:
        return None
    if (
        isinstance(episode_seed, (bool, np.bool_))
        or not isinstance(episode_seed, numbers.Integral)
        or not 0 <= int(episode_seed) < 2**64
    ):
        raise ArgumentError(
            "reset(options={'episode_seed': ...}) expects an integer in 0..2**64-1, got "
            f"{short_repr(episode_seed)}"
        )
    return int(episode_seed)


def parallel_env(
    scenario: str | ScenarioConfig = "medium", render_mode: str | None = None, **overrides: Any
) -> CDREnv:
    """The PettingZoo parallel environment (see :class:`CDREnv` for the env card)."""
    return CDREnv(scenario, render_mode=render_mode, **overrides)


def env(
    scenario: str | ScenarioConfig = "medium", render_mode: str | None = None, **overrides: Any
) -> Any:
    """The AEC form of :func:`parallel_env` (PettingZoo's ``parallel_to_aec``)."""
    return parallel_to_aec(parallel_env(scenario, render_mode=render_mode, **overrides))


# The reward term names, re-exported for users of the info dict.
__all__ = ["CDREnv", "REWARD_TERMS", "env", "parallel_env"]
