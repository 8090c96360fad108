"""``masked_sample``: draws follow the masked softmax, never pick a masked action, depend only on
the seed, and do not change when numpy's own exp would (fixed numeric path)."""

from __future__ import annotations

import numpy as np

from cdr_bench.inference import masked_argmax, masked_sample


def test_draws_follow_the_masked_softmax():
    logits = np.tile(np.array([0.0, 1.0, 2.0, 3.1], np.float32), (40_000, 1))
    mask = np.tile(np.array([1, 1, 0, 1], np.int8), (40_000, 1))
    a = masked_sample(logits, mask, np.random.default_rng(0))
    freq = np.bincount(a, minlength=4) / a.size
    w = np.exp([0.0, 1.0, 3.1])
    p = w / w.sum()
    assert freq[2] == 0.0
    np.testing.assert_allclose(freq[[0, 1, 3]], p, atol=0.006)


def test_same_seed_same_draws_and_unmasked_mode():
    rng = np.random.default_rng(5)
    logits = rng.normal(size=(500, 27)).astype(np.float32)
    a = masked_sample(logits, None, np.random.default_rng(1))
    b = masked_sample(logits, None, np.random.default_rng(1))
    c = masked_sample(logits, None, np.random.default_rng(2))
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert len(set(a.tolist())) > 20  # every action reachable without a mask


def test_a_dominant_logit_is_the_argmax_and_degenerate_rows_fall_back():
    logits = np.zeros((3, 27), np.float32)
    logits[0, 7] = 60.0  # weight e^-60 elsewhere: the draw is the argmax
    logits[1, 3] = np.nan  # NaN: argmax semantics (the NaN wins)
    mask = np.ones((3, 27), np.int8)
    mask[2] = 0  # all masked: argmax semantics (0)
    got = masked_sample(logits, mask, np.random.default_rng(0))
    assert got.tolist() == masked_argmax(logits, mask).tolist() == [7, 3, 0]
