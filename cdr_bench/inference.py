"""Fixed numeric path for the shipped learned agents: the same bits on every x86-64 CPU.

Why. PyTorch, BLAS and numpy pick their kernels by CPU: a matrix product is summed in another
order with AVX-512 than with AVX2 (and with or without FMA), numpy's ``exp``/``tanh`` are SIMD
approximations chosen per instruction set, glibc's ``exp``/``log``/``expm1`` dispatch to FMA
variants that round differently in ~1 of 1,000-10,000 inputs, and ``torch.randn`` is vectorised
per CPU capability. A network's outputs then differ in the last bits between machines; an
argmax on a near tie flips, the episode diverges, and a leaderboard entry cannot be re-checked
on another CPU. This module computes every action of the shipped learned agents (Diffusion-AC
and its ablations, PPO, MaskablePPO, TD3, Rainbow-DQN, Safe-DQN-X) with arithmetic whose result
is fixed by IEEE 754 alone:

* **only correctly rounded operations**: ``+ - * /`` and ``sqrt`` on float32/float64 give one
  result on every CPU (SSE2, AVX2, AVX-512 alike). Nothing else is used at inference;
* **matrix products** are numba loops in a fixed order, ``out[n, j] = sum_k x[n, k] w[k, j]``
  accumulated in float32 over k = 0, 1, ... (the "axpy" form: rows outer, k, then j innermost;
  four rows and four k share a pass over memory, which changes no sum). LLVM vectorises the j
  loop -- independent outputs side by side -- and never the sum itself, so 4-, 8- or 16-lane
  code computes the same bits as scalar code;
* **no FMA, no reassociation**: numba's ``fastmath`` is off, so LLVM neither contracts
  ``a * b + c`` into one fused multiply-add nor reorders a sum
  (``tests/leaderboard/test_cpu_independence.py`` compiles every kernel afresh and finds no
  ``vfmadd``-family instruction in the machine code). Sums (LayerNorm moments, attention,
  softmax) run sequentially in float64;
* **elementwise functions from basic operations**: ``exp``, ``expm1``, ``tanh``, Mish, ``sin``
  and ``cos`` are implemented here (range reduction + fixed polynomial, ~1e-16 relative
  error) instead of calling libm or numpy's ufuncs, both of which are CPU-dispatched;
* **no BLAS anywhere**, including load time: LayerNorm folding and the step-token table are
  computed with the same kernels, the diffusion schedule with the functions above;
* **random numbers** (the diffusion noise) come from ``numpy.random.Generator(PCG64(seed))``,
  seeded by the agent's ``reset``, as float32 standard normals: PCG64 and numpy's ziggurat are
  scalar integer/float code, not dispatched per CPU. Its rare branches call libm: ``expf`` in
  the wedge test (a comparison; a CPU-dependent last bit would have to meet the boundary
  exactly, ~1e-14 per draw) and ``log1pf`` in the tail (no CPU-dispatched variant in glibc).
  numpy does not promise ``Generator``'s algorithms across versions (NEP 19): the "noise"
  golden digest in ``tests/rl/test_fast_policy.py`` fails if an upgrade changes the stream.

The results equal the PyTorch modules' to float rounding (different summation order): the
same action except on near ties (``tests/rl/test_fast_policy.py``), and the same bits under
different kernel settings standing in for different CPUs
(``tests/leaderboard/test_cpu_independence.py``).

Weights come in as the numpy arrays of a checkpoint's ``state_dict`` (read from the file by
:mod:`cdr_bench.weights`, without torch, or by the agent with ``torch.load(weights_only=True)``;
this module imports neither torch nor :mod:`cdr_bench.rl`). Key names are
those of the shipped checkpoints (the modules in :mod:`cdr_bench.rl` that wrote them).

Speed: kernels are compiled once (numba ``cache=True``) and warmed up when a policy is built, so
the evaluator's per-decision time limit never sees a compilation. The Diffusion-AC kernel keeps
the algebraic shortcuts of the former numpy fast path: the state token and its attention
projections are computed once per decision (not once per reverse step), the step token and its
projections are a table of T rows built at load time, LayerNorm affines are folded into the
next linear layer, and attention outputs are summed over the three queries before the output
projection (the denoiser sums its tokens and the projection is linear).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

N_ACTIONS = 27
LN_EPS = 1e-5

_JIT: dict[str, Any] = {"cache": True, "fastmath": False, "error_model": "numpy", "nogil": True}

Array = NDArray[Any]

# ----------------------------------------------------------------------------------------------
# Elementwise functions from + - * / only (float64 arrays; loops LLVM vectorises lane by lane)

_LN2_HI = 6.93147180369123816490e-01  # fdlibm: ln 2 split so that k * _LN2_HI is exact
_LN2_LO = 1.90821492927058770002e-10
_INV_LN2 = 1.44269504088896338700e00
_SHIFT = 6755399441055744.0  # 1.5 * 2^52: v + _SHIFT rounds v to an integer held in low bits
_SHIFT_BITS = int(np.array(_SHIFT).view(np.int64))
_LOG_10000 = 9.210340371976184  # ln(10000) to double precision (a literal: no libm call)
_PIO2_HI = 1.57079632673412561417e00  # fdlibm: pi/2 = _PIO2_HI + _PIO2_LO, n * _PIO2_HI exact
_PIO2_LO = 6.07710050650619224932e-11
_INV_PIO2 = 6.36619772367581382433e-01
# Taylor coefficients 1/n! (correctly rounded divisions of exact integers)
_C = [1.0 / math.factorial(n) for n in range(20)]
C0, C1, C2, C3, C4, C5, C6, C7, C8, C9 = _C[:10]
C10, C11, C12, C13, C14, C15, C16, C17, C18, C19 = _C[10:]
_SIN_COEF = np.array([(-1.0) ** n / math.factorial(2 * n + 1) for n in range(12)])
_COS_COEF = np.array([(-1.0) ** n / math.factorial(2 * n) for n in range(12)])
_CHUNK = 256  # elements per pass of the elementwise kernels


@njit(**_JIT)
def _vexp(x, out, tmp, n):  # pragma: no cover - compiled
    """out[:n] = e^x[:n] (1-D float64; ``tmp`` is scratch; three distinct arrays: LLVM
    vectorises a loop only when its arrays do not overlap, and falls back to scalar code --
    same results, 3x slower -- when they do).

    x = k ln2 + r (Cody-Waite, k by the 1.5 * 2^52 rounding trick), e^r by its Taylor series to
    degree 13 (|r| <= ln2/2: truncation < 1e-17), times 2^k built from the bits of k. Arguments
    are clamped to [-708, 709] (results stay normal numbers; e^-708 ~ 3e-308 stands for 0)."""
    for j in range(n):
        v = x[j]
        v = -708.0 if v < -708.0 else v
        v = 709.0 if v > 709.0 else v
        kd = v * _INV_LN2 + _SHIFT
        tmp[j] = kd
        k = kd - _SHIFT
        r = (v - k * _LN2_HI) - k * _LN2_LO
        p = C13 * r + C12
        p = p * r + C11
        p = p * r + C10
        p = p * r + C9
        p = p * r + C8
        p = p * r + C7
        p = p * r + C6
        p = p * r + C5
        p = p * r + C4
        p = p * r + C3
        p = p * r + C2
        p = p * r + C1
        p = p * r + C0
        out[j] = p
    bits = tmp.view(np.int64)
    for j in range(n):
        bits[j] = (bits[j] - _SHIFT_BITS + 1023) << 52  # 2^k
    for j in range(n):
        out[j] = out[j] * tmp[j]


@njit(**_JIT)
def _vexpm1(x, out, tmp, tmp2, n):  # pragma: no cover - compiled
    """out[:n] = e^x - 1 without cancellation near 0: Taylor series to degree 19 for
    |x| < 0.5, e^x - 1 elsewhere (both computed, one selected per element)."""
    _vexp(x, tmp2, tmp, n)
    for j in range(n):
        v = x[j]
        p = C19 * v + C18
        p = p * v + C17
        p = p * v + C16
        p = p * v + C15
        p = p * v + C14
        p = p * v + C13
        p = p * v + C12
        p = p * v + C11
        p = p * v + C10
        p = p * v + C9
        p = p * v + C8
        p = p * v + C7
        p = p * v + C6
        p = p * v + C5
        p = p * v + C4
        p = p * v + C3
        p = p * v + C2
        p = p * v + C1
        p = p * v
        out[j] = p if -0.5 < v < 0.5 else tmp2[j] - 1.0


@njit(**_JIT)
def _vtanh(x, out, t1, t2, t3, t4, n):  # pragma: no cover - compiled
    """out[:n] = tanh x = -expm1(-2|x|) / (2 + expm1(-2|x|)) with the sign of x (|x| clamped at 20,
    where tanh is 1 in float64)."""
    for j in range(n):
        a = abs(x[j])
        t1[j] = -2.0 * (20.0 if a > 20.0 else a)
    _vexpm1(t1, t4, t2, t3, n)
    for j in range(n):
        e = t4[j]
        out[j] = math.copysign(-e / (2.0 + e), x[j])


@njit(**_JIT)
def _vmish(x, out, t1, t2, t3, n):  # pragma: no cover - compiled
    """out[:n] = Mish x = x tanh(softplus x) = x n / (n + 2), n = e^x (e^x + 2) (exact identity;
    the exponent is capped at 20, beyond which the factor is 1 in float64)."""
    for j in range(n):
        v = x[j]
        t1[j] = 20.0 if v > 20.0 else v
    _vexp(t1, t3, t2, n)
    for j in range(n):
        e = t3[j]
        m = e * (e + 2.0)
        out[j] = x[j] * m / (m + 2.0)


def _scalar(f: Any, x: float, n_tmp: int) -> float:
    a = np.array([float(x)])
    out = np.empty(1)
    f(a, out, *[np.empty(1) for _ in range(n_tmp)], 1)
    return float(out[0])


def exp_(x: float) -> float:
    """e^x on the fixed path (one value; see :func:`_vexp`)."""
    return _scalar(_vexp, x, 1)


def expm1_(x: float) -> float:
    """e^x - 1 on the fixed path (one value)."""
    return _scalar(_vexpm1, x, 2)


def tanh_(x: float) -> float:
    """tanh x on the fixed path (one value)."""
    return _scalar(_vtanh, x, 4)


def mish_(x: float) -> float:
    """Mish x on the fixed path (one value)."""
    return _scalar(_vmish, x, 3)


@njit(**_JIT)
def sincos_(x: float) -> tuple[float, float]:
    """(sin x, cos x) for moderate |x| (< 1e5): x = n pi/2 + r, Taylor series on |r| <= pi/4."""
    n = math.floor(x * _INV_PIO2 + 0.5)
    r = (x - n * _PIO2_HI) - n * _PIO2_LO
    r2 = r * r
    s = _SIN_COEF[11]
    c = _COS_COEF[11]
    for i in range(10, -1, -1):
        s = s * r2 + _SIN_COEF[i]
        c = c * r2 + _COS_COEF[i]
    s = s * r
    q = int(n) & 3
    if q == 0:
        return s, c
    if q == 1:
        return c, -s
    if q == 2:
        return -s, -c
    return -c, s


# ----------------------------------------------------------------------------------------------
# Row kernels on (N, J) float32 arrays


@njit(**_JIT)
def _linear(x, w, b, out):  # pragma: no cover - compiled
    """out[n, :] = x[n, :] @ w + b; w is (K, J) row-major.

    Every output is ``(((0 + x_0 w_0j) + x_1 w_1j) + ...) + x_{K-1} w_{K-1,j}``, then ``+ b_j``:
    one sequential float32 sum per output, in k order. The loops only decide how much work
    shares a pass over memory -- four rows and four k per pass over a row of outputs, with the
    j loop innermost, which LLVM vectorises across outputs -- never the order of a sum, so
    blocking, vector width and batch size change no bit."""
    N, K = x.shape
    J = w.shape[1]
    n = 0
    while n + 4 <= N:
        o0, o1, o2, o3 = out[n], out[n + 1], out[n + 2], out[n + 3]
        for j in range(J):
            o0[j] = 0.0
            o1[j] = 0.0
            o2[j] = 0.0
            o3[j] = 0.0
        k = 0
        while k + 4 <= K:
            w0, w1, w2, w3 = w[k], w[k + 1], w[k + 2], w[k + 3]
            a0, a1, a2, a3 = x[n, k], x[n, k + 1], x[n, k + 2], x[n, k + 3]
            b0, b1, b2, b3 = x[n + 1, k], x[n + 1, k + 1], x[n + 1, k + 2], x[n + 1, k + 3]
            c0, c1, c2, c3 = x[n + 2, k], x[n + 2, k + 1], x[n + 2, k + 2], x[n + 2, k + 3]
            d0, d1, d2, d3 = x[n + 3, k], x[n + 3, k + 1], x[n + 3, k + 2], x[n + 3, k + 3]
            for j in range(J):
                p, q, r, s = w0[j], w1[j], w2[j], w3[j]
                o0[j] = (((o0[j] + a0 * p) + a1 * q) + a2 * r) + a3 * s
                o1[j] = (((o1[j] + b0 * p) + b1 * q) + b2 * r) + b3 * s
                o2[j] = (((o2[j] + c0 * p) + c1 * q) + c2 * r) + c3 * s
                o3[j] = (((o3[j] + d0 * p) + d1 * q) + d2 * r) + d3 * s
            k += 4
        while k < K:
            wk = w[k]
            a0, b0, c0, d0 = x[n, k], x[n + 1, k], x[n + 2, k], x[n + 3, k]
            for j in range(J):
                p = wk[j]
                o0[j] += a0 * p
                o1[j] += b0 * p
                o2[j] += c0 * p
                o3[j] += d0 * p
            k += 1
        for j in range(J):
            o0[j] += b[j]
            o1[j] += b[j]
            o2[j] += b[j]
            o3[j] += b[j]
        n += 4
    while n < N:
        o = out[n]
        for j in range(J):
            o[j] = 0.0
        k = 0
        while k + 4 <= K:
            w0, w1, w2, w3 = w[k], w[k + 1], w[k + 2], w[k + 3]
            a0, a1, a2, a3 = x[n, k], x[n, k + 1], x[n, k + 2], x[n, k + 3]
            for j in range(J):
                o[j] = (((o[j] + a0 * w0[j]) + a1 * w1[j]) + a2 * w2[j]) + a3 * w3[j]
            k += 4
        while k < K:
            a0 = x[n, k]
            wk = w[k]
            for j in range(J):
                o[j] += a0 * wk[j]
            k += 1
        for j in range(J):
            o[j] += b[j]
        n += 1


@njit(**_JIT)
def _normalise(x, out):  # pragma: no cover - compiled
    """LayerNorm without affine: (x - mean) / sqrt(var + eps), each moment one sequential
    float64 sum over j."""
    N, J = x.shape
    for n in range(N):
        xn = x[n]
        s = 0.0
        for j in range(J):
            s += xn[j]
        mean = s / J
        v = 0.0
        for j in range(J):
            d = xn[j] - mean
            v += d * d
        inv = 1.0 / math.sqrt(v / J + LN_EPS)
        on = out[n]
        for j in range(J):
            on[j] = (xn[j] - mean) * inv


@njit(**_JIT)
def _affine(x, g, b):  # pragma: no cover - compiled
    """x <- x * g + b in place (float32, a product then a sum: no FMA)."""
    N, J = x.shape
    for n in range(N):
        for j in range(J):
            x[n, j] = x[n, j] * g[j] + b[j]


@njit(**_JIT)
def _mish_rows(x):  # pragma: no cover - compiled
    """Mish in place on a C-contiguous float32 array, as :func:`_vmish` (float64 inside, chunks
    of ``_CHUNK`` elements)."""
    flat = x.reshape(x.size)
    size = flat.shape[0]
    a = np.empty(_CHUNK)
    e = np.empty(_CHUNK)
    t = np.empty(_CHUNK)
    for s in range(0, size, _CHUNK):
        m = min(_CHUNK, size - s)
        for j in range(m):
            v = flat[s + j]
            a[j] = 20.0 if v > 20.0 else v
        _vexp(a, e, t, m)
        for j in range(m):
            ej = e[j]
            nj = ej * (ej + 2.0)
            flat[s + j] = flat[s + j] * nj / (nj + 2.0)


@njit(**_JIT)
def _tanh_rows(x):  # pragma: no cover - compiled
    """tanh in place on a C-contiguous float32 array (float64 inside, chunks of _CHUNK)."""
    flat = x.reshape(x.size)
    size = flat.shape[0]
    b = np.empty(_CHUNK)
    o = np.empty(_CHUNK)
    t = np.empty((4, _CHUNK))  # _vtanh's scratch
    for s in range(0, size, _CHUNK):
        m = min(_CHUNK, size - s)
        for j in range(m):
            b[j] = flat[s + j]
        _vtanh(b, o, t[0], t[1], t[2], t[3], m)
        for j in range(m):
            flat[s + j] = o[j]


@njit(**_JIT)
def _activate(x, kind):  # pragma: no cover - compiled
    """In place on a C-contiguous float32 array: 0 none, 1 ReLU, 2 tanh, 3 Mish.

    ``kind`` is a run-time value (an entry of an int64 array): a constant would make numba
    compile one more copy of this function per value."""
    if kind == 1:
        flat = x.reshape(x.size)
        for j in range(flat.shape[0]):
            v = flat[j]
            flat[j] = v if v > 0.0 else 0.0
    elif kind == 2:
        _tanh_rows(x)
    elif kind == 3:
        _mish_rows(x)


@njit(**_JIT)
def _mlp(x, ws, bs, acts):  # pragma: no cover - compiled
    """Linear layers (``ws[i]`` is (K, J)), each followed by activation ``acts[i]``."""
    h = x
    for i in range(len(ws)):
        w = ws[i]
        o = np.empty((h.shape[0], w.shape[1]), np.float32)
        _linear(h, w, bs[i], o)
        _activate(o, acts[i])
        h = o
    return h


@njit(inline="always", **_JIT)
def _row_max(v, mask, use_mask, n):  # pragma: no cover - compiled
    """Row ``n`` over its feasible entries (all if not ``use_mask``): ``(arg, best, nan)``, the
    first index of the largest value (that of the first NaN if any: a NaN counts as largest; 0
    for an all-masked row), the largest value that is not NaN (-inf if none) and whether a NaN
    is there. One scan in index order, comparisons only."""
    best = -math.inf
    arg = 0
    found = False
    nan = False
    for a in range(v.shape[1]):
        if use_mask and not mask[n, a]:
            continue
        x = v[n, a]
        if x != x:
            if not nan:
                arg = a
            nan = True
        elif not found or x > best:
            best = x
            if not nan:
                arg = a
            found = True
    return arg, best, nan


@njit(**_JIT)
def _argmax(v, mask, use_mask):  # pragma: no cover - compiled
    """First index of the largest value per row (over rows' feasible entries if ``use_mask``;
    a NaN counts as largest, an all-masked row gives 0: the semantics of torch.argmax after
    masked_fill(-inf))."""
    N = v.shape[0]
    out = np.zeros(N, np.int64)
    for n in range(N):
        out[n] = _row_max(v, mask, use_mask, n)[0]
    return out


@njit(**_JIT)
def _sample(v, mask, use_mask, u):  # pragma: no cover - compiled
    """Per row, the first index whose cumulative softmax weight exceeds ``u[n]`` times the
    total: a draw from the (masked) softmax of the row by its inverse CDF, weights
    e^(v - max) from :func:`_vexp`, summed in index order in float64. NaN logits and
    all-masked rows give :func:`_argmax`'s choice."""
    N, A = v.shape
    out = np.zeros(N, np.int64)
    z = np.empty(A)
    w = np.empty(A)
    tmp = np.empty(A)
    for n in range(N):
        arg, best, bad = _row_max(v, mask, use_mask, n)
        if bad or best == -math.inf:
            out[n] = arg
            continue
        for a in range(A):
            z[a] = np.float64(v[n, a]) - best
        _vexp(z, w, tmp, A)
        total = 0.0
        for a in range(A):
            if use_mask and not mask[n, a]:
                w[a] = 0.0
            total += w[a]
        target = u[n] * total
        acc = 0.0
        last = 0
        for a in range(A):
            if w[a] > 0.0:
                last = a
                acc += w[a]
                if acc > target:
                    break
        out[n] = last
    return out


