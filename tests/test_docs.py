"""The README: its two commands (and the pins that make them install the same versions), what
it says CI runs, and the links to the generated env card and scenario format. Its code blocks
run in tests/test_doc_blocks.py."""

from __future__ import annotations

import re
from importlib import metadata
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_readme_links_the_generated_env_card_and_scenario_format():
    text = (ROOT / "README.md").read_text()
    assert "(docs/environment.md)" in text and "(docs/scenarios.md#fields)" in text
    assert "<!-- cdr-bench: env-card -->" in (ROOT / "docs" / "environment.md").read_text()
    assert "<!-- cdr-bench: scenario-fields -->" in (ROOT / "docs" / "scenarios.md").read_text()


def test_readme_names_install_and_test_commands():
    text = (ROOT / "README.md").read_text()
    assert "pip install torch==2.13.0" in text and "pytest -q" in text
    ci = (ROOT / ".ci" / "run").read_text()
    assert 'pip install -q -e ".[dev]"' in ci and "pytest -q" in ci


def test_env_card_documents_every_observation_index():
    from cdr_bench.env import CDREnv
    from cdr_bench.sim.observation import NEIGHBOUR_FEATURES, OWN_FEATURES

    doc = CDREnv.__doc__ or ""
    for i, name in enumerate(OWN_FEATURES):
        assert f"| {i} | {name} |" in doc
    for j, name in enumerate(NEIGHBOUR_FEATURES):
        assert f"| 12 + 10k + {j} | {name} |" in doc


def _requirement(requirements: list[str], name: str) -> str:
    (req,) = [r for r in requirements if re.match(rf"{name}\b", r, flags=re.IGNORECASE)]
    return req


def test_base_gymnasium_pin_is_the_one_ray_requires():
    """`.[train]` and `.[dev]` (which adds the ray extra) must resolve to the same Gymnasium:
    the base dependencies pin exactly the version the pinned ray[rllib] requires."""
    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    gym = _requirement(project["dependencies"], "gymnasium")
    ray = _requirement(project["optional-dependencies"]["ray"], "ray")
    assert re.fullmatch(r"gymnasium==[\d.]+", gym), gym
    assert re.fullmatch(r"ray\[rllib\]==[\d.]+", ray), ray
    try:
        installed = metadata.version("ray")
    except metadata.PackageNotFoundError:
        pytest.skip("ray is not installed")
    if installed != ray.split("==")[1]:
        pytest.skip(f"ray {installed} installed, {ray} pinned")
    wanted = [
        r.split(";")[0].replace(" ", "")
        for r in metadata.requires("ray") or []
        if r.startswith("gymnasium") and 'extra == "rllib"' in r
    ]
    assert wanted == [gym], (wanted, gym)
    assert metadata.version("gymnasium") == gym.split("==")[1]


def test_readme_says_what_ci_runs():
    """Each step the README says `.ci/run` takes is in `.ci/run`."""
    text = " ".join((ROOT / "README.md").read_text().split())
    ci = (ROOT / ".ci" / "run").read_text()
    said = text.split("`.ci/run` (CI, on a clean clone)", 1)[1].split("The environments", 1)[0]
    for step in re.findall(r"`([^`]+)`", said):
        assert step.split("(")[0].strip() in ci, step
    for words in ("upgrading pip", "chromium", "bubblewrap"):
        assert words in said
    assert "install -q --upgrade pip" in ci and "chromium" in ci and "bubblewrap" in ci
