"""Inference-only Diffusion-AC policy in numpy: the same arithmetic as :class:`Policy`, fewer calls.

Where the time goes. A decision is T = 10 reverse steps of the denoiser. In PyTorch each step is
~45 small operator calls at ~4 us of dispatch each, so batch-1 latency is ~2 ms although the
arithmetic is ~0.1 ms. This module removes work that does not depend on the noisy logits y_t and
makes the remaining calls cheap:

* the state token Enc(s) and its query/key/value projections are computed once per decision,
  not once per step;
* the step token (sinusoidal embedding -> MLP -> LayerNorm -> q/k/v) depends only on t, so it is
  a table of T rows built at load time;
* LayerNorm affine parameters are folded into the linear layer that follows them;
* attention over the three tokens is summed over the query axis before the output projection
  (the denoiser sums its tokens, and the projection is linear);
* every remaining operation is a numpy call on float32 arrays (~1 us each at batch 1); means
  are ``np.add.reduce`` times 1/n, since ``ndarray.mean`` alone costs ~10 us per call.

The noise is drawn from the caller's ``torch.Generator`` in exactly the order of
:meth:`Policy.clean_logits` (y_T, then one z per step t = T..2), so both paths follow the same
random stream; they agree to float32 rounding (``tests/rl/test_fast_policy.py``).
"""

from __future__ import annotations

import math

import numpy as np
import torch

from cdr_bench.rl.networks import N_ACTIONS, sinusoidal_embedding

_LN_EPS = 1e-5


def _np(t: torch.Tensor) -> np.ndarray:
    return t.detach().cpu().numpy().astype(np.float32)


def _normalise(x: np.ndarray) -> np.ndarray:
    """LayerNorm without its affine part (folded into the next linear layer).

    ``np.add.reduce(...) * (1 / n)`` instead of ``mean``: the same pairwise sum, ~5x less call
    overhead (``mean`` goes through Python wrappers), and for power-of-two widths bit-identical
    (multiplying by 1/n is exact)."""
    inv_n = 1.0 / x.shape[-1]
    d = x - np.add.reduce(x, axis=-1, keepdims=True) * inv_n
    return d / np.sqrt(np.add.reduce(d * d, axis=-1, keepdims=True) * inv_n + _LN_EPS)


def _mish(x: np.ndarray) -> np.ndarray:
    """x * tanh(softplus(x)) = x * n / (n + 2) with n = e^x (e^x + 2); exact, overflow-safe."""
    e = np.exp(np.minimum(x, 20.0))
    n = e * (e + 2.0)
    return x * n / (n + 2.0)


def _fold(ln: torch.nn.LayerNorm, lin: torch.nn.Linear) -> tuple[np.ndarray, np.ndarray]:
    """W, b of ``lin(ln(x))`` as ``normalise(x) @ W + b`` (W transposed for row vectors)."""
    w = lin.weight.detach() * ln.weight.detach()[None, :]
    b = lin.bias.detach() + lin.weight.detach() @ ln.bias.detach()
    return _np(w.T), _np(b)