# ----------------------------------------------------------------------------------------------
# Helpers (Python)


def _f32(a: Any) -> Array:
    return np.ascontiguousarray(a, dtype=np.float32)


def _t(w: Any) -> Array:
    """Torch ``Linear`` weight (out, in) -> (in, out), contiguous float32 (a transposition)."""
    return _f32(np.asarray(w, dtype=np.float32).T)


def linear(x: Any, w: Array, b: Array) -> Array:
    """``x @ w + b`` on the fixed path; ``w`` is (K, J) float32 (already transposed)."""
    x = _f32(np.atleast_2d(x))
    out = np.empty((x.shape[0], w.shape[1]), np.float32)
    _linear(x, w, b, out)
    return out


def fold_layernorm(g: Array, beta: Array, w: Array, b: Array) -> tuple[Array, Array]:
    """``LayerNorm(g, beta)`` then ``Linear(w (out, in), b)`` as ``normalise(x) @ W + B``:
    W = diag(g) w^T, B = b + beta @ w^T (on the fixed path)."""
    wt = _t(w)
    folded = _f32(wt * _f32(g)[:, None])  # exact-rounded products
    bias = linear(_f32(beta)[None, :], wt, _f32(b))[0]
    return folded, bias


def _mask_bool(mask: Any, n: int) -> NDArray[np.bool_]:
    m = np.asarray(mask)
    return np.ascontiguousarray(m.reshape(n, -1) != 0)


