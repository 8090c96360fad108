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
from typing import Any, cast

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from cdr_bench.rl import kernels
from cdr_bench.rl.networks import (
    N_ACTIONS,
    FlatParameters,
    LearnerParts,
    adam,
    compiled,
    frozen_copy,
    polyak_update,
)


class NoisyLinear(nn.Module):
    """y = (mu_w + sigma_w * eps_w) x + (mu_b + sigma_b * eps_b), factorised Gaussian noise:
    eps_w = f(eps_out) f(eps_in)^T, eps_b = f(eps_out), f(x) = sign(x) sqrt(|x|).
    Initialisation of Fortunato et al. (2018) §3.2: mu ~ U(-1/sqrt(p), 1/sqrt(p)),
    sigma = sigma0 / sqrt(p) with p inputs. In ``eval()`` mode the noise is off (y = mu_w x + mu_b).
    """

    bias_epsilon: torch.Tensor
    input_epsilon: torch.Tensor

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
        # Noise is not part of the state dict (the shipped checkpoint holds only parameters):
        # its factors f(eps_out) (= eps_b) and f(eps_in); eps_w is formed when first used.
        self.register_buffer("bias_epsilon", torch.zeros(out_features), False)
        self.register_buffer("input_epsilon", torch.zeros(in_features), False)
        self._weight_epsilon: torch.Tensor | None = None
        self.reset_noise()

    @staticmethod
    def scale_noise(x: torch.Tensor) -> torch.Tensor:
        return torch.copysign(x.abs().sqrt_(), x)  # sign(x) sqrt(|x|)

    @torch.no_grad()
    def reset_noise(self, generator: torch.Generator | None = None) -> None:
        dev = self.weight_mu.device
        eps_in = self.scale_noise(torch.randn(self.in_features, generator=generator, device=dev))
        eps_out = self.scale_noise(torch.randn(self.out_features, generator=generator, device=dev))
        self.set_noise(eps_in, eps_out)

    def set_noise(self, eps_in: torch.Tensor, eps_out: torch.Tensor) -> None:
        """A new noise sample, given by its factors f(eps_in), f(eps_out)."""
        self.input_epsilon, self.bias_epsilon = eps_in, eps_out
        self._weight_epsilon = None

    @property
    def weight_epsilon(self) -> torch.Tensor:
        """eps_w = f(eps_out) f(eps_in)^T (formed once per noise sample)."""
        if self._weight_epsilon is None:
            self._weight_epsilon = torch.outer(self.bias_epsilon, self.input_epsilon)
        return self._weight_epsilon

    def noise(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The factors (f(eps_in), f(eps_out)) of the noise in use (zeros in eval mode)."""
        if self.training:
            return self.input_epsilon, self.bias_epsilon
        return torch.zeros_like(self.input_epsilon), torch.zeros_like(self.bias_epsilon)

    def parameters_and_noise(self) -> tuple[torch.Tensor, ...]:
        """(mu_w, sigma_w, mu_b, sigma_b, f(eps_in), f(eps_out)), the noise in use (the layout of
        :data:`cdr_bench.rl.kernels.NoisyLayer`)."""
        return (self.weight_mu, self.weight_sigma, self.bias_mu, self.bias_sigma, *self.noise())

    def weights(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The weight and bias in use: noisy in training mode, the means in eval mode."""
        if self.training:
            w = torch.addcmul(self.weight_mu, self.weight_sigma, self.weight_epsilon)
            b = torch.addcmul(self.bias_mu, self.bias_sigma, self.bias_epsilon)
            return w, b
        return self.weight_mu, self.bias_mu

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.linear(x, *self.weights())


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
    to closeness (all of it to b when b is an integer). Returns (N, K), rows summing to 1
    (float32, no gradient; on the CPU one compiled loop,
    :func:`cdr_bench.rl.kernels.c51_projection`, elsewhere :func:`project_tensors`).
    """
    if not compiled(probs, reward, discount, support):
        return project_tensors(probs, reward, discount, support)
    p, r, d, z = (
        x.detach().contiguous().to(torch.float32).numpy()
        for x in (probs, reward, discount, support)
    )
    out = np.empty(p.shape, np.float32)
    kernels.c51_projection(p, r, d, z, out)
    return torch.from_numpy(out)


@torch.no_grad()
def project_tensors(
    probs: torch.Tensor, reward: torch.Tensor, discount: torch.Tensor, support: torch.Tensor
) -> torch.Tensor:
    """:func:`project_distribution` in tensor operations (any device)."""
    probs = probs.detach().to(torch.float32)
    k = support.shape[0]
    v_min, v_max = support[0], support[k - 1]
    dz = ((v_max.double() - v_min.double()) / (k - 1)).float()
    tz = (reward[:, None] + discount[:, None] * support[None, :]).clamp(v_min, v_max)
    b = (tz - v_min) / dz
    lo, hi = b.floor(), b.ceil()
    same = (lo == hi).to(probs.dtype)
    out = torch.zeros_like(probs)
    out.scatter_add_(1, lo.long(), probs * (hi - b + same))
    out.scatter_add_(1, hi.long(), probs * (b - lo))
    return out


@dataclass
class RainbowConfig:
    obs_dim: int
    width: int = 128
    n_atoms: int = 51
    v_min: float = -20.0
    v_max: float = 5.0
    sigma0: float = 0.5


class NoisyHead(torch.autograd.Function):
    """Per sample, the logits of one action minus their mean over the actions, of a noisy
    linear layer with 27 K outputs (K per action): (W h_i + b)[a_i] - mean_a (W h_i + b)[a] with
    W = mu + sigma (eps_out eps_in^T), b = mu_b + sigma_b eps_out. The compiled loops of
    :mod:`cdr_bench.rl.kernels` form neither W nor the 27 K outputs: K dot products per sample
    plus the layer with the mean weights, and a backward pass of the same size. Inputs h (N, I),
    mu, sigma (27 K, I), mu_b, sigma_b (27 K,), eps_in (I,), eps_out (27 K,), actions (N,) long,
    K; output (N, K)."""

    @staticmethod
    def forward(ctx: Any, h, mu, sigma, mu_b, sigma_b, eps_in, eps_out, actions, k):  # type: ignore[override]
        tensors = (h.contiguous(), mu, sigma, mu_b, sigma_b, eps_in, eps_out)
        ctx.save_for_backward(*tensors)
        h_, *layer = (x.detach().numpy() for x in tensors)
        a = actions.numpy()
        out = np.empty((h.shape[0], k), np.float32)
        w_mean = np.empty((k, h.shape[1]), np.float32)
        b_mean = np.empty(k, np.float32)
        kernels.noisy_head_forward(h_, tuple(layer), a, k, out, w_mean, b_mean)
        ctx.extra = (a, k, w_mean)
        return torch.from_numpy(out)

    @staticmethod
    def backward(ctx: Any, grad_out: torch.Tensor):  # type: ignore[override]
        h, *layer = (x.detach().numpy() for x in ctx.saved_tensors)
        a, k, w_mean = ctx.extra
        grads = tuple(np.empty_like(x) for x in (h, *layer[:4]))
        kernels.noisy_head_backward(
            h, tuple(layer), a, k, w_mean, grad_out.contiguous().numpy(), grads
        )
        return *(torch.from_numpy(x) for x in grads), None, None, None, None


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

    @torch.no_grad()
    def reset_noise(self, generator: torch.Generator | None = None) -> None:
        """A new noise sample for every noisy layer: one standard normal draw for all of their
        eps_in and eps_out (layer after layer, in then out), scaled in one pass."""
        seq = (self.value[0], self.value[2], self.advantage[0], self.advantage[2])
        layers = cast(list[NoisyLinear], list(seq))
        sizes = [n for m in layers for n in (m.in_features, m.out_features)]
        draw = torch.randn(sum(sizes), generator=generator, device=self.support.device)
        f = NoisyLinear.scale_noise(draw).split(sizes)
        for i, m in enumerate(layers):
            m.set_noise(f[2 * i], f[2 * i + 1])

    def streams(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Value (N, 1, n_atoms) and advantage (N, 27, n_atoms) logits."""
        h = self.torso(obs)
        v = self.value(h).view(-1, 1, self.cfg.n_atoms)
        a = self.advantage(h).view(-1, N_ACTIONS, self.cfg.n_atoms)
        return v, a

    def log_probs(self, obs: torch.Tensor) -> torch.Tensor:
        return F.log_softmax(dueling_aggregate(*self.streams(obs)), dim=-1)

    def log_probs_of(self, obs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """(N, n_atoms): the rows ``log_probs(obs)[i, actions[i]]`` (the same function),
        computing only what they need: of the advantage's noisy output layer, the logits of
        action a_i minus their mean over the actions (:class:`NoisyHead`; for a linear layer
        the mean over actions is the layer with the mean weights)."""
        h = self.torso(obs)
        v = self.value(h)
        hidden = self.advantage[1](self.advantage[0](h))
        out: NoisyLinear = self.advantage[2]  # type: ignore[assignment]
        if not compiled(hidden):  # the full layer, then the taken actions' rows
            full = out(hidden).view(-1, N_ACTIONS, self.cfg.n_atoms)
            rows = torch.arange(full.shape[0], device=full.device)
            return F.log_softmax(v + full[rows, actions] - full.mean(dim=1), dim=-1)
        d = NoisyHead.apply(hidden, *out.parameters_and_noise(), actions, self.cfg.n_atoms)
        return F.log_softmax(v + d, dim=-1)

    def q_values(self, obs: torch.Tensor) -> torch.Tensor:
        """(N, 27) expected returns."""
        return torch.softmax(dueling_aggregate(*self.streams(obs)), dim=-1) @ self.support

    @torch.no_grad()
    def expected_q(self, obs: torch.Tensor) -> torch.Tensor:
        """:meth:`q_values` (the same function, to float rounding), without gradients and
        faster: the advantage's noisy output layer formed in one pass, its product without the
        bias, then aggregation, softmax over atoms and expectation in one compiled pass per
        state (:func:`cdr_bench.rl.kernels.dueling_expected_q`); off the CPU :meth:`q_values`."""
        if not compiled(obs):
            return self.q_values(obs)
        h = self.torso(obs)
        v = self.value(h)
        hidden = self.advantage[1](self.advantage[0](h))
        out: NoisyLinear = self.advantage[2]  # type: ignore[assignment]
        layer = tuple(x.detach().numpy() for x in out.parameters_and_noise())
        w = np.empty_like(layer[0])
        kernels.noisy_weight(layer, w)
        adv = torch.mm(hidden, torch.from_numpy(w).t())
        b = torch.addcmul(out.bias_mu, out.bias_sigma, out.noise()[1]).detach()
        q = np.empty((len(obs), N_ACTIONS), np.float32)
        kernels.dueling_expected_q(
            adv.numpy(), b.numpy(), v.contiguous().numpy(), self.support.numpy(), q
        )
        return torch.from_numpy(q)

    @torch.no_grad()
    def act(self, obs: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        return masked_argmax(self.q_values(obs), mask)


class Rainbow(LearnerParts):
    """Online and target networks, Adam, and one update on a prioritised n-step batch. A
    :class:`~cdr_bench.rl.offpolicy.Learner` of the off-policy loop (no schedule: the noisy
    nets explore)."""

    PARTS = ("net", "target", "opt")

    def __init__(
        self,
        cfg: RainbowConfig,
        lr: float = 1e-4,
        adam_eps: float = 1.5e-4,
        polyak: float = 5e-3,
        device: str | torch.device = "cpu",
    ):
        self.cfg, self.polyak = cfg, polyak
        self.device = torch.device(device)
        self.net = RainbowNet(cfg).to(self.device)  # built on the CPU: the same initial weights
        self.target: RainbowNet = frozen_copy(self.net)  # type: ignore[assignment]
        self.flat = FlatParameters(self.net)  # after the target's copy
        self.opt = adam([self.flat.flat], lr=lr, eps=adam_eps)
        self.priorities = np.zeros(0, np.float32)
        """per-sample priorities (cross-entropy) of the last update's batch"""

    def act(self, obs: np.ndarray, mask: np.ndarray, explore: bool) -> np.ndarray:
        """Exploring: a fresh noise sample, then the masked argmax of the noisy network; else
        the masked argmax of the mean weights (noise off)."""
        self.net.train(explore)
        if explore:
            self.net.reset_noise()
        with torch.inference_mode():
            q = self.net.expected_q(torch.from_numpy(obs).to(self.device))
            return masked_argmax(q, torch.from_numpy(mask).to(self.device)).cpu().numpy()

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
        a_star = masked_argmax(self.net.expected_q(next_obs), next_mask)
        p_next = self.target.log_probs_of(next_obs, a_star).exp()
        return project_distribution(p_next, reward, discount, self.net.support)

    def update(self, b: dict[str, torch.Tensor]) -> dict[str, float]:
        """One gradient step; ``b`` from :meth:`PrioritizedReplayBuffer.sample` (as tensors).
        Returns the losses and ``priorities`` (per-sample cross-entropy) in ``self.priorities``."""
        self.net.reset_noise()
        self.target.reset_noise()
        discount = b["discount"] * (1.0 - b["done"])
        target = self.target_distribution(b["next_obs"], b["next_mask"], b["reward"], discount)
        logp = self.net.log_probs_of(b["obs"], b["action"])
        ce = -(target * logp).sum(-1)
        loss = (b["weight"] * ce).mean()
        self.flat.zero_grad()
        loss.backward()
        self.flat.collect_grad()
        self.flat.clip_grad_norm(10.0)
        self.opt.step()
        polyak_update(self.target, self.net, self.polyak)
        self.priorities = ce.detach().cpu().numpy()
        return {"loss_ce": float(loss.item())}


def load_net(path: str) -> RainbowNet:
    """Rebuild the network from a checkpoint read with ``torch.load(weights_only=True)``;
    returned in ``eval()`` mode (noise off)."""
    ck = torch.load(path, map_location="cpu", weights_only=True)
    net = RainbowNet(RainbowConfig(**ck["config"]))
    net.load_state_dict(ck["state_dict"])
    return net.eval()
