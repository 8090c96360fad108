"""Safe-DQN-X: separate Q networks for the safety reward and the goal reward (paper §5.2, ref. [9]).

The paper's reference [9] (Wang et al., "Enhancing Air Traffic Control: A Transparent Deep
Reinforcement Learning Framework for Autonomous Conflict Resolution", Expert Systems with
Applications 260, 2025) "separates the intertwined Q-value learning model into distinct modules
for safety-awareness and efficiency (target attainment)" (its abstract). Neither that abstract
nor the Diffusion-AC paper states how the two modules are combined into one action, so cdr-bench
offers two documented rules (:func:`combine`), chosen with ``--combine``:

* ``sum`` (default) -- reward decomposition: the step reward is R = R_G + R_S, so under one
  policy Q = Q_G + Q_S; act greedily on the sum, and bootstrap *both* components with the action
  the sum picks in the next state. This is Q-decomposition (Russell & Zimdars, ICML 2003) in the
  off-policy form drQ of Juozapaitis et al. ("Explainable Reinforcement Learning via Reward
  Decomposition", IJCAI-19 XAI workshop, 2019), eq. for a' = argmax_a sum_c Q_c(s', a).
* ``lexicographic`` -- safety first: the safe set is the feasible actions whose Q_S is within
  ``slack`` of the best feasible Q_S; among them pick the largest Q_G. Thresholded lexicographic
  Q-learning (Gabor, Kalmar & Szepesvari, ICML 1998; Skalse et al., "Lexicographic Multi-Objective
  Reinforcement Learning", IJCAI 2022). Both components again bootstrap with that action.
* ``mvp-improve`` -- not a rule of the paper: one step of policy improvement on the geometric
  resolver ``mvp`` (:func:`cdr_bench.resolvers.mvp_actions`). The two networks *evaluate*
  ``mvp`` (they bootstrap with ``mvp``'s action in the next state, whatever the behaviour was;
  the behaviour is ``mvp`` with epsilon-random feasible actions), and the policy is ``mvp``'s
  action unless some feasible action's Q_S exceeds Q_S of ``mvp``'s action by more than
  ``slack``; then it is the largest Q_S + Q_G among those actions. Policy improvement
  (Howard 1960; Bertsekas' rollout) with a margin against the critic's error: with exact Q
  values it is never worse than ``mvp``. A further step (``base_steps``, ``--base-policy``)
  evaluates and improves such an improved policy in place of ``mvp`` (policy iteration, one
  step per training run); the checkpoint keeps the earlier steps' networks under ``"base"``.

Masks: every rule chooses among the feasible actions only, in acting and in the targets.
Targets are double-Q style: the online networks choose the next action with the rule, the
target networks score it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from cdr_bench.inference import SafeDQNQ, improved_actions
from cdr_bench.resolvers import mvp_actions
from cdr_bench.rl.networks import N_ACTIONS, LearnerParts, frozen_copy, mlp, polyak_update

RULES = ("sum", "lexicographic", "mvp-improve")


def combine(
    q_safety: torch.Tensor,
    q_goal: torch.Tensor,
    mask: torch.Tensor,
    rule: str = "sum",
    slack: float = 0.1,
    base: torch.Tensor | None = None,
) -> torch.Tensor:
    """(N, 27) safety and goal Q values, (N, 27) feasibility flags -> (N,) chosen actions.

    ``sum``: argmax over feasible a of Q_S(s, a) + Q_G(s, a).
    ``lexicographic``: S = {feasible a : Q_S(s, a) >= max_feasible Q_S(s, .) - slack};
    argmax over a in S of Q_G(s, a).
    ``mvp-improve`` (``base``: (N,) ``mvp``'s actions): B = {feasible a : Q_S(s, a) >
    Q_S(s, base) + slack}; argmax over a in B of Q_S + Q_G if B is not empty, else base.
    """
    infeasible = mask == 0
    if rule == "mvp-improve":
        if base is None:
            raise ValueError("the mvp-improve rule needs mvp's actions (base)")
        q_base = q_safety.gather(1, base[:, None])
        better = (q_safety > q_base + slack) & ~infeasible
        best = (q_safety + q_goal).masked_fill(~better, -torch.inf).argmax(dim=1)
        return torch.where(better.any(dim=1), best, base)
    if rule == "sum":
        return (q_safety + q_goal).masked_fill(infeasible, -torch.inf).argmax(dim=1)
    if rule == "lexicographic":
        qs = q_safety.masked_fill(infeasible, -torch.inf)
        best = qs.max(dim=1, keepdim=True).values
        unsafe = qs < best - slack
        return q_goal.masked_fill(unsafe | infeasible, -torch.inf).argmax(dim=1)
    raise ValueError(f"combination rule must be one of {RULES}, got {rule!r}")


@dataclass
class SafeDQNConfig:
    obs_dim: int
    width: int = 128
    rule: str = "sum"
    slack: float = 0.1


class SafeDQNNet(nn.Module):
    """Two Q networks, each three hidden layers of ``width``: obs (N, F) -> (Q_S, Q_G), (N, 27)."""

    def __init__(self, cfg: SafeDQNConfig):
        super().__init__()
        if cfg.rule not in RULES:
            raise ValueError(f"combination rule must be one of {RULES}, got {cfg.rule!r}")
        self.cfg = cfg
        self.q_safety = mlp(cfg.obs_dim, cfg.width, N_ACTIONS, layers=4)
        self.q_goal = mlp(cfg.obs_dim, cfg.width, N_ACTIONS, layers=4)

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.q_safety(obs), self.q_goal(obs)

    @torch.no_grad()
    def act(
        self, obs: torch.Tensor, mask: torch.Tensor, base: torch.Tensor | None = None
    ) -> torch.Tensor:
        qs, qg = self(obs)
        return combine(qs, qg, mask, self.cfg.rule, self.cfg.slack, base)


class SafeDQN(LearnerParts):
    """Online and target networks, Adam, and one update of both components (Huber loss). A
    :class:`~cdr_bench.rl.offpolicy.Learner` of the off-policy loop.

    Exploration is epsilon-greedy over the feasible actions: with probability ``epsilon(step)``
    a uniformly random feasible action (drawn from ``rng``), otherwise the combination rule.
    Without ``epsilon`` it never explores.

    ``base_steps`` (``mvp-improve`` only): earlier improvement steps, first step first, each
    ``{"config", "state_dict"}`` as in a ``checkpoint.pt``. The policy evaluated and improved
    is then ``mvp`` followed by these steps (:func:`cdr_bench.inference.improved_actions`)
    instead of ``mvp`` alone; they are frozen and written into the checkpoint (``"base"``).
    """

    PARTS = ("net", "target", "opt")

    def __init__(
        self,
        cfg: SafeDQNConfig,
        lr: float = 1e-4,
        gamma: float = 0.99,
        polyak: float = 5e-3,
        epsilon: Callable[[int], float] | None = None,
        rng: np.random.Generator | None = None,
        base_steps: list[dict[str, Any]] | None = None,
        device: str | torch.device = "cpu",
    ):
        if base_steps and cfg.rule != "mvp-improve":
            raise ValueError("earlier improvement steps (base_steps) need the mvp-improve rule")
        self.base_steps = list(base_steps or [])
        self._base = [SafeDQNQ.from_step(b) for b in self.base_steps]
        self.device = torch.device(device)
        self.net = SafeDQNNet(cfg).to(self.device)  # built on the CPU: the same initial weights
        self.target: SafeDQNNet = frozen_copy(self.net)  # type: ignore[assignment]
        self.opt = torch.optim.Adam(self.net.parameters(), lr=lr)
        self.cfg, self.gamma, self.polyak = cfg, gamma, polyak
        self.epsilon_schedule, self.rng = epsilon, rng
        self.epsilon = 0.0

    def schedule(self, step: int, stage: int | None) -> dict[str, float]:
        if self.epsilon_schedule is None:
            return {}
        self.epsilon = self.epsilon_schedule(step)
        return {"epsilon": self.epsilon}

    @property
    def checkpoint_extra(self) -> dict[str, Any]:
        return {"base": self.base_steps} if self.base_steps else {}

    def base_actions(self, obs: np.ndarray, mask: np.ndarray) -> np.ndarray:
        """The evaluated policy's actions (``mvp-improve``): ``mvp``, then the earlier steps."""
        return improved_actions(self._base, obs, mask, mvp_actions(obs, mask))

    def act(self, obs: np.ndarray, mask: np.ndarray, explore: bool) -> np.ndarray:
        if self.cfg.rule == "mvp-improve":
            base = self.base_actions(obs, mask)
            if explore:  # the behaviour is the base policy (with epsilon-random actions below)
                actions = base
            else:
                o, m, base_t = (torch.from_numpy(x).to(self.device) for x in (obs, mask, base))
                actions = self.net.act(o, m, base_t).cpu().numpy()
        else:
            o, m = (torch.from_numpy(x).to(self.device) for x in (obs, mask))
            actions = self.net.act(o, m).cpu().numpy()
        if explore and self.epsilon_schedule is not None:
            assert self.rng is not None
            rows = self.rng.random(len(actions)) < self.epsilon
            if rows.any():
                # A uniformly random feasible action: argmax of uniform noise over the feasible set.
                noise = self.rng.random((int(rows.sum()), mask.shape[1]))
                actions[rows] = np.where(mask[rows] > 0, noise, -1).argmax(axis=1)
        return actions

    @torch.no_grad()
    def targets(self, b: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        """y_S = r_S + gamma (1 - done) Q_S'(s', a*), y_G likewise, a* = rule on the online
        networks over the next state's feasible actions (``mvp-improve``: a* = the base policy's
        action, mvp's or the earlier steps', so the networks evaluate that policy)."""
        if self.cfg.rule == "mvp-improve":
            a_star = torch.from_numpy(
                self.base_actions(b["next_obs"].cpu().numpy(), b["next_mask"].cpu().numpy())
            ).to(self.device)
        else:
            qs_on, qg_on = self.net(b["next_obs"])
            a_star = combine(qs_on, qg_on, b["next_mask"], self.cfg.rule, self.cfg.slack)
        qs_t, qg_t = self.target(b["next_obs"])
        idx = torch.arange(len(a_star), device=a_star.device)
        cont = self.gamma * (1.0 - b["done"])
        return (
            b["safety_reward"] + cont * qs_t[idx, a_star],
            b["goal_reward"] + cont * qg_t[idx, a_star],
        )

    def update(self, b: dict[str, torch.Tensor]) -> dict[str, float]:
        y_s, y_g = self.targets(b)
        qs, qg = self.net(b["obs"])
        idx = torch.arange(len(b["action"]), device=b["action"].device)
        loss_s = F.smooth_l1_loss(qs[idx, b["action"]], y_s)
        loss_g = F.smooth_l1_loss(qg[idx, b["action"]], y_g)
        self.opt.zero_grad()
        (loss_s + loss_g).backward()
        nn.utils.clip_grad_norm_(self.net.parameters(), 10.0)
        self.opt.step()
        polyak_update(self.target, self.net, self.polyak)
        return {"loss_safety": float(loss_s.item()), "loss_goal": float(loss_g.item())}


def load_net(path: str) -> SafeDQNNet:
    """Rebuild from a checkpoint read with ``torch.load(weights_only=True)``."""
    ck = torch.load(path, map_location="cpu", weights_only=True)
    net = SafeDQNNet(SafeDQNConfig(**ck["config"]))
    net.load_state_dict(ck["state_dict"])
    return net.eval()