def masked_argmax(values: Array, mask: Any | None) -> NDArray[np.int64]:
    """(N, A) values -> (N,) argmax over the feasible entries (``mask`` nonzero), or over all
    entries if ``mask`` is None."""
    v = _f32(values)
    if mask is None:
        return _argmax(v, np.ones((1, 1), np.bool_), False)
    return _argmax(v, _mask_bool(mask, v.shape[0]), True)


def masked_sample(logits: Array, mask: Any | None, rng: np.random.Generator) -> NDArray[np.int64]:
    """(N, A) logits -> (N,) actions drawn from the softmax over the feasible entries (or all
    entries if ``mask`` is None), one ``rng.random()`` per row (PCG64: the same draws on every
    CPU) and the weights on the fixed path, so the same seed gives the same actions anywhere."""
    v = _f32(logits)
    u = rng.random(v.shape[0])
    if mask is None:
        return _sample(v, np.ones((1, 1), np.bool_), False, u)
    return _sample(v, _mask_bool(mask, v.shape[0]), True, u)


def _obs(observations: Any) -> Array:
    x = _f32(observations)
    return x.reshape(1, -1) if x.ndim == 1 else x


# ----------------------------------------------------------------------------------------------
# Multi-layer perceptrons: PPO / MaskablePPO, TD3, Safe-DQN-X


