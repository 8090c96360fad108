"""Only the environments read the simulator behind a VectorEnv: the evaluator, the trainers and
every other module use the step result and VectorEnv's public read-only state
(cdr_bench/vector_env.py, its State table)."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import cdr_bench

PACKAGE = Path(cdr_bench.__file__).parent

MAY_READ_SIM = {
    "vector_env.py",  # owns it
    "env.py",  # the PettingZoo face (rendering, its trail)
    "gym_env.py",  # the Gymnasium faces
}
"""Modules (relative to cdr_bench/) that may read ``<something>.sim``; and the simulator package
itself (cdr_bench/sim/)."""

MAY_BUILD_SIMULATOR = {
    "vector_env.py",
    "leaderboard/data.py",  # compares the reset state arrays of a scenario's episodes
}
"""Modules outside cdr_bench/sim/ that may construct a ``Simulator`` of their own."""


@functools.cache
def _modules() -> list[tuple[str, ast.Module]]:
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        if rel.startswith("sim/"):
            continue
        out.append((rel, ast.parse(path.read_text(encoding="utf-8"), filename=str(path))))
    return out


def test_only_the_environments_read_the_simulator():
    reads = [
        f"cdr_bench/{rel}:{node.lineno}"
        for rel, tree in _modules()
        if rel not in MAY_READ_SIM
        for node in ast.walk(tree)
        if isinstance(node, ast.Attribute) and node.attr == "sim"
    ]
    assert not reads, (
        "read the public step result or VectorEnv's read-only state (positions_km, goals_km, "
        "levels, outcomes, episode_steps, ...; add a property there if one is missing) "
        f"instead of .sim: {reads}"
    )


def test_only_the_environments_build_a_simulator():
    calls = [
        f"cdr_bench/{rel}:{node.lineno}"
        for rel, tree in _modules()
        if rel not in MAY_BUILD_SIMULATOR
        for node in ast.walk(tree)
        if isinstance(node, ast.Call)
        and (
            (isinstance(node.func, ast.Name) and node.func.id == "Simulator")
            or (isinstance(node.func, ast.Attribute) and node.func.attr == "Simulator")
        )
    ]
    assert not calls, f"step a VectorEnv instead of a Simulator of your own: {calls}"


def test_the_check_sees_a_read():
    tree = ast.parse("x = env.sim.ac_pos_km\ny = self.vector.sim")
    hits = [n for n in ast.walk(tree) if isinstance(n, ast.Attribute) and n.attr == "sim"]
    assert len(hits) == 2
