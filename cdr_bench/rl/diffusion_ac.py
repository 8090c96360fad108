"""Diffusion-AC: the policy (reverse denoising + masked head) and Algorithm 1 (one update).

Config keys (JSON-able, stored in every checkpoint): ``obs_dim, width, n_blocks, n_heads, T,
schedule, actor ("diffusion" | "categorical"), twin, critic_width``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from cdr_bench.rl.diffusion import Schedule, masked_logits, masked_softmax
from cdr_bench.rl.networks import (
    N_ACTIONS,
    CategoricalActor,
    Denoiser,
    FlatParameters,
    LearnerParts,
    TwinCritic,
    adam,
    frozen_copy,
    polyak_update,
)


@dataclass
class PolicyConfig:
    obs_dim: int = 42
    width: int = 128
    n_blocks: int = 2
    n_heads: int = 8
    T: int = 10
    schedule: str = "cosine"
    actor: str = "diffusion"
    twin: bool = True
    critic_width: int = 128


class Policy(torch.nn.Module):
    """The actor alone (what an agent needs at inference)."""

    def __init__(self, cfg: PolicyConfig):
        super().__init__()
        self.cfg = cfg
        self.schedule = Schedule(cfg.schedule, cfg.T)
        if cfg.actor == "diffusion":
            self.net: Any = Denoiser(cfg.obs_dim, cfg.width, cfg.n_blocks, cfg.n_heads)
        elif cfg.actor == "categorical":
            self.net = CategoricalActor(cfg.obs_dim, cfg.width, cfg.n_blocks)
        else:
            raise ValueError(f"unknown actor {cfg.actor!r}")

    @torch.inference_mode()
    def clean_logits(self, obs: torch.Tensor, generator: torch.Generator | None = None):
        """y0 for each state: the reverse chain y_T ~ N(0, I) -> y_0 (Eq. 31-32), (N, 27)."""
        if self.cfg.actor == "categorical":
            return self.net(obs)
        sch, n = self.schedule, obs.shape[0]
        c = self.net.condition(self.net.encode(obs), sch.T)  # shared by the T steps
        y = torch.randn(n, N_ACTIONS, generator=generator, device=obs.device)
        for t in range(sch.T, 0, -1):
            y0_hat = self.net.denoise(c, y, t)
            if t == 1:  # alpha_bar_0 = 1: the mean is y0_hat and beta_tilde_1 = 0
                return y0_hat
            z = torch.randn(n, N_ACTIONS, generator=generator, device=obs.device)
            y = sch.reverse_step(y0_hat, y, t, z)
        return y  # pragma: no cover

    @torch.inference_mode()
    def act(
        self,
        obs: torch.Tensor,
        mask: torch.Tensor,
        generator: torch.Generator | None = None,
        sample: bool = False,
    ) -> torch.Tensor:
        """Actions (N,). ``sample=False``: argmax of the masked head (the paper's inference; the
        diffusion actor's stochasticity comes from y_T). ``sample=True``: draw from the masked
        softmax (Eq. 33), used for exploration during training."""
        logits = masked_logits(self.clean_logits(obs, generator), mask)
        if sample:
            return torch.multinomial(torch.softmax(logits, -1), 1, generator=generator).squeeze(-1)
        return logits.argmax(-1)


@dataclass
class UpdateConfig:
    gamma: float = 0.99
    polyak: float = 5e-3
    lr_actor: float = 3e-4
    lr_critic: float = 1e-3
    eps_smooth: float = 0.01
    ce_weight: float = 0.1
    tau_relative: bool = True
    """temperature relative to the per-state spread of Q (True) or absolute (Eq. 37 literal)"""
    ce_input: str = "y0"
    """terminal CE input: "y0" = D(s, y0, 0) as in Eq. 39 (clean teacher logits as input, can be
    satisfied by copying), "noise" = D(s, y_T ~ N(0, I), T) (the inference input), "none" = no CE"""
    q_target_max: float = math.inf
    """upper clip of the critics' TD target (inf: none). Every return of the benchmark's reward is
    at most the goal term (1.0; docs/model.md §6, bounded returns), so a target above it is an
    overestimate by construction; 1.0 removes that part of the critics' feedback loop"""
    diffusion_target: str = "teacher"
    """regression target of the denoiser: "teacher" = y0 = log(p* + eps/27), Eq. 38 (one
    deterministic vector per state, so the optimal denoiser ignores y_t and the argmax policy is
    unimodal up to fitting error); "sample" = log(onehot(a) + eps/27) with a ~ p* (the data
    distribution is then multimodal and the reverse chain maps different y_T to different modes)"""


def teacher_distribution(
    q: torch.Tensor, mask: torch.Tensor, tau: float, relative: bool = False
) -> torch.Tensor:
    """p*(a|s) of Eq. 37 from Q values (N, 27) and masks (N, 27)."""
    if math.isinf(tau):
        return masked_softmax(torch.zeros_like(q), mask)
    if relative:
        m = mask.to(q.dtype)
        n = m.sum(-1, keepdim=True)
        mean = (q * m).sum(-1, keepdim=True) / n
        std = (((q - mean) ** 2 * m).sum(-1, keepdim=True) / n).sqrt()
        q = (q - mean) / (std + 1e-6)
    return masked_softmax(q / tau, mask)


class DiffusionAC(LearnerParts):
    """Actor, twin critics, targets and optimisers; :meth:`update` is Algorithm 1. A
    :class:`~cdr_bench.rl.offpolicy.Learner` of the off-policy loop.

    Args:
        seed: seeds the generator of the exploring actions.
        device: where the networks, the optimisers' state, the generators and the updates
            live (the modules are built on the CPU, so their initial weights do not depend on
            it, then moved).
        explore: action selection while training: "sample" from the masked softmax (Eq. 33) or
            "argmax" (the inference rule).
        tau: the teacher temperature as a function of the DPSC stage (None without the
            curriculum); without it, :attr:`tau` stays as set.
    """

    PARTS = ("policy", "critic", "critic_target", "opt_actor", "opt_critic")
    ACTOR = "policy"

    def __init__(
        self,
        cfg: PolicyConfig,
        ucfg: UpdateConfig,
        seed: int = 0,
        explore: str = "sample",
        tau: Callable[[int | None], float] | None = None,
        device: str | torch.device = "cpu",
    ):
        self.cfg, self.ucfg = cfg, ucfg
        self.device = torch.device(device)
        self.policy = Policy(cfg).to(self.device)
        self.policy.schedule.to(self.device)
        self.critic = TwinCritic(cfg.obs_dim, cfg.critic_width, twin=cfg.twin).to(self.device)
        self.critic_target: Any = frozen_copy(self.critic)
        # one flat tensor per optimised module (after the target's copy)
        self.flat_actor, self.flat_critic = FlatParameters(self.policy), FlatParameters(self.critic)
        self.opt_actor = adam([self.flat_actor.flat], lr=ucfg.lr_actor)
        self.opt_critic = adam([self.flat_critic.flat], lr=ucfg.lr_critic)
        self.explore, self.tau_schedule = explore, tau
        self.tau = 1.0
        """teacher temperature of :meth:`update`"""
        self.generator = torch.Generator(self.device).manual_seed(seed)
        self.eval_generator = torch.Generator(self.device).manual_seed(12345)

    def schedule(self, step: int, stage: int | None) -> dict[str, float]:
        if self.tau_schedule is not None:
            self.tau = self.tau_schedule(stage)
        return {"tau": self.tau}

    def act(self, obs: np.ndarray, mask: np.ndarray, explore: bool) -> np.ndarray:
        """Exploring: ``explore`` rule with the training generator; else the argmax of the
        masked head (the paper's inference) with a generator of its own."""
        gen = self.generator if explore else self.eval_generator
        sample = explore and self.explore == "sample"
        o = torch.from_numpy(obs).to(self.device)
        m = torch.from_numpy(mask).to(self.device)
        return self.policy.act(o, m, gen, sample=sample).cpu().numpy()

    def teacher(self, obs: torch.Tensor, mask: torch.Tensor, tau: float) -> torch.Tensor:
        """Eq. 37: softmax(min Q / tau) over feasible classes; tau = inf -> uniform over them.

        With ``UpdateConfig.tau_relative`` the temperature is in units of the per-state standard
        deviation of min Q over the feasible classes (scale-free; see the README)."""
        with torch.no_grad():
            q = self.critic.min_q(obs)
            return teacher_distribution(q, mask, tau, self.ucfg.tau_relative)

    def update(self, b: dict[str, torch.Tensor]) -> dict[str, float]:
        u, tau = self.ucfg, self.tau
        obs, mask, a = b["obs"], b["mask"], b["action"]
        # (A) critics: masked double-Q max target (Eq. 34-35).
        with torch.no_grad():
            q_next = masked_logits(self.critic_target.min_q(b["next_obs"]), b["next_mask"])
            y = b["reward"] + u.gamma * (1 - b["done"]) * q_next.max(-1).values
            y_max = y.max().item()
            if u.q_target_max != math.inf:
                y = y.clamp(max=u.q_target_max)
        q1, q2 = self.critic(obs)
        q1a = q1.gather(1, a[:, None]).squeeze(1)
        q2a = q2.gather(1, a[:, None]).squeeze(1)
        loss_q = ((q1a - y) ** 2).mean()
        if self.cfg.twin:
            loss_q = loss_q + ((q2a - y) ** 2).mean()
        self.flat_critic.zero_grad()
        loss_q.backward()
        self.flat_critic.collect_grad()
        self.opt_critic.step()
        # (B) teacher (Eq. 37-38) with the updated critics held fixed.
        p_star = self.teacher(obs, mask, tau)
        stats = {
            "loss_q": loss_q.item(),
            "q_mean": q1a.mean().item(),
            "q_max": q1a.max().item(),
            "target_max": y_max,
        }
        loss_pi, actor_stats = self.actor_loss(obs, mask, p_star)
        stats.update(actor_stats)
        self.flat_actor.zero_grad()
        loss_pi.backward()
        self.flat_actor.collect_grad()
        self.opt_actor.step()
        # (E) Polyak averaging of the targets (Eq. 36).
        polyak_update(self.critic_target, self.critic, u.polyak)
        return stats

    def actor_loss(
        self, obs: torch.Tensor, mask: torch.Tensor, p_star: torch.Tensor
    ) -> tuple[torch.Tensor, dict[str, float]]:
        """Steps (C)-(D) of Algorithm 1: the actor's loss given the teacher p* (Eq. 38-41); the
        categorical actor of the "without diffusion" ablation is distilled by cross-entropy."""
        u, sch = self.ucfg, self.policy.schedule
        y0 = torch.log(p_star + u.eps_smooth / N_ACTIONS)
        if self.cfg.actor == "categorical":
            logp = torch.log_softmax(masked_logits(self.policy.net(obs), mask), -1)
            loss_pi = -(p_star * logp.masked_fill(mask == 0, 0.0)).sum(-1).mean()
            return loss_pi, {"loss_ce": loss_pi.item()}
        target = y0
        if u.diffusion_target == "sample":
            a = torch.multinomial(p_star, 1).squeeze(-1)
            onehot = torch.nn.functional.one_hot(a, N_ACTIONS).to(y0.dtype)
            target = torch.log(onehot + u.eps_smooth / N_ACTIONS)
        elif u.diffusion_target != "teacher":
            raise ValueError(
                f"diffusion_target must be 'teacher' or 'sample', got {u.diffusion_target!r}"
            )
        # (C) forward diffusion, (D) denoising regression + terminal CE (Eq. 39-41).
        n = obs.shape[0]
        t = torch.randint(1, sch.T + 1, (n,), device=obs.device)
        yt = sch.q_sample(target, t, torch.randn_like(target))
        net = self.policy.net
        c = net.condition(net.encode(obs), sch.T)  # shared by both terms
        ce = u.ce_input != "none" and u.ce_weight > 0
        if ce:  # both terms in one pass of 2n rows
            if u.ce_input == "y0":
                y_ce, t_ce = y0, torch.zeros_like(t)
            else:
                y_ce, t_ce = torch.randn_like(y0), torch.full_like(t, sch.T)
            pred, term = net.denoise(c, torch.cat([yt, y_ce]), torch.cat([t, t_ce])).split(n)
        else:
            pred = net.denoise(c, yt, t)
        loss_diff = ((pred - target) ** 2).sum(-1).mean()
        loss_pi = loss_diff
        stats = {"loss_diff": loss_diff.item()}
        if ce:
            logp = torch.log_softmax(masked_logits(term, mask), -1)
            loss_ce = -(p_star * logp.masked_fill(mask == 0, 0.0)).sum(-1).mean()
            loss_pi = loss_pi + u.ce_weight * loss_ce
            stats["loss_ce"] = loss_ce.item()
        return loss_pi, stats

    def state_dict(self) -> dict:
        return {**super().state_dict(), "generator": self.generator.get_state()}

    def load_state_dict(self, sd: dict) -> None:
        super().load_state_dict(sd)
        self.generator.set_state(sd["generator"])


def load_policy(path: str) -> Policy:
    """The actor of a ``checkpoint.pt`` written by the trainer (``{"config": {...},
    "state_dict": ..., "meta": {...}}``), read with ``weights_only=True``, in eval mode."""
    ck = torch.load(path, map_location="cpu", weights_only=True)
    pol = Policy(PolicyConfig(**ck["config"]))
    pol.load_state_dict(ck["state_dict"])
    pol.eval()
    return pol