ACTIVATIONS = {"none": 0, "relu": 1, "tanh": 2, "mish": 3}


class MLP:
    """Linear layers with one activation between them (and optionally one after the last).

    ``layers``: [(weight (out, in), bias (out,)), ...] as stored by torch ``Linear``."""

    def __init__(
        self, layers: list[tuple[Array, Array]], activation: str, out_activation: str = "none"
    ):
        if not layers:
            raise ValueError("an MLP needs at least one layer")
        self.ws = tuple(_t(w) for w, _ in layers)
        self.bs = tuple(_f32(b) for _, b in layers)
        for (w, b), wt in zip(layers, self.ws, strict=True):
            if np.shape(b) != (wt.shape[1],):
                raise ValueError(f"bias of shape {np.shape(b)} for a weight of shape {w.shape}")
        self.acts = np.array(
            [ACTIVATIONS[activation]] * (len(self.ws) - 1) + [ACTIVATIONS[out_activation]],
            np.int64,
        )
        self.in_dim = self.ws[0].shape[0]
        out = self(np.zeros((1, self.in_dim), np.float32))  # compile / load the kernels now
        masked_argmax(out, None)
        masked_argmax(out, np.ones(out.shape, np.int8))

    @classmethod
    def from_state_dict(
        cls,
        sd: Mapping[str, Array],
        prefix: str,
        activation: str,
        out_activation: str = "none",
        weight: str = "weight",
        bias: str = "bias",
    ) -> MLP:
        """The ``Linear`` layers ``{prefix}{i}.{weight}`` of an ``nn.Sequential``, in index
        order (activations have no parameters)."""
        idx = sorted(
            {
                int(k[len(prefix) :].split(".")[0])
                for k in sd
                if k.startswith(prefix) and k.endswith("." + weight)
            }
        )
        if not idx:
            raise KeyError(f"no '{prefix}<i>.{weight}' entries in the state dict")
        layers = [(sd[f"{prefix}{i}.{weight}"], sd[f"{prefix}{i}.{bias}"]) for i in idx]
        return cls(layers, activation, out_activation)

    def __call__(self, observations: Any) -> Array:
        """(N, in) -> (N, out) float32; a ValueError for another input width (a checkpoint
        trained on other inputs, e.g. with ``--mvp-input``)."""
        x = _obs(observations)
        if x.shape[1] != self.in_dim:
            raise ValueError(f"this network takes {self.in_dim} inputs, got {x.shape[1]}")
        return _mlp(x, self.ws, self.bs, self.acts)


# ----------------------------------------------------------------------------------------------
# Rainbow-DQN: dueling C51 head, expected Q


