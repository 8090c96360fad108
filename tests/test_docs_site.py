"""The documentation site (mkdocs.yml, docs/): the strict build renders every page, the API
pages from the docstrings and the generated parts. The tutorial scripts run as their pages print
them in tests/test_doc_blocks.py."""

from __future__ import annotations

import html
import importlib.util
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


def test_hooks_fill_directives_between_their_markers():
    """A directive and its end marker: the site shows the generated or included text in their
    place; the repository copy keeps the generated text (or a link to the included section)
    between them, and a lone directive gets its end marker."""
    spec = importlib.util.spec_from_file_location("docs_hooks", ROOT / "docs" / "_hooks.py")
    assert spec and spec.loader
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    page = "# T\n\n<!-- cdr-bench: gymnasium-tasks -->\n\nold\n\n<!-- cdr-bench: end -->\n\ntail\n"
    site = hooks.page_markdown(page, "t.md")
    assert "cdr_bench/High-v0" in site and "old" not in site and "<!--" not in site
    assert site.endswith("\n\ntail\n")
    repo = hooks.repository_markdown(page, "t.md")
    assert "old" not in repo and "cdr_bench/High-v0" in repo and repo.count("cdr-bench: end") == 1
    assert hooks.repository_markdown(repo, "t.md") == repo
    lone = '<!-- cdr-bench: section CONTRIBUTING.md "Add a scenario" -->\n'
    assert hooks.repository_markdown(lone, "tutorials/x.md") == (
        '<!-- cdr-bench: section CONTRIBUTING.md "Add a scenario" -->\n\n'
        '*Section "Add a scenario" of [CONTRIBUTING.md](../../CONTRIBUTING.md#add-a-scenario), '
        "shown here on the documentation site.*\n\n<!-- cdr-bench: end -->\n"
    )
    assert "Mappings merge key by key" in hooks.page_markdown(lone, "tutorials/x.md")
    with pytest.raises(ValueError, match="without a directive"):
        hooks.page_markdown("<!-- cdr-bench: end -->\n", "t.md")
    assert hooks.github_slug("10.1.1 The headline score") == "1011-the-headline-score"


class _TaggedLoader(yaml.SafeLoader):
    """Reads mkdocs.yml, ignoring MkDocs' own tags (``!relative``)."""


_TaggedLoader.add_multi_constructor("!", lambda loader, suffix, node: None)
