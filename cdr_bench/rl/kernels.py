"""Compiled (numba) kernels of the trainers, where PyTorch's or numpy's small operations cost more
than the arithmetic: mish, the denoiser's three-token attention, Rainbow's noisy dueling head for
the taken actions (forward and backward), the prioritised replay's sum tree and the n-step
queues. Sequential loops in a fixed order: the same inputs give the same
outputs bit for bit (on the same machine).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

# --- mish --------------------------------------------------------------------------------
#
# mish(x) = x tanh(softplus(x)) = x n / (n + 2) with n = e^x (e^x + 2), in one pass, and its
# derivative tanh(sp) + x sigmoid(x) (1 - tanh(sp)^2) = tt + 4 x e (e + 1) / (n + 2)^2. e^x is
# Cephes' expf (a polynomial after reduction by ln 2, about 1 ulp), written so that the loop
# vectorises; x is clamped to [-87, 20] for it (where tanh(softplus(x)) is 0 or 1 in float32).

_LOG2E = np.float32(1.4426950408889634)
_LN2_HI = np.float32(0.693359375)
_LN2_LO = np.float32(-2.12194440e-4)
_EXP_P = (
    np.float32(1.9875691500e-4),
    np.float32(1.3981999507e-3),
    np.float32(8.3334519073e-3),
    np.float32(4.1665795894e-2),
    np.float32(1.6666665459e-1),
    np.float32(5.0000001201e-1),
)


@njit(cache=True, fastmath={"contract"}, error_model="numpy")
def _exp_parts(x: NDArray[np.float32], mant: NDArray[np.float32], bits: NDArray[np.int32]) -> None:
    """e^x = mant * (the float32 whose bits are ``bits``) = p(r) 2^k, x clamped to [-87, 20]."""
    p0, p1, p2, p3, p4, p5 = _EXP_P
    for i in range(x.size):
        v = min(max(x[i], np.float32(-87.0)), np.float32(20.0))
        k = np.floor(v * _LOG2E + np.float32(0.5))
        r = v - k * _LN2_HI - k * _LN2_LO
        p = ((((p0 * r + p1) * r + p2) * r + p3) * r + p4) * r + p5
        mant[i] = p * r * r + r + np.float32(1.0)
        bits[i] = (np.int32(k) + np.int32(127)) << np.int32(23)


@njit(cache=True, fastmath={"contract"}, error_model="numpy")
def mish_forward(x: NDArray[np.float32], y: NDArray[np.float32]) -> None:
    """y = mish(x) (1-D arrays)."""
    bits = np.empty(x.size, np.int32)
    _exp_parts(x, y, bits)
    scale = bits.view(np.float32)
    for i in range(x.size):
        e = y[i] * scale[i]
        s = (e + np.float32(1.0)) * (e + np.float32(1.0))
        y[i] = x[i] * ((s - np.float32(1.0)) / (s + np.float32(1.0)))


@njit(cache=True, fastmath={"contract"}, error_model="numpy")
def mish_forward_derivative(
    x: NDArray[np.float32], y: NDArray[np.float32], d: NDArray[np.float32]
) -> None:
    """y = mish(x) and d = mish'(x) (1-D arrays)."""
    bits = np.empty(x.size, np.int32)
    _exp_parts(x, y, bits)
    scale = bits.view(np.float32)
    for i in range(x.size):
        v = x[i]
        e = y[i] * scale[i]
        e1 = e + np.float32(1.0)
        s = e1 * e1
        m = s + np.float32(1.0)
        tt = (s - np.float32(1.0)) / m
        y[i] = v * tt
        d[i] = tt + np.float32(4.0) * v * e * e1 / (m * m)


# --- three-token attention, summed over the queries ------------------------------------------
#
# Tokens i = 0 (state), 1 (step), 2 (noisy logits), each row of its table holding the attention's
# input projection [q | k | v] (3W). Per head (width d = W / heads) the scores are
# s_ij = (q_i . k_j) / sqrt(d), a_ij = softmax_j s_ij, and the output is the sum over the queries
# of the attention outputs: out = sum_i sum_j a_ij v_j = sum_j c_j v_j with c_j = sum_i a_ij.