@njit(**_JIT)
def _rainbow_q(x, tw, tb, ta, vw, vb, va, aw, ab, aa, support):  # pragma: no cover - compiled
    """Expected Q (N, A): dueling logits V + A - mean_a A per atom (float32, as the module),
    softmax over the K atoms (float64), expectation over the support."""
    h = _mlp(x, tw, tb, ta)
    v = _mlp(h, vw, vb, va)  # (N, K)
    a = _mlp(h, aw, ab, aa)  # (N, A * K), action-major
    N = x.shape[0]
    K = support.shape[0]
    A = a.shape[1] // K
    q = np.empty((N, A), np.float32)
    mean = np.empty(K, np.float32)
    z = np.empty(K * A)  # atom-major: z[k * A + i]
    ez = np.empty(K * A)
    tmp = np.empty(K * A)
    mx = np.empty(A)
    tot = np.empty(A)
    ev = np.empty(A)
    for n in range(N):
        for k in range(K):
            mean[k] = 0.0
        for i in range(A):  # each atom's sum over actions in action order
            for k in range(K):
                mean[k] += a[n, i * K + k]
        for k in range(K):
            mean[k] = mean[k] / np.float32(A)
        for i in range(A):
            for k in range(K):
                z[k * A + i] = (v[n, k] + a[n, i * K + k]) - mean[k]
        for i in range(A):
            mx[i] = -math.inf
            tot[i] = 0.0
            ev[i] = 0.0
        for k in range(K):
            for i in range(A):
                zv = z[k * A + i]
                mx[i] = zv if zv > mx[i] else mx[i]
        for k in range(K):
            for i in range(A):
                z[k * A + i] = z[k * A + i] - mx[i]
        _vexp(z, ez, tmp, K * A)
        for k in range(K):  # sums over atoms in atom order
            sk = support[k]
            for i in range(A):
                e = ez[k * A + i]
                tot[i] += e
                ev[i] += e * sk
        for i in range(A):
            q[n, i] = ev[i] / tot[i]
    return q


class RainbowQ:
    """Expected Q of :class:`cdr_bench.rl.rainbow.RainbowNet` with noise off (mean weights):
    torso (2 x Linear+ReLU), value and advantage streams (Linear+ReLU, Linear), dueling
    aggregation per atom, softmax over atoms, expectation over the support."""

    def __init__(self, sd: Mapping[str, Array], config: Mapping[str, Any]):
        self.torso = MLP.from_state_dict(sd, "torso.", "relu", "relu")
        self.value = MLP.from_state_dict(sd, "value.", "relu", weight="weight_mu", bias="bias_mu")
        self.adv = MLP.from_state_dict(sd, "advantage.", "relu", weight="weight_mu", bias="bias_mu")
        k = int(config["n_atoms"])
        # torch.linspace(v_min, v_max, k) in float32: start + i * step below the middle,
        # end - (k - 1 - i) * step above it (float32 arithmetic, as the module's buffer).
        lo, hi = np.float32(config["v_min"]), np.float32(config["v_max"])
        step = np.float32((hi - lo) / np.float32(k - 1)) if k > 1 else np.float32(0)
        i = np.arange(k)
        sup = np.where(
            i < k // 2, lo + i.astype(np.float32) * step, hi - (k - 1 - i).astype(np.float32) * step
        )
        self.support = _f32(sup).astype(np.float64)
        if self.value.ws[-1].shape[1] != k or self.adv.ws[-1].shape[1] != N_ACTIONS * k:
            raise ValueError("Rainbow state dict does not match n_atoms")
        self.q_values(np.zeros((1, self.torso.in_dim), np.float32))

    def q_values(self, observations: Any) -> Array:
        """(N, F) -> (N, 27) expected returns (float32)."""
        return _rainbow_q(
            _obs(observations),
            self.torso.ws,
            self.torso.bs,
            self.torso.acts,
            self.value.ws,
            self.value.bs,
            self.value.acts,
            self.adv.ws,
            self.adv.bs,
            self.adv.acts,
            self.support,
        )

    def act(self, observations: Any, masks: Any) -> NDArray[np.int64]:
        return masked_argmax(self.q_values(observations), masks)


# ----------------------------------------------------------------------------------------------
# Safe-DQN-X: two Q networks and a combination rule


class SafeDQNQ:
    """Q_S and Q_G of :class:`cdr_bench.rl.safe_dqn.SafeDQNNet` and its rule (``sum``: argmax
    of Q_S + Q_G; ``lexicographic``: the largest Q_G among feasible actions whose Q_S is within
    ``slack`` of the best; ``mvp-improve``: ``base``, mvp's action, unless some feasible action's
    Q_S exceeds Q_S(base) by more than ``slack``, then the largest Q_S + Q_G among those), over
    the feasible actions only."""

    def __init__(self, sd: Mapping[str, Array], config: Mapping[str, Any]):
        self.safety = MLP.from_state_dict(sd, "q_safety.", "relu")
        self.goal = MLP.from_state_dict(sd, "q_goal.", "relu")
        self.rule = str(config.get("rule", "sum"))
        self.slack = np.float32(config.get("slack", 0.1))
        if self.rule not in ("sum", "lexicographic", "mvp-improve"):
            raise ValueError(f"unknown combination rule {self.rule!r}")

    @classmethod
    def from_step(cls, step: Mapping[str, Any]) -> SafeDQNQ:
        """One improvement step as checkpoints store it: ``{"config", "state_dict"}``, the
        state dict's values torch tensors (as ``torch.load`` returns them) or arrays; the
        checkpoint's top level is its last step, its ``"base"`` list the earlier ones."""
        sd = {
            k: v.detach().cpu().numpy() if hasattr(v, "detach") else np.asarray(v)
            for k, v in step["state_dict"].items()
        }
        return cls(sd, step["config"])

    def act(self, observations: Any, masks: Any, base: Any | None = None) -> NDArray[np.int64]:
        qs, qg = self.safety(observations), self.goal(observations)
        if self.rule == "sum":
            return masked_argmax(qs + qg, masks)  # float32 sum (exact-rounded, elementwise)
        feasible = _mask_bool(masks, qs.shape[0])
        if self.rule == "mvp-improve":
            if base is None:
                raise ValueError("the mvp-improve rule needs mvp's actions (base)")
            b = np.asarray(base, np.int64)
            q_base = qs[np.arange(len(b)), b][:, None]
            better = feasible & (qs > q_base + self.slack)  # float32 add, exact compares
            best = masked_argmax(qs + qg, better)
            return np.where(better.any(axis=1), best, b)
        best = np.where(feasible, qs, np.float32(-np.inf)).max(axis=1, keepdims=True)
        safe = feasible & ~(qs < best - self.slack)  # max and compares are exact
        return masked_argmax(qg, safe)


def improved_actions(
    steps: list[SafeDQNQ], observations: Any, masks: Any, base: Any
) -> NDArray[np.int64]:
    """Iterated policy improvement (``mvp-improve`` rules, first step first): step k keeps the
    action of the policy before it unless its own networks find a better one, so the result of
    ``steps[:k]`` is the base of ``steps[k]``. ``base`` is the first base policy's action
    (``mvp``'s); no steps: ``base`` itself."""
    actions = np.asarray(base, np.int64)
    for step in steps:
        actions = step.act(observations, masks, base=actions)
    return actions


# ----------------------------------------------------------------------------------------------
# Diffusion-AC actor (and its categorical ablation)