class FastDiffusionPolicy:
    """Numpy twin of a diffusion :class:`~cdr_bench.rl.diffusion_ac.Policy` for inference."""

    def __init__(self, policy) -> None:
        if policy.cfg.actor != "diffusion":
            raise ValueError("FastDiffusionPolicy needs a diffusion actor")
        net = policy.net
        sch = policy.schedule
        self.T = sch.T
        self.width = W = net.width
        self.n_heads = H = net.attn.num_heads
        self.head_dim = W // H
        self.scale = 1.0 / math.sqrt(self.head_dim)
        self.coef_y0 = sch.coef_y0.numpy().astype(np.float32)
        self.coef_yt = sch.coef_yt.numpy().astype(np.float32)
        self.sigma = sch.beta_tilde.sqrt().numpy().astype(np.float32)
        enc = net.enc.net  # Linear, LN, Mish, Linear, LN, Mish
        self.e1w, self.e1b = _np(enc[0].weight.T), _np(enc[0].bias)
        self.e1g, self.e1beta = _np(enc[1].weight), _np(enc[1].bias)
        self.e2w, self.e2b = _np(enc[3].weight.T), _np(enc[3].bias)
        self.e2g, self.e2beta = _np(enc[4].weight), _np(enc[4].bias)
        self.y1w, self.y1b = _np(net.y_mlp[0].weight.T), _np(net.y_mlp[0].bias)
        self.y2w, self.y2b = _np(net.y_mlp[2].weight.T), _np(net.y_mlp[2].bias)
        in_proj = torch.nn.Linear(W, 3 * W)
        in_proj.weight.data.copy_(net.attn.in_proj_weight.detach())
        in_proj.bias.data.copy_(net.attn.in_proj_bias.detach())
        self.qkv_w, self.qkv_b = _fold(net.attn_norm, in_proj)
        self.out_w = _np(net.attn.out_proj.weight.T)
        self.out_b3 = 3.0 * _np(net.attn.out_proj.bias)  # one bias per summed token
        self.blocks = [_fold(b.net[0], b.net[1]) + (_np(b.net[3].weight.T), _np(b.net[3].bias))
                       for b in net.blocks]  # fmt: skip
        self.head_w, self.head_b = _fold(net.head[0], net.head[1])
        with torch.no_grad():  # step-token table, index t = 1..T (row 0 unused)
            t = torch.arange(self.T + 1)
            te = _np(net.t_mlp(sinusoidal_embedding(t, W)))
        self.te = te
        self.te_qkv = _normalise(te) @ self.qkv_w + self.qkv_b

    def _heads(self, x: np.ndarray) -> np.ndarray:
        return x.reshape(x.shape[0], self.n_heads, self.head_dim)

    def clean_logits(self, obs: np.ndarray, generator: torch.Generator | None = None) -> np.ndarray:
        """y0 for each state (N, 27): the reverse chain of :meth:`Policy.clean_logits`."""
        obs = np.asarray(obs, dtype=np.float32)
        n, W = obs.shape[0], self.width
        x = _normalise(obs @ self.e1w + self.e1b) * self.e1g + self.e1beta
        x = _mish(x) @ self.e2w + self.e2b
        h = _mish(_normalise(x) * self.e2g + self.e2beta)  # Enc(s), (N, W)
        h_qkv = _normalise(h) @ self.qkv_w + self.qkv_b  # (N, 3W)
        # q/k/v per token, shaped (N, heads, tokens, head_dim); tokens = (state, step, logits)
        q = np.empty((n, self.n_heads, 3, self.head_dim), np.float32)
        k = np.empty_like(q)
        v = np.empty_like(q)
        for arr, sl in ((q, slice(0, W)), (k, slice(W, 2 * W)), (v, slice(2 * W, 3 * W))):
            arr[:, :, 0] = self._heads(h_qkv[:, sl])
        y = torch.randn(n, N_ACTIONS, generator=generator).numpy()
        for t in range(self.T, 0, -1):
            ye = _mish(y @ self.y1w + self.y1b) @ self.y2w + self.y2b
            y_qkv = _normalise(ye) @ self.qkv_w + self.qkv_b
            t_qkv = self.te_qkv[t]
            for arr, sl in ((q, slice(0, W)), (k, slice(W, 2 * W)), (v, slice(2 * W, 3 * W))):
                arr[:, :, 1] = t_qkv[sl].reshape(self.n_heads, self.head_dim)
                arr[:, :, 2] = self._heads(y_qkv[:, sl])
            s = (q @ k.transpose(0, 1, 3, 2)) * self.scale  # (N, H, 3, 3)
            s = np.exp(s - s.max(-1, keepdims=True))
            s /= s.sum(-1, keepdims=True)
            o = (s @ v).sum(2).reshape(n, W)  # attention outputs summed over the 3 queries
            x = h + self.te[t] + ye + o @ self.out_w + self.out_b3
            for w1, b1, w2, b2 in self.blocks:
                x = x + _mish(_normalise(x) @ w1 + b1) @ w2 + b2
            y0_hat = _normalise(x) @ self.head_w + self.head_b
            if t == 1:
                return y0_hat
            z = torch.randn(n, N_ACTIONS, generator=generator).numpy()
            y = self.coef_y0[t] * y0_hat + self.coef_yt[t] * y + self.sigma[t] * z
        raise AssertionError("unreachable")  # pragma: no cover

    def act(
        self, obs: np.ndarray, mask: np.ndarray, generator: torch.Generator | None = None
    ) -> np.ndarray:
        """Argmax of the masked head (the paper's inference), (N,) int64."""
        logits = self.clean_logits(obs, generator)
        logits = np.where(np.asarray(mask) != 0, logits, -np.inf)
        return logits.argmax(-1).astype(np.int64)