Tokens = tuple[
    NDArray[np.float32],
    NDArray[np.int64],
    NDArray[np.float32],
    NDArray[np.int64],
    NDArray[np.float32],
]
"""The three tokens' [q | k | v] tables and the rows taken from them: ``(qkv0, idx0, qkv1, idx1,
qkv2)``. Row n of the output takes token 0 from row ``idx0[n]`` of qkv0, token 1 from row
``idx1[n]`` of qkv1, token 2 from row n of qkv2 (float32 tables, int64 indices)."""


@njit(cache=True, inline="always")
def _attention_sizes(tokens: Tokens, heads: int) -> tuple[int, int, int, np.float32]:
    """The output's rows N and width W, the head width d and the scores' scale 1 / sqrt(d)."""
    qkv2 = tokens[4]
    w = qkv2.shape[1] // 3
    d = w // heads
    return qkv2.shape[0], w, d, np.float32(1.0 / np.sqrt(d))


@njit(cache=True, inline="always")
def _token_rows(
    tokens: Tokens, n: int
) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32]]:
    """The rows of the three tables that row ``n`` of the output takes its tokens from."""
    qkv0, idx0, qkv1, idx1, qkv2 = tokens
    return qkv0[idx0[n]], qkv1[idx1[n]], qkv2[n]


@njit(cache=True)
def attention_forward(
    tokens: Tokens, heads: int, out: NDArray[np.float32], attn: NDArray[np.float32]
) -> None:
    """``out`` (N, W) and the attention weights ``attn`` (N, heads, 3, 3) (kept for the
    backward pass)."""
    n_rows, w, d, scale = _attention_sizes(tokens, heads)
    s = np.empty((3, 3), np.float32)
    for n in range(n_rows):
        r0, r1, r2 = _token_rows(tokens, n)
        for hd in range(heads):
            o = hd * d
            ko, vo = w + o, 2 * w + o
            s00 = s01 = s02 = s10 = s11 = s12 = s20 = s21 = s22 = np.float32(0.0)
            for e in range(d):
                q0, q1, q2 = r0[o + e], r1[o + e], r2[o + e]
                k0, k1, k2 = r0[ko + e], r1[ko + e], r2[ko + e]
                s00 += q0 * k0
                s01 += q0 * k1
                s02 += q0 * k2
                s10 += q1 * k0
                s11 += q1 * k1
                s12 += q1 * k2
                s20 += q2 * k0
                s21 += q2 * k1
                s22 += q2 * k2
            s[0, 0], s[0, 1], s[0, 2] = s00 * scale, s01 * scale, s02 * scale
            s[1, 0], s[1, 1], s[1, 2] = s10 * scale, s11 * scale, s12 * scale
            s[2, 0], s[2, 1], s[2, 2] = s20 * scale, s21 * scale, s22 * scale
            c0 = c1 = c2 = np.float32(0.0)
            for i in range(3):
                m = max(s[i, 0], max(s[i, 1], s[i, 2]))
                e0 = np.exp(s[i, 0] - m)
                e1 = np.exp(s[i, 1] - m)
                e2 = np.exp(s[i, 2] - m)
                z = e0 + e1 + e2
                a0, a1, a2 = e0 / z, e1 / z, e2 / z
                attn[n, hd, i, 0], attn[n, hd, i, 1], attn[n, hd, i, 2] = a0, a1, a2
                c0 += a0
                c1 += a1
                c2 += a2
            for e in range(d):
                out[n, o + e] = c0 * r0[vo + e] + c1 * r1[vo + e] + c2 * r2[vo + e]