def _cosine_betas(T: int) -> list[float]:
    """:func:`cdr_bench.rl.diffusion.make_betas` ("cosine") without libm."""
    s = 0.008
    f = []
    for t in range(T + 1):
        c = sincos_((t / T + s) / (1 + s) * (math.pi / 2))[1]
        f.append(c * c)
    return [min(1 - f[t] / f[t - 1], 0.999) for t in range(1, T + 1)]


def _linear_betas(T: int) -> list[float]:
    """``torch.linspace(1e-4, 2e-2, T, dtype=float64)`` (its symmetric formula)."""
    start, end = 1e-4, 2e-2
    if T == 1:
        return [start]
    step = (end - start) / (T - 1)
    half = T // 2
    return [start + i * step if i < half else end - (T - 1 - i) * step for i in range(T)]


def diffusion_schedule(kind: str, T: int) -> dict[str, Array]:
    """Float32 ``coef_y0``, ``coef_yt`` (Eq. 32) and ``sigma`` = sqrt(beta_tilde) (Eq. 29),
    index t = 0..T, as :class:`cdr_bench.rl.diffusion.Schedule` computes them (in float64, then
    rounded), from + - * / sqrt only."""
    if kind == "cosine":
        beta = _cosine_betas(T)
    elif kind == "linear":
        beta = _linear_betas(T)
    else:
        raise ValueError(f"unknown schedule {kind!r}")
    abar = [1.0]
    for b in beta:
        abar.append(abar[-1] * (1.0 - b))
    c0 = np.zeros(T + 1)
    ct = np.zeros(T + 1)
    bt = np.zeros(T + 1)
    for t in range(1, T + 1):
        b, prev, cur = beta[t - 1], abar[t - 1], abar[t]
        bt[t] = (1 - prev) / (1 - cur) * b
        c0[t] = math.sqrt(prev) * b / (1 - cur)
        ct[t] = math.sqrt(1.0 - b) * (1 - prev) / (1 - cur)
    return {
        "coef_y0": _f32(c0),
        "coef_yt": _f32(ct),
        "sigma": np.sqrt(_f32(bt)),  # float32 sqrt: correctly rounded
    }


def sinusoidal_embedding(t: Array, dim: int) -> Array:
    """(N,) steps -> (N, dim) float32 [sin, cos] embedding, with the float32 roundings of
    :func:`cdr_bench.rl.networks.sinusoidal_embedding` (and this module's exp/sin/cos)."""
    half = dim // 2
    i = np.arange(half, dtype=np.float32)
    v = (np.float32(-_LOG_10000) * i) / np.float32(half)  # float32 ops, as torch's
    freqs64 = v.astype(np.float64)
    freqs = np.empty(half)
    _vexp(freqs64, freqs, np.empty(half), half)
    freqs = _f32(freqs)
    ang = np.asarray(t, dtype=np.float32)[:, None] * freqs[None, :]
    sc = [[sincos_(float(a)) for a in row] for row in ang]
    sin = _f32([[p[0] for p in row] for row in sc])
    cos = _f32([[p[1] for p in row] for row in sc])
    return np.concatenate([sin, cos], axis=1)


@njit(**_JIT)
def _encode(obs, e1w, e1b, e1g, e1beta, e2w, e2b, e2g, e2beta):  # pragma: no cover - compiled
    """Enc(s): Linear, LayerNorm, Mish, Linear, LayerNorm, Mish."""
    N = obs.shape[0]
    W = e1w.shape[1]
    x = np.empty((N, W), np.float32)
    y = np.empty((N, W), np.float32)
    _linear(obs, e1w, e1b, x)
    _normalise(x, y)
    _affine(y, e1g, e1beta)
    _mish_rows(y)
    _linear(y, e2w, e2b, x)
    _normalise(x, y)
    _affine(y, e2g, e2beta)
    _mish_rows(y)
    return y


@njit(**_JIT)
def _residual_blocks(x, bw1, bb1, bw2, bb2):  # pragma: no cover - compiled
    """x <- x + Linear(Mish(Linear(LayerNorm x))) per block (LayerNorm affine folded in)."""
    N, W = x.shape
    nx = np.empty((N, W), np.float32)
    h = np.empty((N, bw1.shape[2]), np.float32)
    d = np.empty((N, W), np.float32)
    for i in range(bw1.shape[0]):
        _normalise(x, nx)
        _linear(nx, bw1[i], bb1[i], h)
        _mish_rows(h)
        _linear(h, bw2[i], bb2[i], d)
        for n in range(N):
            for j in range(W):
                x[n, j] = x[n, j] + d[n, j]


@njit(**_JIT)
def _head(x, hw, hb):  # pragma: no cover - compiled
    nx = np.empty(x.shape, np.float32)
    _normalise(x, nx)
    out = np.empty((x.shape[0], hw.shape[1]), np.float32)
    _linear(nx, hw, hb, out)
    return out


@njit(**_JIT)
def _categorical_logits(
    obs, e1w, e1b, e1g, e1beta, e2w, e2b, e2g, e2beta, bw1, bb1, bw2, bb2, hw, hb
):  # pragma: no cover - compiled
    x = _encode(obs, e1w, e1b, e1g, e1beta, e2w, e2b, e2g, e2beta)
    _residual_blocks(x, bw1, bb1, bw2, bb2)
    return _head(x, hw, hb)


@njit(**_JIT)
def _split_heads(qkv, n_heads):  # pragma: no cover - compiled
    """(N, 3W) q|k|v rows -> (N, 2, D, H) q and k with the head index last (a layout in which
    the per-head dot products vectorise across heads)."""
    N = qkv.shape[0]
    W = qkv.shape[1] // 3
    D = W // n_heads
    out = np.empty((N, 2, D, n_heads), np.float32)
    for n in range(N):
        for a in range(2):
            for hd in range(n_heads):
                for d in range(D):
                    out[n, a, d, hd] = qkv[n, a * W + hd * D + d]
    return out


