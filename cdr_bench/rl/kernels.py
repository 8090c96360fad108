"""Compiled (numba) kernels of the trainers, where PyTorch's or numpy's small operations cost more
than the arithmetic: the denoiser's three-token attention (forward and backward) and the
prioritised replay's sum tree. Sequential loops in a fixed order: the same inputs give the same
outputs bit for bit (on the same machine).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

# --- three-token attention, summed over the queries ------------------------------------------
#
# Tokens i = 0 (state), 1 (step), 2 (noisy logits), each row of its table holding the attention's
# input projection [q | k | v] (3W). Per head (width d = W / heads) the scores are
# s_ij = (q_i . k_j) / sqrt(d), a_ij = softmax_j s_ij, and the output is the sum over the queries
# of the attention outputs: out = sum_i sum_j a_ij v_j = sum_j c_j v_j with c_j = sum_i a_ij.
# Row n of the output takes token 0 from row h_idx[n] of its table, token 1 from row t_idx[n],
# token 2 from row n.


@njit(cache=True)
def attention_forward(
    qkv0: NDArray[np.float32],
    idx0: NDArray[np.int64],
    qkv1: NDArray[np.float32],
    idx1: NDArray[np.int64],
    qkv2: NDArray[np.float32],
    heads: int,
    out: NDArray[np.float32],
    attn: NDArray[np.float32],
) -> None:
    """``out`` (N, W) and the attention weights ``attn`` (N, heads, 3, 3) (kept for the
    backward pass)."""
    n_rows = qkv2.shape[0]
    w = qkv2.shape[1] // 3
    d = w // heads
    scale = np.float32(1.0 / np.sqrt(d))
    s = np.empty((3, 3), np.float32)
    for n in range(n_rows):
        r0, r1, r2 = qkv0[idx0[n]], qkv1[idx1[n]], qkv2[n]
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
    qkv0: NDArray[np.float32],
    idx0: NDArray[np.int64],
    qkv1: NDArray[np.float32],
    idx1: NDArray[np.int64],
    qkv2: NDArray[np.float32],
    heads: int,
    attn: NDArray[np.float32],
    grad_out: NDArray[np.float32],
    grad0: NDArray[np.float32],
    grad1: NDArray[np.float32],
    grad2: NDArray[np.float32],
) -> None:
    """Adds the gradients of the three tables to ``grad0``, ``grad1``, ``grad2`` (zeroed by the
    caller; rows shared by several outputs accumulate in row order)."""
    n_rows = qkv2.shape[0]
    w = qkv2.shape[1] // 3
    d = w // heads
    scale = np.float32(1.0 / np.sqrt(d))
    ds = np.empty((3, 3), np.float32)
    for n in range(n_rows):
        r0, r1, r2 = qkv0[idx0[n]], qkv1[idx1[n]], qkv2[n]
        g0, g1, g2 = grad0[idx0[n]], grad1[idx1[n]], grad2[n]
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