@njit(cache=True)
def attention_backward(
    tokens: Tokens,
    heads: int,
    attn: NDArray[np.float32],
    grad_out: NDArray[np.float32],
    grads: tuple[NDArray[np.float32], ...],
) -> None:
    """Adds the gradients of the three tables, ``grads`` = those of (qkv0, qkv1, qkv2) (zeroed
    by the caller; rows shared by several outputs accumulate in row order)."""
    n_rows, w, d, scale = _attention_sizes(tokens, heads)
    grad_tokens = (grads[0], tokens[1], grads[1], tokens[3], grads[2])
    ds = np.empty((3, 3), np.float32)
    for n in range(n_rows):
        r0, r1, r2 = _token_rows(tokens, n)
        g0, g1, g2 = _token_rows(grad_tokens, n)
        for hd in range(heads):
            o = hd * d
            ko, vo = w + o, 2 * w + o
            c0 = attn[n, hd, 0, 0] + attn[n, hd, 1, 0] + attn[n, hd, 2, 0]
            c1 = attn[n, hd, 0, 1] + attn[n, hd, 1, 1] + attn[n, hd, 2, 1]
            c2 = attn[n, hd, 0, 2] + attn[n, hd, 1, 2] + attn[n, hd, 2, 2]
            # out = sum_j c_j v_j: dv_j = c_j g, dc_j = g . v_j
            dc0 = dc1 = dc2 = np.float32(0.0)
            for e in range(d):
                g = grad_out[n, o + e]
                dc0 += g * r0[vo + e]
                dc1 += g * r1[vo + e]
                dc2 += g * r2[vo + e]
                g0[vo + e] += c0 * g
                g1[vo + e] += c1 * g
                g2[vo + e] += c2 * g
            # c_j = sum_i a_ij, softmax over j: ds_ij = a_ij (dc_j - sum_j' a_ij' dc_j') / sqrt(d)
            for i in range(3):
                a0, a1, a2 = attn[n, hd, i, 0], attn[n, hd, i, 1], attn[n, hd, i, 2]
                dot = a0 * dc0 + a1 * dc1 + a2 * dc2
                ds[i, 0] = a0 * (dc0 - dot) * scale
                ds[i, 1] = a1 * (dc1 - dot) * scale
                ds[i, 2] = a2 * (dc2 - dot) * scale
            # s_ij = q_i . k_j: dq_i = sum_j ds_ij k_j, dk_j = sum_i ds_ij q_i
            for e in range(d):
                q0, q1, q2 = r0[o + e], r1[o + e], r2[o + e]
                k0, k1, k2 = r0[ko + e], r1[ko + e], r2[ko + e]
                g0[o + e] += ds[0, 0] * k0 + ds[0, 1] * k1 + ds[0, 2] * k2
                g1[o + e] += ds[1, 0] * k0 + ds[1, 1] * k1 + ds[1, 2] * k2
                g2[o + e] += ds[2, 0] * k0 + ds[2, 1] * k1 + ds[2, 2] * k2
                g0[ko + e] += ds[0, 0] * q0 + ds[1, 0] * q1 + ds[2, 0] * q2
                g1[ko + e] += ds[0, 1] * q0 + ds[1, 1] * q1 + ds[2, 1] * q2
                g2[ko + e] += ds[0, 2] * q0 + ds[1, 2] * q1 + ds[2, 2] * q2


# --- the prioritised replay's sum tree --------------------------------------------------------
#
# Node i has children 2i and 2i + 1; leaf j is node n_leaves + j. The same arithmetic as the
# level-by-level numpy version it replaces (every sum is recomputed from its two children, a
# repeated leaf keeps its last value), so the same tree and the same draws bit for bit.


@njit(cache=True)
def sum_tree_update(
    tree: NDArray[np.float64], n_leaves: int, idx: NDArray[np.int64], value: NDArray[np.float64]
) -> None:
    """Leaves ``idx`` <- ``value``, then the sums above them level by level (the reads of one
    level overlap; a parent shared by several leaves is recomputed from final children)."""
    node = np.empty(len(idx), np.int64)
    for i in range(len(idx)):
        node[i] = idx[i] + n_leaves
        tree[node[i]] = value[i]
    level = n_leaves
    while level > 1:
        for i in range(len(idx)):
            parent = node[i] // 2
            node[i] = parent
            tree[parent] = tree[2 * parent] + tree[2 * parent + 1]
        level //= 2


@njit(cache=True)
def sum_tree_find(
    tree: NDArray[np.float64], n_leaves: int, prefix: NDArray[np.float64], out: NDArray[np.int64]
) -> None:
    """Leaf j with cumsum(leaves)[j-1] <= prefix < cumsum(leaves)[j], per prefix. Level by
    level for all prefixes (their memory reads overlap)."""
    u = prefix.copy()
    node = np.ones(len(prefix), np.int64)
    level = 1
    while level < n_leaves:
        for i in range(len(prefix)):
            left = 2 * node[i]
            if u[i] >= tree[left]:
                u[i] = u[i] - tree[left]
                node[i] = left + 1
            else:
                node[i] = left
        level *= 2
    for i in range(len(prefix)):
        out[i] = node[i] - n_leaves


