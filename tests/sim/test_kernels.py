"""The compiled simulator: one implementation for every batch size, and floating point that does
not depend on the CPU (docs/model.md §12)."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cdr_bench.scenarios import list_scenarios, load_scenario
from cdr_bench.sim import Simulator, observe
from cdr_bench.sim.geometry import exact_unit_vector
from tests.kernel_code import INSPECTED_ENV

ROOT = Path(__file__).resolve().parents[2]


def _rollout(sim: Simulator, steps: int, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    frames = []
    for _ in range(steps):
        masks = sim.action_masks().astype(bool)
        act = np.array([[rng.choice(np.flatnonzero(mk)) for mk in row] for row in masks])
        r = sim.step(act)
        frames += [observe(sim).copy(), r.terms.copy(), r.outcome.copy(), sim.pos_km.copy()]
    return frames


@pytest.mark.parametrize("name", ["high", "marl/medium-4", "marl/high-24", "tactical/crossing"])
def test_an_episode_is_the_same_in_a_batch_of_one_and_in_a_big_batch(name):
    cfg = load_scenario(name)
    seeds = [11, 12, 13, 14, 15]
    big = Simulator(cfg, len(seeds))
    big.reset(seeds)
    one = Simulator(cfg, 1)
    one.reset([seeds[3]])
    rng = np.random.default_rng(0)
    for _ in range(40):
        act = rng.integers(0, 27, (len(seeds), big.M))
        rb, ro = big.step(act), one.step(act[3:4])
        assert np.array_equal(rb.terms[3], ro.terms[0])
        assert np.array_equal(rb.events[:, 3], ro.events[:, 0])
        assert np.array_equal(big.pos_km[3], one.pos_km[0])
        assert np.array_equal(observe(big)[3], observe(one)[0])


def test_same_seed_same_bits_and_reset_of_a_subset_leaves_the_others_alone():
    cfg = load_scenario("medium")
    a, b = Simulator(cfg, 3), Simulator(cfg, 3)
    a.reset([1, 2, 3])
    b.reset([1, 2, 3])
    fa, fb = _rollout(a, 20), _rollout(b, 20)
    assert all(np.array_equal(x, y) for x, y in zip(fa, fb, strict=True))
    before = a.pos_km[[0, 2]].copy()
    a.reset([99], episodes=[1])
    assert np.array_equal(a.pos_km[[0, 2]], before) and a.steps[1] == 0


def test_reset_rejects_bad_episode_indices_and_seed_counts():
    sim = Simulator(load_scenario("low"), 2)
    with pytest.raises(ValueError, match="episode indices"):
        sim.reset([1], episodes=[2])
    with pytest.raises(ValueError, match="expected 2 seeds"):
        sim.reset([1])


def test_every_shipped_scenario_resets_and_steps():
    for name in list_scenarios():
        sim = Simulator(load_scenario(name), 2)
        sim.reset([0, 1])
        sim.step(np.full((2, sim.M), 13))
        o = observe(sim)
        assert np.isfinite(o).all(), name


_INSPECT = """
import sys, numpy as np
from cdr_bench.scenarios import load_scenario
from cdr_bench.sim import Simulator, kernels, observe
from tests.kernel_code import inspect_module
sim = Simulator(load_scenario("marl/low-2"), 2)
sim.reset([0, 1])
sim.step(np.full((2, sim.M), 13))
observe(sim)
E, M = 2, 1  # the evaluator's per-step accumulator, compiled on small arrays of its dtypes
f, i, b = np.zeros((E, M)), np.zeros((E, M), np.int64), np.zeros((E, M), bool)
kernels.accumulate_step(
    np.full((E, M), 13, np.int64), np.zeros((E, M, 7)), np.zeros((E, M, 6), bool),
    np.zeros((E, M), np.int8), f.copy(), np.zeros((E, M, 2)), np.ones((E, M, 2)),
    np.zeros((E, M, 2)), 5.0, 30.0, np.zeros((8, E, M), np.int64), i.copy(), i.copy(),
    f.copy(), f.copy(), f.copy(), f.copy(), i.copy(), f.copy(), np.zeros((E, M), np.int8),
    b.copy(), b.copy(),
)
found = inspect_module(kernels)
for fn in ("step_episodes", "observe_episodes", "reset_episodes", "accumulate_step"):
    assert any(k.startswith(f"cdr_bench.sim.kernels.{fn}(") for k in found), fn
bad = {k: v for k, v in found.items() if v}
if bad:
    sys.exit(f"in the machine code: {bad}")
print("ok")
"""


@pytest.mark.slow
def test_no_fused_multiply_add_or_transcendental_call_in_the_kernels(tmp_path):
    # tests/kernel_code.py: why; in a fresh process with an empty cache (numba cannot inspect
    # code loaded from its cache). CI inspects every kernel it compiles (.ci/warm_kernels.py).
    by = os.environ.get(INSPECTED_ENV)
    if by:
        pytest.skip(f"the kernels' machine code was inspected by {by}")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    # the timeout only guards against a hang: compiling every kernel afresh took 70 s on a
    # loaded 2-core machine
    out = subprocess.run(
        [sys.executable, "-c", _INSPECT], env=env, capture_output=True, text=True, timeout=3600
    )
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-2000:] + out.stdout


@settings(max_examples=300, deadline=None)
@given(st.floats(0.0, 360.0).filter(lambda h: h == 0.0 or h >= 1e-300))
def test_exact_unit_vector_is_sin_and_cos_correctly_rounded(h):
    """Below 1e-300 degrees the sine is a subnormal number, where this reference and the
    function were seen one subnormal step apart (h = 8.590653706980105e-308); no heading of a
    scenario comes near, so those angles are outside what this test checks."""
    mpmath = pytest.importorskip("mpmath")
    with mpmath.workdps(60):
        x = mpmath.mpf(h) / 180
        assert exact_unit_vector(h) == (float(mpmath.sinpi(x)), float(mpmath.cospi(x)))


def test_exact_unit_vector_at_the_cardinal_points():
    assert exact_unit_vector(0.0) == (0.0, 1.0)
    assert exact_unit_vector(90.0) == (1.0, 0.0)
    assert exact_unit_vector(180.0) == (0.0, -1.0)
    assert exact_unit_vector(270.0) == (-1.0, 0.0)
    # sin 5 deg = 0.087155742747658173558...: the nearest float64 prints as ...818; libm's
    # sin(radians(5)) gives ...817 (radians(5) is itself rounded).
    assert exact_unit_vector(5.0) == (0.08715574274765818, 0.9961946980917455)


def test_heading_vector_stays_unit_after_many_turns():
    sim = Simulator(load_scenario("low"), 1)
    sim.reset([0])
    for _ in range(200):
        sim.step(np.array([[22]]))  # right turn, level
        if not sim.ac_active[0, 0]:
            break
    u = sim.ac_dir[0, 0]
    assert abs(math.hypot(u[0], u[1]) - 1.0) < 4e-16
