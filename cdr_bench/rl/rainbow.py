"""Rainbow-DQN (Hessel et al. 2018) with action masks, in one file.

The six components, each a small function or class with its own test (tests/rl/test_rainbow.py):

1. **double Q-learning** (van Hasselt et al. 2016): the online network picks the next action,
   the target network scores it (:meth:`Rainbow.target_distribution`);
2. **dueling** aggregation (Wang et al. 2016) per atom: logits(s, a, z) = V(s, z) + A(s, a, z) -
   mean_a' A(s, a', z) (:func:`dueling_aggregate`);
3. **prioritised replay** (Schaul et al. 2016):
   :class:`cdr_bench.rl.replay.PrioritizedReplayBuffer`, priority = the per-sample
   cross-entropy loss, as in the Rainbow paper;
4. **n-step returns**: :class:`cdr_bench.rl.replay.NStepAccumulator`;
5. **distributional** C51 (Bellemare et al. 2017): :func:`project_distribution` (their
   Algorithm 1) and a cross-entropy loss;
6. **noisy nets** (Fortunato et al. 2018), factorised Gaussian: :class:`NoisyLinear`; no
   epsilon-greedy. Inference (the agent) uses the mean weights (``eval()`` mode).

Action masks (the 27-action feasibility mask, SPEC §2) enter twice: acting takes the argmax of
the expected Q over feasible actions only (:func:`masked_argmax`), and the double-Q target picks
the next action among the *next* state's feasible actions.

Network (3 hidden layers of 128, as every baseline): a torso of two linear+ReLU layers, then a
value and an advantage stream, each a noisy hidden layer of 128 and a noisy output layer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from cdr_bench.rl.networks import N_ACTIONS, LearnerParts, frozen_copy, polyak_update


class NoisyLinear(nn.Module):
    """y = (mu_w + sigma_w * eps_w) x + (mu_b + sigma_b * eps_b), factorised Gaussian noise:
    eps_w = f(eps_out) f(eps_in)^T, eps_b = f(eps_out), f(x) = sign(x) sqrt(|x|).
    Initialisation of Fortunato et al. (2018) §3.2: mu ~ U(-1/sqrt(p), 1/sqrt(p)),
    sigma = sigma0 / sqrt(p) with p inputs. In ``eval()`` mode the noise is off (y = mu_w x + mu_b).
    """

    weight_epsilon: torch.Tensor
    bias_epsilon: torch.Tensor

    def __init__(self, in_features: int, out_features: int, sigma0: float = 0.5):
        super().__init__()
        self.in_features, self.out_features = in_features, out_features
        bound = 1.0 / math.sqrt(in_features)
        self.weight_mu = nn.Parameter(
            torch.empty(out_features, in_features).uniform_(-bound, bound)
        )
        self.bias_mu = nn.Parameter(torch.empty(out_features).uniform_(-bound, bound))
        self.weight_sigma = nn.Parameter(torch.full((out_features, in_features), sigma0 * bound))
        self.bias_sigma = nn.Parameter(torch.full((out_features,), sigma0 * bound))
        # Noise is not part of the state dict (the shipped checkpoint holds only parameters).
        self.register_buffer("weight_epsilon", torch.zeros(out_features, in_features), False)
        self.register_buffer("bias_epsilon", torch.zeros(out_features), False)
        self.reset_noise()

    @staticmethod
    def scale_noise(x: torch.Tensor) -> torch.Tensor:
        return x.sign() * x.abs().sqrt()

    def reset_noise(self, generator: torch.Generator | None = None) -> None:
        eps_in = self.scale_noise(torch.randn(self.in_features, generator=generator))
        eps_out = self.scale_noise(torch.randn(self.out_features, generator=generator))
        self.weight_epsilon.copy_(torch.outer(eps_out, eps_in))
        self.bias_epsilon.copy_(eps_out)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.training:
            w = self.weight_mu + self.weight_sigma * self.weight_epsilon
            b = self.bias_mu + self.bias_sigma * self.bias_epsilon
            return F.linear(x, w, b)
        return F.linear(x, self.weight_mu, self.bias_mu)


def dueling_aggregate(value: torch.Tensor, advantage: torch.Tensor) -> torch.Tensor:
    """(N, 1, K) value and (N, A, K) advantage logits -> (N, A, K): V + A - mean_a A."""
    return value + advantage - advantage.mean(dim=1, keepdim=True)


def masked_argmax(q: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """(N, A) values, (N, A) feasibility flags (nonzero = feasible) -> (N,) argmax over the
    feasible actions (every row has at least one: hold is always feasible)."""
    return q.masked_fill(mask == 0, -torch.inf).argmax(dim=1)


def project_distribution(
    probs: torch.Tensor, reward: torch.Tensor, discount: torch.Tensor, support: torch.Tensor
) -> torch.Tensor:
    """C51 projection (Bellemare et al. 2017, Algorithm 1) of the distribution of
    r + discount * Z onto the fixed support.

    probs (N, K) on ``support`` (K,) evenly spaced from v_min to v_max; reward, discount (N,)
    (discount = gamma^n (1 - done)). Each shifted atom Tz_j = clip(r + discount z_j) lands at
    b = (Tz_j - v_min) / dz and splits its mass between atoms floor(b) and ceil(b) in proportion
    to closeness (all of it to b when b is an integer). Returns (N, K), rows summing to 1.
    """
    v_min, v_max = float(support[0]), float(support[-1])
    dz = (v_max - v_min) / (len(support) - 1)
    tz = (reward[:, None] + discount[:, None] * support[None, :]).clamp(v_min, v_max)
    b = (tz - v_min) / dz
    lower, upper = b.floor().long(), b.ceil().long()
    out = torch.zeros_like(probs)
    out.scatter_add_(1, lower, probs * (upper.to(probs.dtype) - b))
    out.scatter_add_(1, upper, probs * (b - lower.to(probs.dtype)))
    out.scatter_add_(1, lower, probs * (lower == upper).to(probs.dtype))
    return out


@dataclass
class RainbowConfig:
    obs_dim: int
    width: int = 128
    n_atoms: int = 51
    v_min: float = -20.0
    v_max: float = 5.0
    sigma0: float = 0.5


class RainbowNet(nn.Module):
    """Dueling distributional Q network with noisy streams: obs (N, F) -> log-probabilities
    (N, 27, n_atoms) over the support."""

    support: torch.Tensor

    def __init__(self, cfg: RainbowConfig):
        super().__init__()
        self.cfg = cfg
        w, k = cfg.width, cfg.n_atoms
        self.torso = nn.Sequential(nn.Linear(cfg.obs_dim, w), nn.ReLU(), nn.Linear(w, w), nn.ReLU())
        self.value = nn.Sequential(
            NoisyLinear(w, w, cfg.sigma0), nn.ReLU(), NoisyLinear(w, k, cfg.sigma0)
        )
        self.advantage = nn.Sequential(
            NoisyLinear(w, w, cfg.sigma0), nn.ReLU(), NoisyLinear(w, N_ACTIONS * k, cfg.sigma0)
        )
        self.register_buffer("support", torch.linspace(cfg.v_min, cfg.v_max, k), False)

    def reset_noise(self, generator: torch.Generator | None = None) -> None:
        for m in self.modules():
            if isinstance(m, NoisyLinear):
                m.reset_noise(generator)

    def log_probs(self, obs: torch.Tensor) -> torch.Tensor:
        h = self.torso(obs)
        v = self.value(h).view(-1, 1, self.cfg.n_atoms)
        a = self.advantage(h).view(-1, N_ACTIONS, self.cfg.n_atoms)
        return F.log_softmax(dueling_aggregate(v, a), dim=-1)

    def q_values(self, obs: torch.Tensor) -> torch.Tensor:
        """(N, 27) expected returns."""
        return (self.log_probs(obs).exp() * self.support).sum(-1)

    @torch.no_grad()
    def act(self, obs: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        return masked_argmax(self.q_values(obs), mask)


class Rainbow(LearnerParts):
    """Online and target networks, Adam, and one update on a prioritised n-step batch. A
    :class:`~cdr_bench.rl.offpolicy.Learner` of the off-policy loop (no schedule: the noisy
    nets explore)."""

    PARTS = ("net", "target", "opt")

    def __init__(
        self, cfg: RainbowConfig, lr: float = 1e-4, adam_eps: float = 1.5e-4, polyak: float = 5e-3
    ):
        self.cfg, self.polyak = cfg, polyak
        self.net = RainbowNet(cfg)
        self.target: RainbowNet = frozen_copy(self.net)  # type: ignore[assignment]
        self.opt = torch.optim.Adam(self.net.parameters(), lr=lr, eps=adam_eps)
        self.priorities = np.zeros(0, np.float32)
        """per-sample priorities (cross-entropy) of the last update's batch"""

    def act(self, obs: np.ndarray, mask: np.ndarray, explore: bool) -> np.ndarray:
        """Exploring: a fresh noise sample, then the masked argmax of the noisy network; else
        the masked argmax of the mean weights (noise off)."""
        self.net.train(explore)
        if explore:
            self.net.reset_noise()
        return self.net.act(torch.from_numpy(obs), torch.from_numpy(mask)).numpy()

    @torch.no_grad()
    def target_distribution(
        self,
        next_obs: torch.Tensor,
        next_mask: torch.Tensor,
        reward: torch.Tensor,
        discount: torch.Tensor,
    ) -> torch.Tensor:
        """Double-Q, masked: a* = argmax over the next state's feasible actions of the online
        expected Q; project the target network's distribution of (s', a*)."""
        a_star = masked_argmax(self.net.q_values(next_obs), next_mask)
        p_next = self.target.log_probs(next_obs).exp()[torch.arange(len(a_star)), a_star]
        return project_distribution(p_next, reward, discount, self.net.support)

    def update(self, b: dict[str, torch.Tensor]) -> dict[str, float]:
        """One gradient step; ``b`` from :meth:`PrioritizedReplayBuffer.sample` (as tensors).
        Returns the losses and ``priorities`` (per-sample cross-entropy) in ``self.priorities``."""
        self.net.reset_noise()
        self.target.reset_noise()
        discount = b["discount"] * (1.0 - b["done"])
        target = self.target_distribution(b["next_obs"], b["next_mask"], b["reward"], discount)
        logp = self.net.log_probs(b["obs"])[torch.arange(len(b["action"])), b["action"]]
        ce = -(target * logp).sum(-1)
        loss = (b["weight"] * ce).mean()
        self.opt.zero_grad()
        loss.backward()
        nn.utils.clip_grad_norm_(self.net.parameters(), 10.0)
        self.opt.step()
        polyak_update(self.target, self.net, self.polyak)
        self.priorities = ce.detach().numpy()
        return {"loss_ce": float(loss.item())}


def load_net(path: str) -> RainbowNet:
    """Rebuild the network from a checkpoint read with ``torch.load(weights_only=True)``;
    returned in ``eval()`` mode (noise off)."""
    ck = torch.load(path, map_location="cpu", weights_only=True)
    net = RainbowNet(RainbowConfig(**ck["config"]))
    net.load_state_dict(ck["state_dict"])
    return net.eval()