# --- n-step returns ---------------------------------------------------------------------------


@njit(cache=True)
def n_step_push(
    slots: NDArray[np.int64],
    obs: NDArray[np.float32],
    mask: NDArray[np.int8],
    action: NDArray[np.int64],
    rewards: NDArray[np.float32],
    ended: NDArray[np.bool_],
    q_obs: NDArray[np.float32],
    q_mask: NDArray[np.int8],
    q_action: NDArray[np.int64],
    q_rewards: NDArray[np.float32],
    q_start: NDArray[np.int64],
    q_len: NDArray[np.int64],
    gamma_pow: NDArray[np.float32],
    out_src: NDArray[np.int64],
    out_row: NDArray[np.int64],
    out_obs: NDArray[np.float32],
    out_mask: NDArray[np.int8],
    out_action: NDArray[np.int64],
    out_rewards: NDArray[np.float32],
    out_discount: NDArray[np.float32],
) -> int:
    """One step of the aircraft in ``slots`` (row i is slot ``slots[i]``) into per-slot queues
    of length n (ring buffers: ``q_start``, ``q_len``); returns how many n-step transitions
    completed, in order, with the row ``out_row`` whose next state closes each. The returns sum
    the rewards as float32 from the oldest: R = sum_k float32(gamma^k) r_k."""
    n = q_obs.shape[1]
    m = 0
    for i in range(len(slots)):
        s = slots[i]
        tail = (q_start[s] + q_len[s]) % n
        q_obs[s, tail] = obs[i]
        q_mask[s, tail] = mask[i]
        q_action[s, tail] = action[i]
        q_rewards[s, tail] = rewards[i]
        q_len[s] += 1
        emit = 1 if q_len[s] == n else 0
        if ended[i]:
            emit = q_len[s]
        for _ in range(emit):
            length = q_len[s]
            head = q_start[s]
            out_src[m] = s * n + head
            out_row[m] = i
            out_obs[m] = q_obs[s, head]
            out_mask[m] = q_mask[s, head]
            out_action[m] = q_action[s, head]
            for j in range(rewards.shape[1]):
                acc = np.float32(0.0)
                for k in range(length):
                    acc += gamma_pow[k] * q_rewards[s, (head + k) % n, j]
                out_rewards[m, j] = acc
            out_discount[m] = gamma_pow[length]
            q_start[s] = (head + 1) % n
            q_len[s] = length - 1
            m += 1
        if q_len[s] == 0:
            q_start[s] = 0
    return m


# --- Rainbow's noisy dueling head for one action per sample -----------------------------------
#
# The advantage stream's noisy output layer: W = mu + sigma * (eps_out eps_in^T), b = mu_b +
# sigma_b * eps_out, 27 blocks of K rows (one per action). The loss needs, per sample, the K
# logits of one action minus the mean over actions: d[n] = (W h_n + b)[block a_n] -
# mean_a (W h_n + b)[block a], and for a linear layer the mean over actions is the layer with
# the mean weights. Computed without forming W; the backward pass writes the gradients of mu,
# sigma (dense: the mean reaches every block) and h.


@njit(cache=True)
def _groups(actions: NDArray[np.int64], n_act: int) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The samples ordered by action (stable) and where each action's group starts."""
    start = np.zeros(n_act + 1, np.int64)
    for n in range(len(actions)):
        start[actions[n] + 1] += 1
    for a in range(n_act):
        start[a + 1] += start[a]
    fill = start[:-1].copy()
    order = np.empty(len(actions), np.int64)
    for n in range(len(actions)):
        order[fill[actions[n]]] = n
        fill[actions[n]] += 1
    return order, start


NoisyLayer = tuple[NDArray[np.float32], ...]
"""A noisy linear layer with O outputs and I inputs and its noise sample: ``(mu, sigma, mu_b,
sigma_b, eps_in, eps_out)``, mu and sigma (O, I), mu_b, sigma_b and eps_out (O,), eps_in (I,)."""


