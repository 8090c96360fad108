"""DDPM in 27-D logit space with x0-prediction (paper Eq. 27-33).

Index convention: arrays have T + 1 entries, index t = 0..T; ``alpha_bar[0] = 1`` (clean).
"""

from __future__ import annotations

import math

import torch

SCHEDULES = ("linear", "cosine")


def make_betas(kind: str, T: int) -> torch.Tensor:
    """beta_1..beta_T, shape (T,), float64.

    ``linear``: the paper's literal schedule, beta from 1e-4 to 2e-2 (Table 1). With T = 10 it
    ends at alpha_bar_T ~ 0.90, i.e. y_T is still mostly signal.
    ``cosine``: Nichol & Dhariwal (2021), alpha_bar(t) = cos^2((t/T + s)/(1 + s) * pi/2),
    betas clipped at 0.999, so alpha_bar_T ~ 1e-3 -- y_T is (almost) pure noise, matching the
    N(0, I) start of inference.
    """
    if kind == "linear":
        return torch.linspace(1e-4, 2e-2, T, dtype=torch.float64)
    if kind == "cosine":
        s = 0.008
        f = [math.cos((t / T + s) / (1 + s) * math.pi / 2) ** 2 for t in range(T + 1)]
        b = [min(1 - f[t] / f[t - 1], 0.999) for t in range(1, T + 1)]
        return torch.tensor(b, dtype=torch.float64)
    raise ValueError(f"unknown schedule {kind!r}; expected one of {SCHEDULES}")


class Schedule:
    """Constants of the forward kernel q(y_t | y_0) and the reverse kernel p(y_{t-1} | y_t)."""

    def __init__(self, kind: str = "cosine", T: int = 10):
        self.kind, self.T = kind, T
        beta = make_betas(kind, T)
        alpha = 1.0 - beta
        abar = torch.cumprod(alpha, 0)
        one = torch.ones(1, dtype=torch.float64)
        self.beta = torch.cat([torch.zeros(1, dtype=torch.float64), beta]).float()  # (T+1,)
        self.alpha = torch.cat([one, alpha]).float()
        abar_full = torch.cat([one, abar])
        self.alpha_bar = abar_full.float()
        abar_prev = torch.cat([one, one, abar[:-1]])  # alpha_bar_{t-1}, index t
        # Eq. 29; index 0 unused (set to 0).
        bt = torch.zeros(T + 1, dtype=torch.float64)
        bt[1:] = (1 - abar_prev[1:]) / (1 - abar_full[1:]) * beta
        self.beta_tilde = bt.float()
        # Eq. 32 coefficients of y0_hat and y_t.
        c0 = torch.zeros(T + 1, dtype=torch.float64)
        ct = torch.zeros(T + 1, dtype=torch.float64)
        c0[1:] = abar_prev[1:].sqrt() * beta / (1 - abar_full[1:])
        ct[1:] = alpha.sqrt() * (1 - abar_prev[1:]) / (1 - abar_full[1:])
        self.coef_y0, self.coef_yt = c0.float(), ct.float()
        # the same constants as Python floats (exactly the float32 values): scalar factors of
        # the reverse step without indexing a tensor
        self._reverse = [
            (float(a), float(b), float(s))
            for a, b, s in zip(self.coef_y0, self.coef_yt, self.beta_tilde.sqrt(), strict=True)
        ]

    def to(self, device: torch.device | str) -> Schedule:
        """The constant tensors moved to ``device`` (in place; returns self)."""
        for name in ("beta", "alpha", "alpha_bar", "beta_tilde", "coef_y0", "coef_yt"):
            setattr(self, name, getattr(self, name).to(device))
        return self

    def tensors(self) -> list[torch.Tensor]:
        return [self.beta, self.alpha, self.alpha_bar, self.beta_tilde, self.coef_y0, self.coef_yt]

    def q_sample(self, y0: torch.Tensor, t: torch.Tensor, noise: torch.Tensor) -> torch.Tensor:
        """Eq. 28/40: y_t = sqrt(abar_t) y0 + sqrt(1 - abar_t) eps; y0 (N, K), t (N,) long."""
        a = self.alpha_bar.to(y0.device)[t].unsqueeze(-1)
        return a.sqrt() * y0 + (1 - a).sqrt() * noise

    def posterior_mean(self, y0_hat: torch.Tensor, yt: torch.Tensor, t: int) -> torch.Tensor:
        """Eq. 32: mean of p(y_{t-1} | y_t) for a scalar step t in 1..T."""
        return self.coef_y0[t] * y0_hat + self.coef_yt[t] * yt

    def reverse_step(
        self, y0_hat: torch.Tensor, yt: torch.Tensor, t: int, z: torch.Tensor
    ) -> torch.Tensor:
        """Eq. 31: y_{t-1} = mean + sqrt(beta_tilde_t) z for a scalar step t in 2..T (the
        arithmetic of :meth:`posterior_mean` plus the noise term, with float factors)."""
        c0, ct, s = self._reverse[t]
        return (y0_hat * c0 + yt * ct) + z * s


def masked_logits(logits: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Logits with infeasible classes set to -inf (mask: 1 = feasible)."""
    return logits.masked_fill(mask == 0, float("-inf"))


def masked_softmax(logits: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Eq. 33: softmax over the feasible classes only; exactly 0 on masked classes."""
    return torch.softmax(masked_logits(logits, mask), dim=-1)