@njit(**_JIT)
def _attention(h_qk, h_qkv, t_qkv, y_qkv, n_heads, o):  # pragma: no cover - compiled
    """Multi-head attention over the three tokens (state, step, noisy logits), its outputs
    summed over the three queries: o[n] = sum_j (sum_i softmax_j(q_i . k_j / sqrt D)) v_j per
    head, before the output projection. Dot products: float32 products summed over d in order
    in float64; softmax and weights in float64."""
    N = y_qkv.shape[0]
    W = y_qkv.shape[1] // 3
    H = n_heads
    D = W // H
    scale = 1.0 / math.sqrt(D)
    t_qk = _split_heads(t_qkv.reshape(1, 3 * W), H)[0]
    y_qk = np.empty((1, 2, D, H), np.float32)
    acc = np.empty(H)
    sc = np.empty(9 * H)  # [(i * 3 + j) * H + hd]
    ex = np.empty(9 * H)
    tmp = np.empty(9 * H)
    for n in range(N):
        for a in range(2):
            for hd in range(H):
                for d in range(D):
                    y_qk[0, a, d, hd] = y_qkv[n, a * W + hd * D + d]
        toks = (h_qk[n], t_qk, y_qk[0])
        for i in range(3):  # query token
            q = toks[i][0]
            for j in range(3):  # key token
                k = toks[j][1]
                for hd in range(H):
                    acc[hd] = 0.0
                for d in range(D):
                    for hd in range(H):
                        acc[hd] += q[d, hd] * k[d, hd]
                for hd in range(H):
                    sc[(i * 3 + j) * H + hd] = acc[hd] * scale
        for i in range(3):  # softmax over the keys: subtract each row's maximum
            for hd in range(H):
                r0 = (i * 3) * H + hd
                m = max(sc[r0], max(sc[r0 + H], sc[r0 + 2 * H]))
                sc[r0] -= m
                sc[r0 + H] -= m
                sc[r0 + 2 * H] -= m
        _vexp(sc, ex, tmp, 9 * H)
        for hd in range(H):
            p0 = 0.0
            p1 = 0.0
            p2 = 0.0
            for i in range(3):  # attention weights summed over the three queries
                r0 = (i * 3) * H + hd
                tot = (ex[r0] + ex[r0 + H]) + ex[r0 + 2 * H]
                p0 += ex[r0] / tot
                p1 += ex[r0 + H] / tot
                p2 += ex[r0 + 2 * H] / tot
            for d in range(D):
                c = 2 * W + hd * D + d
                o[n, hd * D + d] = (p0 * h_qkv[n, c] + p1 * t_qkv[c]) + p2 * y_qkv[n, c]


@njit(**_JIT)
def _diffusion_logits(
    obs,
    noise,
    e1w,
    e1b,
    e1g,
    e1beta,
    e2w,
    e2b,
    e2g,
    e2beta,
    y1w,
    y1b,
    y2w,
    y2b,
    qkv_w,
    qkv_b,
    out_w,
    out_b3,
    bw1,
    bb1,
    bw2,
    bb2,
    hw,
    hb,
    te,
    te_qkv,
    coef_y0,
    coef_yt,
    sigma,
    n_heads,
):  # pragma: no cover - compiled
    """y0 per state (N, 27): the reverse chain y_T = noise[0] -> y_0; the step-t noise z (t =
    T..2) is noise[T - t + 1]."""
    N = obs.shape[0]
    T = noise.shape[0]
    W = e1w.shape[1]
    h = _encode(obs, e1w, e1b, e1g, e1beta, e2w, e2b, e2g, e2beta)  # Enc(s), (N, W)
    nh = np.empty((N, W), np.float32)
    _normalise(h, nh)
    h_qkv = np.empty((N, 3 * W), np.float32)
    _linear(nh, qkv_w, qkv_b, h_qkv)
    y = noise[0].copy()
    y1 = np.empty((N, y1w.shape[1]), np.float32)
    ye = np.empty((N, W), np.float32)
    nye = np.empty((N, W), np.float32)
    y_qkv = np.empty((N, 3 * W), np.float32)
    o = np.empty((N, W), np.float32)
    attn = np.empty((N, W), np.float32)
    x = np.empty((N, W), np.float32)
    h_qk = _split_heads(h_qkv, n_heads)  # the state token's q and k, once per decision
    for t in range(T, 0, -1):
        _linear(y, y1w, y1b, y1)
        _mish_rows(y1)
        _linear(y1, y2w, y2b, ye)
        _normalise(ye, nye)
        _linear(nye, qkv_w, qkv_b, y_qkv)
        _attention(h_qk, h_qkv, te_qkv[t], y_qkv, n_heads, o)
        _linear(o, out_w, out_b3, attn)
        tet = te[t]
        for n in range(N):
            for j in range(W):
                x[n, j] = ((h[n, j] + tet[j]) + ye[n, j]) + attn[n, j]
        _residual_blocks(x, bw1, bb1, bw2, bb2)
        y0 = _head(x, hw, hb)
        if t == 1:
            return y0
        z = noise[T - t + 1]
        c0, ct, sg = coef_y0[t], coef_yt[t], sigma[t]
        for n in range(N):
            for a in range(y.shape[1]):
                y[n, a] = (c0 * y0[n, a] + ct * y[n, a]) + sg * z[n, a]
    return y  # T == 0 never happens (T >= 1)


