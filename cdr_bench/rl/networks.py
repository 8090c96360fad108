"""Networks: the diffusion denoiser D(s, y_t, t), twin critics Q(s, .) and a categorical actor."""

from __future__ import annotations

import copy
import math
from dataclasses import asdict
from typing import Any, NamedTuple

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from cdr_bench.actions import N_ACTIONS
from cdr_bench.rl import kernels

COMPILED = True
"""Use the compiled CPU kernels for CPU tensors (tests set it to False to run the tensor
operations that every other device runs, on the CPU, and compare)."""


def compiled(*tensors: torch.Tensor) -> bool:
    """Whether the compiled kernels of :mod:`cdr_bench.rl.kernels` compute on ``tensors``: all
    on the CPU (numba reads their memory) and :data:`COMPILED`. Else the same function in tensor
    operations, on the tensors' device."""
    return COMPILED and all(x.device.type == "cpu" for x in tensors)


def sinusoidal_embedding(t: torch.Tensor, dim: int) -> torch.Tensor:
    """(N,) integer steps -> (N, dim) sinusoidal embedding (Vaswani et al. 2017)."""
    half = dim // 2
    freqs = torch.exp(-math.log(10000.0) * torch.arange(half, device=t.device) / half)
    ang = t.float().unsqueeze(-1) * freqs
    return torch.cat([ang.sin(), ang.cos()], dim=-1)


class _MishFunction(torch.autograd.Function):
    """mish, its derivative computed in the same pass (so the backward pass is one
    multiplication)."""

    @staticmethod
    def forward(ctx: Any, x: torch.Tensor) -> torch.Tensor:  # type: ignore[override]
        xs = x.detach().contiguous().numpy().reshape(-1)
        y, d = np.empty_like(xs), np.empty_like(xs)
        kernels.mish_forward_derivative(xs, y, d)
        ctx.save_for_backward(torch.from_numpy(d).view(x.shape))
        return torch.from_numpy(y).view(x.shape)

    @staticmethod
    def backward(ctx: Any, grad: torch.Tensor) -> torch.Tensor:  # type: ignore[override]
        (derivative,) = ctx.saved_tensors
        return grad * derivative