@njit(cache=True, fastmath={"reassoc", "contract"}, inline="always")
def _centred_row(
    layer: NoisyLayer, w_mean: NDArray[np.float32], o: int, j: int, row: NDArray[np.float32]
) -> None:
    """``row`` = row ``o`` of the noisy weights minus the mean row ``j`` over actions."""
    mu, sigma, _, _, eps_in, eps_out = layer
    eo = eps_out[o]
    m, sg, wm = mu[o], sigma[o], w_mean[j]
    for i in range(row.shape[0]):
        row[i] = m[i] + sg[i] * (eo * eps_in[i]) - wm[i]


@njit(cache=True, fastmath={"reassoc", "contract"})
def noisy_head_forward(
    h: NDArray[np.float32],
    layer: NoisyLayer,
    actions: NDArray[np.int64],
    k: int,
    out: NDArray[np.float32],
    w_mean: NDArray[np.float32],
    b_mean: NDArray[np.float32],
) -> None:
    """``out`` (N, K) = taken-action logits minus the mean over actions; ``w_mean`` (K, I),
    ``b_mean`` (K,) are written (kept for the backward pass). Samples grouped by action: each
    row of W is formed once."""
    mu, sigma, mu_b, sigma_b, eps_in, eps_out = layer
    width = h.shape[1]
    n_act = mu.shape[0] // k
    inv = np.float32(1.0 / n_act)
    w_mean[:] = 0.0
    b_mean[:] = 0.0
    for o in range(mu.shape[0]):
        j = o % k
        eo = eps_out[o]
        m, sg, wm = mu[o], sigma[o], w_mean[j]
        for i in range(width):
            wm[i] += m[i] + sg[i] * (eo * eps_in[i])
        b_mean[j] += mu_b[o] + sigma_b[o] * eo
    for j in range(k):
        for i in range(width):
            w_mean[j, i] *= inv
        b_mean[j] *= inv
    order, start = _groups(actions, n_act)
    row = np.empty(width, np.float32)
    for a in range(n_act):
        if start[a] == start[a + 1]:
            continue
        for j in range(k):
            o = a * k + j
            _centred_row(layer, w_mean, o, j, row)
            bias = mu_b[o] + sigma_b[o] * eps_out[o] - b_mean[j]
            for p in range(start[a], start[a + 1]):
                n = order[p]
                hn = h[n]
                acc = np.float32(0.0)
                for i in range(width):
                    acc += row[i] * hn[i]
                out[n, j] = acc + bias


@njit(cache=True, fastmath={"reassoc", "contract"})
def noisy_head_backward(
    h: NDArray[np.float32],
    layer: NoisyLayer,
    actions: NDArray[np.int64],
    k: int,
    w_mean: NDArray[np.float32],
    grad_out: NDArray[np.float32],
    grads: tuple[NDArray[np.float32], ...],
) -> None:
    """Writes every gradient, ``grads`` = those of (h, mu, sigma, mu_b, sigma_b) (no zeroing
    needed); each row of the weights' gradients once."""
    mu, _, _, _, eps_in, eps_out = layer
    grad_h, grad_mu, grad_sigma, grad_mu_b, grad_sigma_b = grads
    n_rows, width = h.shape
    n_act = mu.shape[0] // k
    inv = np.float32(1.0 / n_act)
    # the mean over actions: every block gets -1/27 sum_n g_n h_n^T
    g_mean = np.zeros((k, width), np.float32)
    gb_mean = np.zeros(k, np.float32)
    for n in range(n_rows):
        hn = h[n]
        for j in range(k):
            g = grad_out[n, j]
            gb_mean[j] += g
            gm = g_mean[j]
            for i in range(width):
                gm[i] += g * hn[i]
    grad_h[:] = 0.0
    order, start = _groups(actions, n_act)
    row = np.empty(width, np.float32)
    wrow = np.empty(width, np.float32)
    for a in range(n_act):
        for j in range(k):
            o = a * k + j
            eo = eps_out[o]
            gm = g_mean[j]
            for i in range(width):
                row[i] = -inv * gm[i]
            gb = -inv * gb_mean[j]
            if start[a] < start[a + 1]:
                _centred_row(layer, w_mean, o, j, wrow)
                for p in range(start[a], start[a + 1]):
                    n = order[p]
                    g = grad_out[n, j]
                    gb += g
                    hn, gh = h[n], grad_h[n]
                    for i in range(width):
                        row[i] += g * hn[i]
                        gh[i] += g * wrow[i]
            dmu, dsg = grad_mu[o], grad_sigma[o]
            for i in range(width):
                dmu[i] = row[i]
                dsg[i] = row[i] * (eo * eps_in[i])
            grad_mu_b[o] = gb
            grad_sigma_b[o] = gb * eo


