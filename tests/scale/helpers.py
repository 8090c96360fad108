"""A tiny sweep file for the tests (seconds per trial)."""

from __future__ import annotations

from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[2]
AGENT_FILE = REPO / "agents" / "diffusion_ac" / "agent.py"


def tiny_sweep(tmp: Path, seeds: list[int], grid: dict | None = None, **extra) -> Path:
    doc = {
        "name": "tiny",
        "agent": "diffusion-ac",
        "agent_file": str(AGENT_FILE),
        "seeds": seeds,
        "budget": {"total_steps": 120},
        "fixed": {
            "n-envs": 2,
            "learning-starts": 40,
            "log-every": 60,
            "eval-episodes": 0,
            "curve-every": 0,  # no fixed-set curve point (a third of a tiny trial's time)
            "curriculum": False,
            "scenario": "low",
            "width": 16,
            "critic-width": 16,
            "batch-size": 16,
        },
        "evaluation": {"scenarios": ["tactical/head-on"], "episodes": 2, "seed": 0},
        "max_retries": 3,
        **extra,
    }
    if grid:
        doc["grid"] = grid
    path = tmp / "tiny.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path
