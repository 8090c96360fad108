"""The README: its two commands, its runnable quick start, and the links to the generated env
card and scenario format of the documentation site."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_readme_links_the_generated_env_card_and_scenario_format():
    text = (ROOT / "README.md").read_text()
    assert "(docs/environment.md)" in text and "(docs/scenarios.md)" in text
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


def test_readme_batched_quick_start_runs():
    text = (ROOT / "README.md").read_text()
    blocks = [b.split("```", 1)[0] for b in text.split("```python\n")[1:]]
    (block,) = [b for b in blocks if "make_vec" in b]
    exec(compile(block, "README.md (batched quick start)", "exec"), {})