@njit(cache=True, fastmath={"contract"})
def noisy_weight(layer: NoisyLayer, out: NDArray[np.float32]) -> None:
    """out = mu + sigma * (eps_out eps_in^T), in one pass."""
    mu, sigma, _, _, eps_in, eps_out = layer
    for o in range(mu.shape[0]):
        eo = eps_out[o]
        m, s, w = mu[o], sigma[o], out[o]
        for i in range(mu.shape[1]):
            w[i] = m[i] + s[i] * (eo * eps_in[i])


@njit(cache=True, fastmath={"contract", "reassoc", "nsz"}, error_model="numpy")
def dueling_expected_q(
    adv: NDArray[np.float32],
    bias: NDArray[np.float32],
    value: NDArray[np.float32],
    support: NDArray[np.float32],
    out: NDArray[np.float32],
) -> None:
    """``out`` (N, A): the expected return sum_z softmax_z(V_z + A_az - mean_a' A_a'z) z of the
    dueling C51 head, from the advantage logits without their bias ``adv`` (N, A K) + ``bias``
    (A K) and the value logits (N, K), in one pass (exp as in :func:`_exp_parts`)."""
    n_rows = adv.shape[0]
    k = value.shape[1]
    n_act = adv.shape[1] // k
    inv = np.float32(1.0 / n_act)
    shift = np.empty(k, np.float32)
    logits = np.empty(n_act * k, np.float32)
    mant = np.empty(n_act * k, np.float32)
    bits = np.empty(n_act * k, np.int32)
    scale = bits.view(np.float32)
    for n in range(n_rows):
        row = adv[n]
        for i in range(n_act * k):
            logits[i] = row[i] + bias[i]
        shift[:] = 0.0
        for a in range(n_act):
            for j in range(k):
                shift[j] += logits[a * k + j]
        for j in range(k):
            shift[j] = value[n, j] - inv * shift[j]
        for a in range(n_act):
            m = logits[a * k] + shift[0]
            for j in range(k):
                x = logits[a * k + j] + shift[j]
                logits[a * k + j] = x
                m = max(m, x)
            for j in range(k):
                logits[a * k + j] -= m
        _exp_parts(logits, mant, bits)
        for a in range(n_act):
            num = np.float32(0.0)
            den = np.float32(0.0)
            for j in range(k):
                e = mant[a * k + j] * scale[a * k + j]
                num += e * support[j]
                den += e
            out[n, a] = num / den


@njit(cache=True)
def c51_projection(
    probs: NDArray[np.float32],
    reward: NDArray[np.float32],
    discount: NDArray[np.float32],
    support: NDArray[np.float32],
    out: NDArray[np.float32],
) -> None:
    """C51 projection of r + discount Z onto ``support`` (evenly spaced), per row: each
    shifted atom's mass split between the two atoms around it (all on one when it lands on
    one), in float32 as the tensor version (:func:`cdr_bench.rl.rainbow.project_distribution`)."""
    n_rows, k = probs.shape
    v_min, v_max = support[0], support[k - 1]
    dz = np.float32((np.float64(v_max) - np.float64(v_min)) / (k - 1))
    out[:] = 0.0
    for n in range(n_rows):
        for j in range(k):
            tz = min(max(reward[n] + discount[n] * support[j], v_min), v_max)
            b = (tz - v_min) / dz
            lo = np.floor(b)
            hi = np.ceil(b)
            p = probs[n, j]
            il, ih = int(lo), int(hi)
            if il == ih:
                out[n, il] += p
            else:
                out[n, il] += p * (hi - b)
                out[n, ih] += p * (b - lo)