class Mish(nn.Module):
    """mish(x) = x tanh(softplus(x)) (Misra 2019), as ``nn.Mish`` to float rounding, in one
    compiled pass (:func:`cdr_bench.rl.kernels.mish_forward`; PyTorch's kernel evaluates exp,
    log1p and tanh per element, unvectorised on this CPU). float32."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if not compiled(x):
            return F.mish(x)
        if x.requires_grad and torch.is_grad_enabled():
            return _MishFunction.apply(x)
        xs = x.detach().contiguous().numpy().reshape(-1)
        y = np.empty_like(xs)
        kernels.mish_forward(xs, y)
        return torch.from_numpy(y).view(x.shape)


class StateEncoder(nn.Module):
    """Enc(s): a small MLP with LayerNorm and Mish (§4.2.1)."""

    def __init__(self, obs_dim: int, width: int):
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(obs_dim, width),
            nn.LayerNorm(width),
            Mish(),
            nn.Linear(width, width),
            nn.LayerNorm(width),
            Mish(),
        )

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.net(obs)


class ResidualBlock(nn.Module):
    """Pre-norm residual MLP block."""

    def __init__(self, width: int):
        super().__init__()
        self.net = nn.Sequential(
            nn.LayerNorm(width), nn.Linear(width, width), Mish(), nn.Linear(width, width)
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.net(x)


class Denoiser(nn.Module):
    """D_theta(s, y_t, t) -> predicted clean logits y0_hat, shape (N, 27).

    The paper's UNet (Fig. 4) is over a 27-D vector; we keep its ingredients at a CPU-friendly
    size (§5.1.4): three tokens of width ``width`` -- state embedding Enc(s), sinusoidal step
    embedding, noisy-logit embedding -- mixed by one 8-head self-attention layer, then
    ``n_blocks`` residual blocks on their sum and a linear head.

    Computed as that network, arranged for speed (the same function, to float rounding;
    ``tests/rl/test_fast_training.py`` checks it against ``nn.MultiheadAttention``):
    what depends only on the state (its token's query, key and value) or only on the step (the
    step token for t = 0..T) is computed once per decision or update (:meth:`condition`) and
    shared by the reverse steps or losses that use it (:meth:`denoise`), and since only the sum
    of the three attention outputs is used, it is summed before the output projection.
    """

    def __init__(self, obs_dim: int, width: int = 128, n_blocks: int = 2, n_heads: int = 8):
        super().__init__()
        self.width = width
        self.enc = StateEncoder(obs_dim, width)
        self.t_mlp = nn.Sequential(nn.Linear(width, width), Mish(), nn.Linear(width, width))
        self.y_mlp = nn.Sequential(nn.Linear(N_ACTIONS, width), Mish(), nn.Linear(width, width))
        self.attn_norm = nn.LayerNorm(width)
        self.attn = nn.MultiheadAttention(width, n_heads, batch_first=True)
        self.blocks = nn.Sequential(*[ResidualBlock(width) for _ in range(n_blocks)])
        self.head = nn.Sequential(nn.LayerNorm(width), nn.Linear(width, N_ACTIONS))

    def encode(self, obs: torch.Tensor) -> torch.Tensor:
        """State embedding, reusable across the T reverse steps of one decision."""
        return self.enc(obs)

    def _qkv(self, token: torch.Tensor) -> torch.Tensor:
        """The attention's input projection of one token (..., W) -> (..., 3W): q, k, v."""
        return F.linear(self.attn_norm(token), self.attn.in_proj_weight, self.attn.in_proj_bias)

    def condition(self, h: torch.Tensor, max_t: int) -> Conditioning:
        """What :meth:`denoise` needs of the state embedding h (N, W) and of the steps
        0..``max_t``."""
        te = self.t_mlp(sinusoidal_embedding(torch.arange(max_t + 1, device=h.device), self.width))
        return Conditioning(h, self._qkv(h), te, self._qkv(te))

    def denoise(self, c: Conditioning, yt: torch.Tensor, t: torch.Tensor | int) -> torch.Tensor:
        """y0_hat for noisy logits yt (k N, 27) of the N conditioned states (row r is state
        r mod N: k passes in one) at steps t ((k N,) long, or one int for every row)."""
        n, n_states = yt.shape[0], c.h.shape[0]
        ye = self.y_mlp(yt)
        t_idx: np.ndarray | torch.Tensor
        if compiled(yt):
            t_idx = np.full(n, t, np.int64) if isinstance(t, int) else t.numpy()
            h_idx: np.ndarray | torch.Tensor = np.arange(n, dtype=np.int64) % n_states
        else:  # the indices stay on the device
            t_idx = torch.full((n,), t, device=yt.device) if isinstance(t, int) else t
            h_idx = torch.arange(n, device=yt.device) % n_states
        mixed = three_token_attention(
            c.qkv_h, h_idx, c.qkv_t, t_idx, self._qkv(ye), self.attn.num_heads
        )
        h = c.h if n == n_states else c.h.repeat(n // n_states, 1)
        out = F.linear(mixed, self.attn.out_proj.weight, 3.0 * self.attn.out_proj.bias)
        return self.head(self.blocks(h + c.te[t] + ye + out))

    def forward_h(self, h: torch.Tensor, yt: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        return self.denoise(self.condition(h, int(t.max())), yt, t)

    def forward(self, obs: torch.Tensor, yt: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        return self.forward_h(self.encode(obs), yt, t)


class Conditioning(NamedTuple):
    """:meth:`Denoiser.condition`: the state embedding h (N, W) and its token's attention
    projection (N, 3W); the step token te for t = 0..max_t (max_t + 1, W) and its projection."""

    h: torch.Tensor
    qkv_h: torch.Tensor
    te: torch.Tensor
    qkv_t: torch.Tensor


class ThreeTokenAttention(torch.autograd.Function):
    """The denoiser's attention over its three tokens, summed over the queries (before the
    output projection), per row: the compiled loops of :mod:`cdr_bench.rl.kernels` instead of
    a few dozen small tensor operations. Inputs: the [q | k | v] tables of the state token
    (rows picked by ``idx0``), of the step token (rows ``idx1``) and of the noisy-logit token
    (one row per output row), float32; output (N, W)."""

    @staticmethod
    def forward(ctx: Any, qkv0, idx0, qkv1, idx1, qkv2, heads):  # type: ignore[override]
        qkv0, qkv1, qkv2 = (x.contiguous() for x in (qkv0, qkv1, qkv2))
        n, w = qkv2.shape[0], qkv2.shape[1] // 3
        out = np.empty((n, w), np.float32)
        attn = np.empty((n, heads, 3, 3), np.float32)
        q0, q1, q2 = (x.detach().numpy() for x in (qkv0, qkv1, qkv2))
        kernels.attention_forward((q0, idx0, q1, idx1, q2), heads, out, attn)
        ctx.save_for_backward(qkv0, qkv1, qkv2)
        ctx.extra = (idx0, idx1, heads, attn)
        return torch.from_numpy(out)

    @staticmethod
    def backward(ctx: Any, grad_out: torch.Tensor):  # type: ignore[override]
        idx0, idx1, heads, attn = ctx.extra
        q0, q1, q2 = (x.detach().numpy() for x in ctx.saved_tensors)
        grads = (np.zeros_like(q0), np.zeros_like(q1), np.zeros_like(q2))
        g = grad_out.contiguous().numpy()
        kernels.attention_backward((q0, idx0, q1, idx1, q2), heads, attn, g, grads)
        g0, g1, g2 = (torch.from_numpy(x) for x in grads)
        return g0, None, g1, None, g2, None


def three_token_attention(
    qkv0: torch.Tensor,
    idx0: np.ndarray | torch.Tensor,
    qkv1: torch.Tensor,
    idx1: np.ndarray | torch.Tensor,
    qkv2: torch.Tensor,
    heads: int,
) -> torch.Tensor:
    """:class:`ThreeTokenAttention`, without recording the backward pass when no gradient is
    wanted (acting); off the CPU (indices as tensors) :func:`attention_tensors`."""
    tables = (qkv0, qkv1, qkv2)
    if isinstance(idx0, torch.Tensor) or isinstance(idx1, torch.Tensor):
        return attention_tensors(
            qkv0, torch.as_tensor(idx0), qkv1, torch.as_tensor(idx1), qkv2, heads
        )
    if torch.is_grad_enabled() and any(x.requires_grad for x in tables):
        return ThreeTokenAttention.apply(qkv0, idx0, qkv1, idx1, qkv2, heads)
    q0, q1, q2 = (x.detach().contiguous().numpy() for x in tables)
    out = np.empty((q2.shape[0], q2.shape[1] // 3), np.float32)
    attn = np.empty((q2.shape[0], heads, 3, 3), np.float32)
    kernels.attention_forward((q0, idx0, q1, idx1, q2), heads, out, attn)
    return torch.from_numpy(out)


def attention_tensors(
    qkv0: torch.Tensor,
    idx0: torch.Tensor,
    qkv1: torch.Tensor,
    idx1: torch.Tensor,
    qkv2: torch.Tensor,
    heads: int,
) -> torch.Tensor:
    """:class:`ThreeTokenAttention` in tensor operations (any device; autograd gives the
    backward pass): per row and head, softmax(q_i k_j / sqrt(d)) over the three tokens j,
    summed over the three queries i, times the values; (N, W)."""
    rows = torch.stack([qkv0[idx0], qkv1[idx1], qkv2], dim=1)  # (N, 3 tokens, 3 W)
    n, w = rows.shape[0], rows.shape[2] // 3
    d = w // heads
    q, k, v = rows.view(n, 3, 3, heads, d).unbind(2)  # each (N, token, head, d)
    scores = torch.einsum("nihe,njhe->nhij", q, k) * (1.0 / math.sqrt(d))
    weight = torch.softmax(scores, dim=-1).sum(dim=2)  # (N, head, token j)
    return torch.einsum("nhj,njhe->nhe", weight, v).reshape(n, w)


def mlp(inp: int, width: int, out: int, layers: int = 3) -> nn.Sequential:
    mods: list[nn.Module] = []
    d = inp
    for _ in range(layers - 1):
        mods += [nn.Linear(d, width), nn.ReLU()]
        d = width
    mods.append(nn.Linear(d, out))
    return nn.Sequential(*mods)


class TwinCritic(nn.Module):
    """Q_phi1, Q_phi2 (s, .) in R^27, three layers of width 128 each (Table 1); one critic without
    ``twin`` (then Q2 = Q1).

    The critics are computed together: each layer's parameters stacked along a leading critic
    dimension (``weight[l]`` (k, out, in), ``bias[l]`` (k, out)), the first layer one matrix
    product for both (same input), the others one batched product. The same function and the
    same initial weights as two separate :func:`mlp` (tests/rl/test_fast_training.py)."""

    def __init__(self, obs_dim: int, width: int = 128, twin: bool = True):
        super().__init__()
        self.twin = twin
        nets = [mlp(obs_dim, width, N_ACTIONS) for _ in range(2 if twin else 1)]
        layers = [[m for m in net if isinstance(m, nn.Linear)] for net in nets]
        self.weight = nn.ParameterList(
            [nn.Parameter(torch.stack([ls[i].weight.detach() for ls in layers])) for i in range(3)]
        )
        self.bias = nn.ParameterList(
            [nn.Parameter(torch.stack([ls[i].bias.detach() for ls in layers])) for i in range(3)]
        )

    def q_all(self, obs: torch.Tensor) -> torch.Tensor:
        """(k, N, 27): Q of each critic."""
        w0, b0 = self.weight[0], self.bias[0]
        k, width = w0.shape[0], w0.shape[1]
        x = F.linear(obs, w0.reshape(k * width, -1), b0.reshape(k * width))
        x = torch.relu(x).view(-1, k, width).transpose(0, 1)  # (k, N, width)
        x = torch.relu(torch.baddbmm(self.bias[1].unsqueeze(1), x, self.weight[1].transpose(1, 2)))
        return torch.baddbmm(self.bias[2].unsqueeze(1), x, self.weight[2].transpose(1, 2))

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        q = self.q_all(obs)
        return q[0], q[-1]

    def min_q(self, obs: torch.Tensor) -> torch.Tensor:
        q = self.q_all(obs)
        return torch.minimum(q[0], q[-1])

    def _load_from_state_dict(self, state_dict: dict, prefix: str, *args: Any) -> None:
        # a state written before the critics were stacked: q1.0.weight, q1.2.weight, ...
        if prefix + "q1.0.weight" in state_dict:
            nets = ["q1", "q2"] if self.twin else ["q1"]
            for i, layer in enumerate((0, 2, 4)):
                for kind in ("weight", "bias"):
                    parts = [state_dict.pop(f"{prefix}{q}.{layer}.{kind}") for q in nets]
                    state_dict[f"{prefix}{kind}.{i}"] = torch.stack(parts)
        super()._load_from_state_dict(state_dict, prefix, *args)


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
    tps: list[torch.Tensor] = list(target.parameters())
    sps: list[torch.Tensor] = list(source.parameters())
    if len(tps) != len(sps):
        raise ValueError("target and source have different parameters")
    # one multi-tensor operation, one pass: tp + rho (sp - tp)
    torch._foreach_lerp_(tps, sps, rho)


OPTIMIZER_FLAGS = ("fused", "foreach")


class FlatParameters:
    """The parameters of ``module`` made views of one flat tensor :attr:`flat`: an optimiser of
    ``flat`` makes one step for all of them (Adam is elementwise: the same update as per tensor)
    and :meth:`clip_grad_norm` is one norm. Between :meth:`zero_grad` (the parameters' gradients
    set to None, so that the backward pass hands its gradient tensors over without copying) and
    the step, :meth:`collect_grad` copies the gradients into ``flat.grad`` in one operation."""

    def __init__(self, module: nn.Module):
        self.params = list(module.parameters())
        with torch.no_grad():
            self.flat = nn.Parameter(torch.cat([p.reshape(-1) for p in self.params]))
        self.flat.grad = torch.zeros_like(self.flat)
        offset = 0
        for p in self.params:
            n = p.numel()
            p.data = self.flat.data[offset : offset + n].view_as(p)
            offset += n

    def zero_grad(self) -> None:
        for p in self.params:
            p.grad = None

    def collect_grad(self) -> None:
        """``flat.grad`` <- the parameters' gradients (0 where a parameter has none)."""
        grads = [p.grad if p.grad is not None else torch.zeros_like(p) for p in self.params]
        torch.cat([g.reshape(-1) for g in grads], out=self.flat.grad)

    def clip_grad_norm(self, max_norm: float) -> None:
        """``nn.utils.clip_grad_norm_`` (the global 2-norm of the gradients, scaled down to
        ``max_norm`` if above) over ``flat.grad``."""
        assert self.flat.grad is not None
        coef = max_norm / (float(torch.linalg.vector_norm(self.flat.grad)) + 1e-6)
        if coef < 1.0:  # (a factor clamped at 1 leaves the gradient as it is)
            self.flat.grad.mul_(coef)


class FusedAdam(torch.optim.Adam):
    """``torch.optim.Adam(fused=True)`` (the same update, state and state dict) whose step, for
    one parameter group of one tensor (a :class:`FlatParameters`), calls the fused kernel
    directly: ``Adam.step``'s bookkeeping costs more than the kernel at this size."""

    @torch.no_grad()
    def step(self, closure: Any = None) -> Any:  # type: ignore[override]
        group = self.param_groups[0]
        params = group["params"]
        if (
            closure is not None
            or len(self.param_groups) != 1
            or len(params) != 1
            or params[0].grad is None
            or group["amsgrad"]
            or group["capturable"]
            or group["differentiable"]
            or not group["fused"]
        ):
            return super().step(closure)
        p = params[0]
        state = self.state[p]
        if not state:
            state["step"] = torch.zeros((), dtype=torch.float32, device=p.device)
            state["exp_avg"] = torch.zeros_like(p, memory_format=torch.preserve_format)
            state["exp_avg_sq"] = torch.zeros_like(p, memory_format=torch.preserve_format)
        state["step"].add_(1)
        beta1, beta2 = group["betas"]
        torch._fused_adam_(
            [p],
            [p.grad],
            [state["exp_avg"]],
            [state["exp_avg_sq"]],
            [],
            [state["step"]],
            amsgrad=False,
            lr=group["lr"],
            beta1=beta1,
            beta2=beta2,
            weight_decay=group["weight_decay"],
            eps=group["eps"],
            maximize=group["maximize"],
        )
        return None


def adam(params: Any, **kw: Any) -> torch.optim.Adam:
    """Adam with the fused kernel (CPU or CUDA) (one call per step for all parameters instead of a
    dozen small operations per parameter tensor; the same update rule)."""
    return FusedAdam(params, fused=True, **kw)


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

    @property
    def checkpoint_extra(self) -> dict[str, Any]:
        return {}

    def schedule(self, step: int, stage: int | None) -> dict[str, float]:
        return {}

    def state_dict(self) -> dict[str, Any]:
        return {name: getattr(self, name).state_dict() for name in self.PARTS}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        for name in self.PARTS:
            part = getattr(self, name)
            if isinstance(part, torch.optim.Optimizer):  # keep how this one computes its step
                flags = [{k: g.get(k) for k in OPTIMIZER_FLAGS} for g in part.param_groups]
                part.load_state_dict(state[name])
                for g, f in zip(part.param_groups, flags, strict=True):
                    g.update(f)
            else:
                part.load_state_dict(state[name])
