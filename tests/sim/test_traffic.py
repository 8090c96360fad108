"""Steady-state traffic, spawn hold rule, curriculum schedule and the import boundary."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from cdr_bench.actions import HOLD
from cdr_bench.scenarios import load_scenario
from cdr_bench.sim import Simulator


@pytest.mark.parametrize("name,expected", [("low", 24), ("medium", 36), ("high", 48)])
def test_steady_state_intruder_count(name, expected):
    # Ownship kept far away in a corner-level so the spawn hold rule does not interfere; run the
    # traffic for a long horizon and average the number of intruders in the sky.
    cfg = load_scenario(name, time={"max_steps": 400})
    sim = Simulator(cfg, n_episodes=8)
    sim.reset(np.arange(8))
    counts = []
    for _ in range(400):
        sim.step(np.full((8, 1), HOLD))
        live = sim.ac_active.any(axis=1)
        counts.extend(sim.intruder_count()[live].tolist())
    assert abs(np.mean(counts) - expected) <= 0.05 * expected


def test_steady_state_from_first_step():
    sim = Simulator(load_scenario("high"), n_episodes=4)
    sim.reset([0, 1, 2, 3])
    assert (sim.intruder_count() == 48).all()


def test_levels_cyclic_in_spawn_order_and_spacing():
    cfg = load_scenario("medium")
    sim = Simulator(cfg)
    sim.reset([5])
    for r in range(sim.R):
        slots = np.arange(r * sim.C, (r + 1) * sim.C)
        act = sim.bg_active[0, slots]
        arcs = sim.bg_arc_km[0, slots][act]
        order = np.argsort(arcs)
        gaps = np.diff(arcs[order])
        np.testing.assert_allclose(gaps, sim.route_spacing_km[r])
        levels = sim.bg_level[0, slots][act][order]  # newest first
        assert set(levels.tolist()) == {0, 1, 2}
        assert ((levels[1:] - levels[:-1]) % 3 == 2).all()  # older = one level earlier


def test_spawn_waits_for_controlled_aircraft_at_its_level():
    cfg = load_scenario("curriculum/stage-01", traffic={"routes": 1, "per_route": 3})
    sim = Simulator(cfg)
    sim.reset([0])
    # Park the ownship on the airway entry at the level of the next spawn.
    nxt = sim.route_spawn_count[0, 0] % 3
    sim.ac_pos_km[0, 0] = sim.route_start_km[0]
    sim.ac_level[0, 0] = nxt
    sim.ac_speed_kt[0, 0] = 330.0
    before = sim.intruder_count()[0]
    steps_to_due = int(
        np.ceil(
            (sim.route_spacing_km[0] - sim.route_last_arc_km[0, 0])
            / (sim.traffic_speed_km_s * sim.dt_s)
        )
    )
    for _ in range(steps_to_due):
        sim.pos_km[0, sim.B] = sim.route_start_km[0]  # keep it there
        sim.step(np.array([[HOLD]]))
    assert sim.route_waiting[0, 0]
    assert sim.intruder_count()[0] == before - 1  # one left at the end, none entered


@pytest.mark.parametrize("k", range(1, 13))
def test_curriculum_schedule(k):
    cfg = load_scenario(f"curriculum/stage-{k:02d}")
    assert cfg.traffic.routes == k and cfg.traffic.per_route == 3
    assert cfg.n_route_intruders == 3 * k
    assert cfg.separation.los_km == pytest.approx(4.5 + 0.5 * (k - 1))
    assert cfg.separation.nmac_km == 0.2 and cfg.separation.los_terminates
    sim = Simulator(cfg)
    sim.reset([k])
    assert sim.intruder_count()[0] == 3 * k


def test_density_scenarios_do_not_end_on_los():
    for name in ("low", "medium", "high"):
        assert not load_scenario(name).separation.los_terminates


_BLOCKER = """
import sys, importlib.abc
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in ('pettingzoo', 'gymnasium', 'torch'):
            raise ImportError('blocked: ' + name)
sys.meta_path.insert(0, Block())
"""


def test_sim_runs_without_rl_libraries():
    """The simulator imports and runs with PettingZoo, Gymnasium and torch absent."""
    code = _BLOCKER + (
        "import numpy as np\n"
        "from cdr_bench.scenarios import load_scenario\n"
        "from cdr_bench.sim import Simulator, observe\n"
        "sim = Simulator(load_scenario('high'), 2); sim.reset([0, 1])\n"
        "for _ in range(5): sim.step(np.full((2, 1), 13)); observe(sim)\n"
        "bad = [m for m in ('pettingzoo', 'gymnasium', 'torch') if m in sys.modules]\n"
        "assert not bad, bad\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_sim_source_imports_no_rl_library():
    import ast
    from pathlib import Path

    import cdr_bench.sim

    for path in Path(cdr_bench.sim.__file__).parent.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            for n in names:
                top = n.split(".")[0]
                assert top not in ("pettingzoo", "gymnasium", "torch", "supersuit"), (path, n)
                assert not n.startswith(("cdr_bench.env", "cdr_bench.evaluate")), (path, n)


def test_batched_episodes_are_independent_of_the_batch():
    cfg = load_scenario("high")
    single = Simulator(cfg)
    single.reset([42])
    batch = Simulator(cfg, n_episodes=3)
    batch.reset([1, 42, 7])
    rng = np.random.default_rng(0)
    for _ in range(50):
        a = rng.integers(0, 27)
        single.step(np.array([[a]]))
        batch.step(np.array([[3], [a], [20]]))
        np.testing.assert_array_equal(single.pos_km[0], batch.pos_km[1])
        np.testing.assert_array_equal(single.active[0], batch.active[1])
