"""Networks: the diffusion denoiser D(s, y_t, t), twin critics Q(s, .) and a categorical actor."""

from __future__ import annotations

import copy
import math
from dataclasses import asdict
from typing import Any

import torch
from torch import nn

N_ACTIONS = 27


def sinusoidal_embedding(t: torch.Tensor, dim: int) -> torch.Tensor:
    """(N,) integer steps -> (N, dim) sinusoidal embedding (Vaswani et al. 2017)."""
    half = dim // 2
    freqs = torch.exp(-math.log(10000.0) * torch.arange(half, device=t.device) / half)
    ang = t.float().unsqueeze(-1) * freqs
    return torch.cat([ang.sin(), ang.cos()], dim=-1)


class StateEncoder(nn.Module):
    """Enc(s): a small MLP with LayerNorm and Mish (§4.2.1)."""

    def __init__(self, obs_dim: int, width: int):
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(obs_dim, width),
            nn.LayerNorm(width),
            nn.Mish(),
            nn.Linear(width, width),
            nn.LayerNorm(width),
            nn.Mish(),
        )

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.net(obs)


class ResidualBlock(nn.Module):
    """Pre-norm residual MLP block."""

    def __init__(self, width: int):
        super().__init__()
        self.net = nn.Sequential(
            nn.LayerNorm(width), nn.Linear(width, width), nn.Mish(), nn.Linear(width, width)
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.net(x)


class Denoiser(nn.Module):
    """D_theta(s, y_t, t) -> predicted clean logits y0_hat, shape (N, 27).

    The paper's UNet (Fig. 4) is over a 27-D vector; we keep its ingredients at a CPU-friendly
    size (§5.1.4): three tokens of width ``width`` -- state embedding Enc(s), sinusoidal step
    embedding, noisy-logit embedding -- mixed by one 8-head self-attention layer, then
    ``n_blocks`` residual blocks on their sum and a linear head.
    """

    def __init__(self, obs_dim: int, width: int = 128, n_blocks: int = 2, n_heads: int = 8):
        super().__init__()
        self.width = width
        self.enc = StateEncoder(obs_dim, width)
        self.t_mlp = nn.Sequential(nn.Linear(width, width), nn.Mish(), nn.Linear(width, width))
        self.y_mlp = nn.Sequential(nn.Linear(N_ACTIONS, width), nn.Mish(), nn.Linear(width, width))
        self.attn_norm = nn.LayerNorm(width)
        self.attn = nn.MultiheadAttention(width, n_heads, batch_first=True)
        self.blocks = nn.Sequential(*[ResidualBlock(width) for _ in range(n_blocks)])
        self.head = nn.Sequential(nn.LayerNorm(width), nn.Linear(width, N_ACTIONS))

    def encode(self, obs: torch.Tensor) -> torch.Tensor:
        """State embedding, reusable across the T reverse steps of one decision."""
        return self.enc(obs)

    def forward_h(self, h: torch.Tensor, yt: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        te = self.t_mlp(sinusoidal_embedding(t, self.width))
        tokens = torch.stack([h, te, self.y_mlp(yt)], dim=1)  # (N, 3, W)
        x = self.attn_norm(tokens)
        tokens = tokens + self.attn(x, x, x, need_weights=False)[0]
        return self.head(self.blocks(tokens.sum(dim=1)))

    def forward(self, obs: torch.Tensor, yt: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        return self.forward_h(self.encode(obs), yt, t)


def mlp(inp: int, width: int, out: int, layers: int = 3) -> nn.Sequential:
    mods: list[nn.Module] = []
    d = inp
    for _ in range(layers - 1):
        mods += [nn.Linear(d, width), nn.ReLU()]
        d = width
    mods.append(nn.Linear(d, out))
    return nn.Sequential(*mods)


class TwinCritic(nn.Module):
    """Q_phi1, Q_phi2 (s, .) in R^27, three layers of width 128 each (Table 1)."""

    def __init__(self, obs_dim: int, width: int = 128, twin: bool = True):
        super().__init__()
        self.q1 = mlp(obs_dim, width, N_ACTIONS)
        self.q2 = mlp(obs_dim, width, N_ACTIONS) if twin else None

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        q1 = self.q1(obs)
        return q1, (self.q2(obs) if self.q2 is not None else q1)

    def min_q(self, obs: torch.Tensor) -> torch.Tensor:
        q1, q2 = self(obs)
        return torch.minimum(q1, q2)


class CategoricalActor(nn.Module):
    """Ablation "without diffusion": logits = f(s), distilled from the same teacher."""

    def __init__(self, obs_dim: int, width: int = 128, n_blocks: int = 2):
        super().__init__()
        self.enc = StateEncoder(obs_dim, width)
        self.blocks = nn.Sequential(*[ResidualBlock(width) for _ in range(n_blocks)])
        self.head = nn.Sequential(nn.LayerNorm(width), nn.Linear(width, N_ACTIONS))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.head(self.blocks(self.enc(obs)))


@torch.no_grad()
def polyak_update(target: nn.Module, source: nn.Module, rho: float) -> None:
    """Eq. 36: target <- rho * source + (1 - rho) * target."""
    for tp, sp in zip(target.parameters(), source.parameters(), strict=True):
        tp.mul_(1.0 - rho).add_(sp, alpha=rho)


def frozen_copy(module: nn.Module) -> nn.Module:
    tgt = copy.deepcopy(module)
    for p in tgt.parameters():
        p.requires_grad_(False)
    return tgt


class LearnerParts:
    """The parts of a :class:`~cdr_bench.rl.offpolicy.Learner` that follow from naming its
    pieces: ``config`` (of ``cfg``), ``actor`` (the attribute named ``ACTOR``), no schedule, and
    ``state_dict`` / ``load_state_dict`` over the modules and optimisers named in ``PARTS``."""

    PARTS: tuple[str, ...] = ()
    ACTOR: str = "net"
    cfg: Any

    @property
    def config(self) -> dict[str, Any]:
        return asdict(self.cfg)

    @property
    def actor(self) -> nn.Module:
        return getattr(self, self.ACTOR)

    def schedule(self, step: int, stage: int | None) -> dict[str, float]:
        return {}

    def state_dict(self) -> dict[str, Any]:
        return {name: getattr(self, name).state_dict() for name in self.PARTS}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        for name in self.PARTS:
            getattr(self, name).load_state_dict(state[name])