class DiffusionActor:
    """The actor of a Diffusion-AC checkpoint (:class:`cdr_bench.rl.diffusion_ac.Policy`):
    ``diffusion`` -- y_T ~ N(0, I), T reverse steps of the denoiser, argmax of the masked clean
    logits (paper §4.2.2) -- or the ``categorical`` ablation (argmax of the masked logits).

    ``sd``: the checkpoint's ``state_dict`` as numpy arrays; ``config``: its ``config``."""

    def __init__(self, sd: Mapping[str, Array], config: Mapping[str, Any]):
        self.kind = str(config.get("actor", "diffusion"))
        if self.kind not in ("diffusion", "categorical"):
            raise ValueError(f"unknown actor {self.kind!r}")
        p = "net."
        self.enc = (
            _t(sd[p + "enc.net.0.weight"]),
            _f32(sd[p + "enc.net.0.bias"]),
            _f32(sd[p + "enc.net.1.weight"]),
            _f32(sd[p + "enc.net.1.bias"]),
            _t(sd[p + "enc.net.3.weight"]),
            _f32(sd[p + "enc.net.3.bias"]),
            _f32(sd[p + "enc.net.4.weight"]),
            _f32(sd[p + "enc.net.4.bias"]),
        )
        self.width = W = self.enc[0].shape[1]
        self.obs_dim = self.enc[0].shape[0]
        n_blocks = len({k.split(".")[2] for k in sd if k.startswith(p + "blocks.")})
        blocks = [
            fold_layernorm(
                sd[f"{p}blocks.{i}.net.0.weight"],
                sd[f"{p}blocks.{i}.net.0.bias"],
                sd[f"{p}blocks.{i}.net.1.weight"],
                sd[f"{p}blocks.{i}.net.1.bias"],
            )
            + (_t(sd[f"{p}blocks.{i}.net.3.weight"]), _f32(sd[f"{p}blocks.{i}.net.3.bias"]))
            for i in range(n_blocks)
        ]
        self.blocks = (
            _f32(np.stack([b[0] for b in blocks]).reshape(n_blocks, W, -1)),
            _f32(np.stack([b[1] for b in blocks]).reshape(n_blocks, -1)),
            _f32(np.stack([b[2] for b in blocks]).reshape(n_blocks, -1, W)),
            _f32(np.stack([b[3] for b in blocks]).reshape(n_blocks, W)),
        )
        self.head = fold_layernorm(
            sd[p + "head.0.weight"],
            sd[p + "head.0.bias"],
            sd[p + "head.1.weight"],
            sd[p + "head.1.bias"],
        )
        if self.kind == "categorical":
            self.act(np.zeros((1, self.obs_dim), np.float32), np.ones((1, N_ACTIONS), np.int8))
            return
        self.T = T = int(config.get("T", 10))
        self.n_heads = H = int(config.get("n_heads", 8))
        if W % H:
            raise ValueError(f"width {W} is not a multiple of n_heads {H}")
        sch = diffusion_schedule(str(config.get("schedule", "cosine")), T)
        self.coef_y0, self.coef_yt, self.sigma = sch["coef_y0"], sch["coef_yt"], sch["sigma"]
        self.y_mlp = (
            _t(sd[p + "y_mlp.0.weight"]),
            _f32(sd[p + "y_mlp.0.bias"]),
            _t(sd[p + "y_mlp.2.weight"]),
            _f32(sd[p + "y_mlp.2.bias"]),
        )
        self.qkv = fold_layernorm(
            sd[p + "attn_norm.weight"],
            sd[p + "attn_norm.bias"],
            sd[p + "attn.in_proj_weight"],
            sd[p + "attn.in_proj_bias"],
        )
        out_b = _f32(sd[p + "attn.out_proj.bias"])
        self.out = (_t(sd[p + "attn.out_proj.weight"]), _f32(out_b + out_b + out_b))
        # step-token table, row t = 1..T (row 0 unused): t_mlp(embedding(t)) and its q/k/v
        t_mlp = MLP.from_state_dict(sd, p + "t_mlp.", "mish")
        self.te = t_mlp(sinusoidal_embedding(np.arange(T + 1), W))
        nte = np.empty_like(self.te)
        _normalise(self.te, nte)
        self.te_qkv = linear(nte, *self.qkv)
        self.act(
            np.zeros((1, self.obs_dim), np.float32),
            np.ones((1, N_ACTIONS), np.int8),
            np.random.default_rng(0),
        )

    def clean_logits(self, observations: Any, noise: Array | None = None) -> Array:
        """y0 per state, (N, 27) float32. ``noise``: (T, N, 27) float32, y_T then the z of steps
        t = T..2 (the diffusion actor only; the categorical actor ignores it)."""
        obs = _obs(observations)
        if self.kind == "categorical":
            return _categorical_logits(obs, *self.enc, *self.blocks, *self.head)
        if noise is None:
            raise ValueError("the diffusion actor needs noise (T, N, 27)")
        noise = _f32(noise)
        if noise.shape != (self.T, obs.shape[0], N_ACTIONS):
            raise ValueError(f"noise of shape {noise.shape}, expected {(self.T, obs.shape[0])}")
        return _diffusion_logits(
            obs,
            noise,
            *self.enc,
            *self.y_mlp,
            *self.qkv,
            *self.out,
            *self.blocks,
            *self.head,
            self.te,
            self.te_qkv,
            self.coef_y0,
            self.coef_yt,
            self.sigma,
            self.n_heads,
        )

    def logits(self, observations: Any, rng: np.random.Generator | None = None) -> Array:
        """Clean logits; the diffusion actor draws its noise from ``rng`` (float32 standard
        normals, all T x N x 27 in one call: y_T first, then the steps' z)."""
        obs = _obs(observations)
        if self.kind == "categorical":
            return self.clean_logits(obs)
        if rng is None:
            raise ValueError("the diffusion actor needs a numpy Generator")
        noise = rng.standard_normal((self.T, obs.shape[0], N_ACTIONS), dtype=np.float32)
        return self.clean_logits(obs, noise)

    def act(
        self, observations: Any, masks: Any, rng: np.random.Generator | None = None
    ) -> NDArray[np.int64]:
        """Argmax of the masked clean logits (the paper's inference), (N,) int64."""
        return masked_argmax(self.logits(observations, rng), masks)


def new_generator(seed: int | None) -> np.random.Generator:
    """The agents' random stream: ``Generator(PCG64(seed))`` (seed None -> 0)."""
    return np.random.Generator(np.random.PCG64(0 if seed is None else int(seed)))


class CheckpointActorAgent:
    """The agent protocol for a weights-only actor checkpoint of the trainers' layout
    (``{"config": {...}, "state_dict": ...}``, read by :func:`cdr_bench.weights.load_weights`;
    Linear+Tanh layers, Linear -> 27 logits): the argmax of the masked logits on this module's
    fixed numeric path, for every aircraft on its own observation. An agent file subclasses it
    with ``algorithm`` (the ``config["algorithm"]`` it accepts) and ``default_checkpoint`` (the
    file beside it, used when neither ``checkpoint`` nor ``CDR_BENCH_CHECKPOINT`` is given);
    where it needs more, it overrides :meth:`refuse` (which checkpoints it takes),
    :meth:`features` (what the network sees) and ``missing`` (what to say when there is no
    checkpoint)."""

    algorithm: str = ""
    default_checkpoint: str = ""
    missing: str = ""
    """Said after "no checkpoint at PATH" when the file does not exist (empty: that alone)."""

    def __init__(self, observation_space: Any = None, action_space: Any = None,
                 checkpoint: str | None = None) -> None:  # fmt: skip
        import os

        from cdr_bench.weights import load_weights

        self.checkpoint = (
            checkpoint or os.environ.get("CDR_BENCH_CHECKPOINT") or str(self.default_checkpoint)
        )
        if self.missing and not os.path.isfile(self.checkpoint):
            raise FileNotFoundError(f"no checkpoint at {self.checkpoint}: {self.missing}")
        ck = load_weights(self.checkpoint)
        reason = self.refuse(ck["config"])
        if reason is not None:
            raise ValueError(f"{self.checkpoint}: {reason}")
        self.net = MLP.from_state_dict(dict(ck["state_dict"]), "", "tanh")

    def refuse(self, config: Mapping[str, Any]) -> str | None:
        """Why this checkpoint's ``config`` is not one this agent runs (None: it is)."""
        if config.get("algorithm") != self.algorithm:
            return f"not a {self.algorithm} actor (algorithm {config.get('algorithm')!r})"
        return None

    def features(self, observations: Any, masks: Any) -> Any:
        """The network's input for these observations and masks (the observations)."""
        return observations

    def reset(self, seed: int | None = None) -> None:
        """Deterministic policy: nothing to re-seed."""

    def act_batch(self, observations: Any, masks: Any) -> NDArray[np.int64]:
        return masked_argmax(self.net(self.features(observations, masks)), masks)

    def act(self, obs_dict: dict[str, Any]) -> int:
        return int(self.act_batch(obs_dict["observation"][None], obs_dict["action_mask"][None])[0])
