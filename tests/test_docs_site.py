"""The documentation site (mkdocs.yml, docs/): the strict build renders every page, the API
pages from the docstrings, and each tutorial script runs end to end at a small budget."""

from __future__ import annotations

import html
import importlib.util
import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

pytest.importorskip("mkdocs")
pytest.importorskip("mkdocstrings")

ROOT = Path(__file__).resolve().parents[1]
TUTORIALS = ROOT / "docs" / "tutorials"
ENV = {**os.environ, "NO_MKDOCS_2_WARNING": "1", "PYTHONWARNINGS": "ignore"}


def mkdocs_build(config: Path, site: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(config), "-d", str(site)],
        cwd=ROOT,
        env=ENV,
        capture_output=True,
        text=True,
        timeout=300,
    )


def run_tutorial(script: str, *args: str, cwd: Path) -> str:
    """Run a tutorial script as documented; its output (stdout and stderr)."""
    r = subprocess.run(
        [sys.executable, str(TUTORIALS / script), *args],
        cwd=cwd,
        env=ENV,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stdout[-4000:]
    return r.stdout


def json_lines(output: str) -> list[dict]:
    return [json.loads(line) for line in output.splitlines() if line.startswith("{")]


def page(site: Path, name: str) -> str:
    """The text of a built page (tags removed: highlighted code is split into spans)."""
    text = (site / name / "index.html").read_text(encoding="utf-8")
    return html.unescape(re.sub(r"<[^>]+>", "", text))


@pytest.mark.slow
def test_site_builds_strict_with_api_pages_generated_parts_and_tutorials(tmp_path):
    site = tmp_path / "site"
    r = mkdocs_build(ROOT / "mkdocs.yml", site)
    assert r.returncode == 0, r.stderr[-4000:]

    # mkdocstrings rendered the docstrings (not just the ::: lines), and the reStructuredText
    # idioms of the docstrings became Markdown
    vector = page(site, "api/vector_env")
    assert "episodes of one scenario in lock-step, arrays in and out" in vector
    assert "============" not in vector  # the simple rst table became a Markdown table
    assert "<th>shape and meaning</th>" in (site / "api/vector_env/index.html").read_text()
    assert "Start episodes (default all) and return every episode" in vector  # a method
    assert "::: cdr_bench" not in vector
    for api in (site / "api").rglob("index.html"):
        text = html.unescape(api.read_text(encoding="utf-8"))
        assert not re.search(r":(class|meth|mod|func|data):`", text), api
    assert "Index of the triple (a_psi, a_v, a_h)" in page(site, "api/actions")
    assert "Load a scenario by registry name or YAML path" in page(site, "api/scenarios")
    agents = page(site, "agents")
    assert "The required part of the protocol" in agents  # Agent's docstring
    assert "AgentProcess starts python -m cdr_bench.evaluate.agent_host" in agents  # remote.py
    assert "class Agent:" in agents  # the template, included from agents/template/agent.py

    # generated parts: the env card from CDREnv's docstring, the Gymnasium ids from the code,
    # sections of README.md / CONTRIBUTING.md, the leaderboard as committed
    env = page(site, "environment")
    assert "cdr_bench/CurriculumStage12-v0" in env and "goal_sin_rel" in env
    assert "Termination (per agent; the agent then leaves agents and the sky)" in env
    scenarios = page(site, "scenarios")
    assert "extends: inherits from another scenario" in scenarios  # README, "Scenarios"
    assert "ownship.start_clearance_km" in scenarios  # its generated field table
    assert "Mappings merge key by key" in scenarios  # CONTRIBUTING.md, "Add a scenario"
    assert "cdr-bench leaderboard build --evaluate my-agent" in page(site, "leaderboard")
    for built in site.rglob("*.html"):
        assert "<!-- cdr-bench:" not in built.read_text(encoding="utf-8"), built
    results = page(site, "leaderboard/results")
    assert "# cdr-bench leaderboard" not in results and "Measured here" in results
    plots = sorted((ROOT / "leaderboard" / "plots").glob("*.png"))
    assert plots and all((site / "leaderboard" / "plots" / p.name).is_file() for p in plots)

    # each tutorial page shows its script as it is in the repository
    for name, script in [
        ("evaluate-your-agent", "evaluate_your_agent.py"),
        ("evaluate-your-agent", "level_change_agent.py"),
        ("add-a-scenario", "add_a_scenario.py"),
        ("add-a-scenario", "tight-medium.yaml"),
        ("ppo-vector-env", "ppo_vector_env.py"),
        ("rllib", "rllib_ppo.py"),
    ]:
        text = page(site, f"tutorials/{name}")
        code = [ln.strip() for ln in (TUTORIALS / script).read_text().splitlines() if ln.strip()]
        for line in (code[0], code[len(code) // 2], code[-1]):
            assert line in text, (name, line)


def test_strict_build_fails_on_a_broken_link_or_anchor(tmp_path):
    """The site's validation settings turn a broken link or anchor into a failed build."""
    config = yaml.load((ROOT / "mkdocs.yml").read_text(), Loader=_TaggedLoader)
    docs = tmp_path / "docs"
    docs.mkdir()
    (docs / "index.md").write_text("# Home\n\n## Here\n\n[there](missing.md), [here](#nowhere)\n")
    kept = {k: config[k] for k in ("site_name", "strict", "validation", "theme")}
    (tmp_path / "mkdocs.yml").write_text(yaml.safe_dump({**kept, "docs_dir": str(docs)}))
    r = mkdocs_build(tmp_path / "mkdocs.yml", tmp_path / "site")
    assert r.returncode != 0
    assert "missing.md" in r.stderr and "#nowhere" in r.stderr


def test_hooks_include_relink_and_rewrite_docstrings():
    """What docs/_hooks.py does to included text and to docstrings."""
    spec = importlib.util.spec_from_file_location("docs_hooks", ROOT / "docs" / "_hooks.py")
    assert spec and spec.loader
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    body = hooks.section("CONTRIBUTING.md", "Add a scenario")
    assert "extends:" in body and "## Add an agent" not in body  # up to the next section
    with pytest.raises(ValueError, match="no heading"):
        hooks.section("CONTRIBUTING.md", "No such section")
    relink = hooks._relink
    assert relink("[m](docs/model.md#4-separation)", "README.md", "tutorials/a.md") == (
        "[m](../model.md#4-separation)"
    )
    assert relink("[x](leaderboard/README.md)", "README.md", "index.md") == (
        "[x](leaderboard/results.md)"
    )
    assert relink("[bench](benchmarks/README.md)", "README.md", "index.md") == (
        "bench (`benchmarks/README.md`)"
    )  # not part of the site: no dead link
    assert relink("[lo, hi] [0, 360] `[a] [b]` [u](https://x.org)", "README.md", "index.md") == (
        r"\[lo, hi\] \[0, 360\] `[a] [b]` [u](https://x.org)"
    )
    rst = "See :class:`~cdr_bench.vector_env.VectorEnv` or :mod:`cdr_bench.actions`::\n\n    x = 1"
    assert hooks.rst_to_markdown(rst) == (
        "See `VectorEnv` or `cdr_bench.actions`:\n\n```python\nx = 1\n```\n"
    )


class _TaggedLoader(yaml.SafeLoader):
    """Reads mkdocs.yml, ignoring MkDocs' own tags (``!relative``)."""


_TaggedLoader.add_multi_constructor("!", lambda loader, suffix, node: None)


def test_evaluate_your_agent_tutorial(tmp_path):
    out = run_tutorial("evaluate_your_agent.py", "--episodes", "10", "--out", "r", cwd=tmp_path)
    assert "$ cdr-bench evaluate" in out and "$ cdr-bench compare" in out
    summary = json_lines(out)[-1]
    mine = json.loads((tmp_path / "r" / "level_change.json").read_text())
    direct = json.loads((tmp_path / "r" / "direct.json").read_text())
    (scenario,) = mine["scenarios"]
    assert scenario["id"] == "medium" and scenario["episodes"] == 10
    assert summary["success_rate"] == scenario["metrics"]["ownship"]["success_rate"]["value"]
    assert len((tmp_path / "r" / "level_change.jsonl").read_text().splitlines()) == 10
    # the same episodes for both agents, and the conflict-driven level change pays off
    assert scenario["seeds_sha256"] == direct["scenarios"][0]["seeds_sha256"]
    assert summary["los_rate"] < direct["scenarios"][0]["metrics"]["ownship"]["los_rate"]["value"]
    assert "los_rate" in out.split("$ cdr-bench compare", 1)[1]


def test_add_a_scenario_tutorial(tmp_path):
    out = run_tutorial("add_a_scenario.py", "--episodes", "3", cwd=tmp_path)
    assert "ok " in out and "tight-medium" in out
    assert "did you mean 'traffic'" in out and "separation.los_km" in out  # the broken copy
    assert "18 intruders on 6 airways" in out and "ends the episode: True" in out
    outcomes = json_lines(out)[-1]
    assert sum(outcomes.values()) == 3
    assert set(outcomes) <= {"success", "los", "nmac", "boundary", "timeout"}


@pytest.mark.slow
def test_ppo_vector_env_tutorial(tmp_path):
    import torch

    args = ["--total-timesteps", "1024", "--num-envs", "8", "--num-steps", "32"]
    args += ["--update-epochs", "2", "--num-minibatches", "2"]
    out = run_tutorial(
        "ppo_vector_env.py", *args, "--eval-episodes", "8", "--save", "p.pt", cwd=tmp_path
    )
    *updates, summary = json_lines(out)
    assert [u["update"] for u in updates] == [1, 2, 3, 4]
    assert updates[-1]["global_step"] == summary["global_step"] == 1024
    assert all(math.isfinite(u[k]) for u in updates for k in ("pg_loss", "v_loss", "entropy"))
    assert 0 < updates[0]["entropy"] <= math.log(27) + 1e-6  # a categorical over 27 actions
    assert summary["invalid_actions"] == 0  # the masked categorical never picks a masked action
    assert 0.0 <= summary["eval_success_rate"] <= 1.0 and summary["eval_episodes"] == 8
    state = torch.load(tmp_path / "p.pt", weights_only=True)
    assert state["actor.4.weight"].shape == (27, 64)


@pytest.mark.slow
def test_rllib_tutorial(tmp_path):
    pytest.importorskip("ray.rllib")
    args = ["--iterations", "1", "--batch", "128", "--minibatch", "64", "--eval-episodes", "1"]
    out = run_tutorial("rllib_ppo.py", *args, "--out", "rl", cwd=tmp_path)
    row, summary = json_lines(out)[-2:]
    assert row["iteration"] == 1 and summary["env_steps"] >= 128
    assert (tmp_path / "rl" / "checkpoint").is_dir()
    # the greedy module flew one episode: one outcome for the ownship and each intruder
    assert set(summary["outcomes"]) == {"ownship_0", "intruder_0", "intruder_1"}
    assert all(sum(c.values()) == 1 for c in summary["outcomes"].values())
