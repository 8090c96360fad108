"""The multimodality claim over training seeds (``claims.multimodality_over_seeds``): judged
against PPO sampled, paired on the same episodes, Holm-corrected over the tactical families, and
never judged on fewer than three seeds a side or on runs that are not on the same episodes; the
committed per-seed files are what ``cdr-bench multimodal`` gives (PPO sampled: its first episodes
alone give the same counts; Diffusion-AC draws the noise of every episode's samples together, so
only the full command, ``sweeps/multimodal_seeds.sh``, reproduces its files)."""

from __future__ import annotations

import json
import lzma
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from cdr_bench.leaderboard.claims import (
    HELD,
    MULTIMODAL_MIN_SEEDS,
    NOT_HELD,
    NOT_MEASURED,
    multimodality_over_seeds,
)
from cdr_bench.leaderboard.data import load_multimodal
from cdr_bench.leaderboard.tables import multimodal_seed_path

ROOT = Path(__file__).resolve().parents[2]
FAMILIES = ("left", "right", "climb", "descend", "speed")


def _run(families: list[int], seeds: list[int], samples: int = 10) -> dict[str, Any]:
    """A ``cdr-bench multimodal`` JSON whose episode ``i`` has ``families[i]`` successful
    families, each with one successful sample (the others fail)."""
    eps = []
    for i, (f, s) in enumerate(zip(families, seeds, strict=True)):
        success = [0] * 27
        success[:f] = [1] * f
        eps.append(
            {"episode": i, "seed": s, "all": [samples] + [0] * 26, "success": success,
             "families": list(FAMILIES[:f])}
        )  # fmt: skip
    return {"samples": samples, "per_episode": eps}


def _side(rng: np.random.Generator, mean: float, n_seeds: int, seeds: list[int]) -> dict:
    fams = ("tactical/head-on", "tactical/crossing", "tactical/overtaking")
    return {
        sc: {
            k: _run(list(np.clip(rng.poisson(mean, len(seeds)), 0, 5)), seeds)
            for k in range(1, n_seeds + 1)
        }
        for sc in fams
    }


def test_more_families_on_every_family_is_held_and_the_cells_say_so() -> None:
    rng = np.random.default_rng(0)
    seeds = list(range(100, 200))
    a, b = _side(rng, 3.0, 3, seeds), _side(rng, 1.0, 3, seeds)
    measured, verdict = multimodality_over_seeds(a, b)
    assert verdict == HELD, measured
    assert measured.count("(3 vs 3 seeds, 100 episodes, 10 samples each)") == 3
    assert "Holm p" in measured and "per-sample success" in measured


def test_equal_sides_are_not_held_and_one_family_behind_is_enough() -> None:
    rng = np.random.default_rng(1)
    seeds = list(range(100))
    a, b = _side(rng, 2.0, 3, seeds), _side(rng, 2.0, 3, seeds)
    assert multimodality_over_seeds(a, b)[1] == NOT_HELD
    a = _side(rng, 3.0, 3, seeds)
    b = _side(rng, 1.0, 3, seeds)
    b["tactical/crossing"] = _side(rng, 4.0, 3, seeds)["tactical/crossing"]
    assert multimodality_over_seeds(a, b)[1] == NOT_HELD


def test_too_few_seeds_or_other_episodes_are_not_measured() -> None:
    rng = np.random.default_rng(2)
    seeds = list(range(50))
    a, b = _side(rng, 3.0, MULTIMODAL_MIN_SEEDS - 1, seeds), _side(rng, 1.0, 3, seeds)
    measured, verdict = multimodality_over_seeds(a, b)
    assert verdict == NOT_MEASURED and f"fewer than {MULTIMODAL_MIN_SEEDS} seeds" in measured
    other = _side(rng, 1.0, 3, [s + 1 for s in seeds])
    measured, verdict = multimodality_over_seeds(_side(rng, 3.0, 3, seeds), other)
    assert verdict == NOT_MEASURED and "not on the same episodes" in measured
    assert multimodality_over_seeds({}, other)[1] == NOT_MEASURED


def test_a_compressed_file_that_is_not_json_is_refused(tmp_path: Path) -> None:
    from cdr_bench.errors import UserError

    bad = tmp_path / "x.seed-2.multimodal-tactical_head-on.json.xz"
    bad.write_bytes(b"not xz")
    with pytest.raises(UserError, match="not a multimodality file"):
        load_multimodal(bad)


@pytest.mark.artefacts
@pytest.mark.parametrize(
    ("entry", "agent", "checkpoint", "seed", "scenario"),
    [("ppo-sampled", "agents/ppo_sampled", "agents/ppo/seeds/2/checkpoint.pt", 2, "head-on")],
)
def test_committed_seed_files_are_what_the_command_gives(
    tmp_path: Path, entry: str, agent: str, checkpoint: str, seed: int, scenario: str
) -> None:
    path = multimodal_seed_path(
        ROOT / "leaderboard" / "results", entry, seed, f"tactical/{scenario}"
    )
    committed = json.loads(lzma.decompress(path.read_bytes()))
    assert committed["episodes"] >= 100 and committed["samples"] >= 50
    out = tmp_path / "mm.json"
    r = subprocess.run(
        [sys.executable, "-m", "cdr_bench", "multimodal", agent, "--search", "--seed",
         str(committed["seed"]), "--episodes", "2", "--samples", str(committed["samples"]),
         "--scenario", f"tactical/{scenario}", "--out", str(out)],
        capture_output=True, text=True, cwd=ROOT, timeout=300,
        env={**os.environ, "CDR_BENCH_CHECKPOINT": str(ROOT / checkpoint), "OMP_NUM_THREADS": "1"},
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert json.loads(out.read_text())["per_episode"] == committed["per_episode"][:2]
