"""Every results table in the repository is what the committed files produce now: the marked
blocks of README.md, agents/BASELINES.md and agents/diffusion_ac/README.md (rendered by
``cdr_bench.leaderboard.tables``; the leaderboard's own pages are compared by CI's
``cdr-bench leaderboard build --check``); plus the rendering mechanism
on a miniature repository and the import boundary between the leaderboard and the trainers."""

from __future__ import annotations

import ast
import os
import re
import shutil
from pathlib import Path

import pytest

from cdr_bench.errors import UserError
from cdr_bench.evaluate import report
from cdr_bench.leaderboard import page_tables, tables
from tests.leaderboard.conftest import ROOT, cdr

DOC_FILES = sorted(
    {*tables.DOC_BLOCKS, *(str(p.relative_to(ROOT)) for p in (ROOT / "leaderboard").glob("*.md"))}
)


@pytest.mark.parametrize("rel", DOC_FILES)
def test_every_marked_block_has_a_renderer(rel: str) -> None:
    """No block can go stale unnoticed: each is rendered by tables.DOC_BLOCKS (checked below)."""
    text = (ROOT / rel).read_text(encoding="utf-8")
    names = re.findall(r"<!-- ([a-z0-9-]+):start -->", text)
    assert len(names) == len(set(names)), f"{rel}: a block name is used twice"
    assert sorted(names) == sorted(tables.marked_blocks(text)), f"{rel}: unclosed block"
    known = set(tables.DOC_BLOCKS.get(rel, {}))
    assert set(names) <= known, f"{rel}: blocks without a renderer: {set(names) - known}"
    assert known <= set(names), f"{rel}: registered blocks missing"


@pytest.mark.skipif(
    os.environ.get("CDR_BENCH_DOCS_CHECKED_BY") == "leaderboard-check",
    reason="CI's `cdr-bench leaderboard build --check`, run beside the tests, renders and "
    "compares these same blocks; .ci/run fails unless its output says they match",
)
def test_doc_blocks_are_what_the_committed_files_produce() -> None:
    # one render of the repository's blocks (the costly part: every result read), through the
    # CLI a contributor runs; it names every stale block and exits non-zero
    assert set(tables.DOC_BLOCKS) >= {"README.md"}
    r = cdr("leaderboard", "render-docs", "--check", cwd=ROOT, timeout=300)
    assert r.returncode == 0, (
        f"stale results blocks: run `cdr-bench leaderboard render-docs`\n{r.stderr}"
    )
    assert "match the result files" in r.stderr


def test_stale_block_is_detected_and_rewritten(
    evaluated_repo: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The mechanism on the miniature repository: an empty or tampered block is reported by
    ``check`` (which writes nothing) and rewritten otherwise; other text is left alone."""
    repo = tmp_path / "repo"
    shutil.copytree(evaluated_repo, repo)
    monkeypatch.setattr(
        tables,
        "DOC_BLOCKS",
        {
            "README.md": {
                "results": lambda r: tables.measured(r, ["direct", "weave"]),
                "low": lambda r: tables.measured(r, ["weave"], ["low"], ci=False),
            }
        },
    )
    readme = repo / "README.md"
    text = (
        "# Mini\n\nintro\n\n<!-- results:start -->\nold\n<!-- results:end -->\n\nmiddle\n\n"
        "<!-- low:start -->\n<!-- low:end -->\n\nend\n"
    )
    readme.write_text(text)
    lb = repo / "leaderboard"

    diffs = tables.render_docs(lb, check=True)
    assert len(diffs) == 1 and "README.md" in diffs[0]
    assert readme.read_text() == text  # check writes nothing

    assert tables.render_docs(lb) == diffs
    new = readme.read_text()
    assert tables.render_docs(lb, check=True) == []
    assert new.startswith("# Mini\n\nintro\n\n<!-- results:start -->\n| agent | scenario |")
    assert "\nmiddle\n" in new and new.endswith("<!-- low:end -->\n\nend\n")
    body = tables.marked_blocks(new)["results"]
    assert "| Direct | low | 8 |" in body and "| Weave | tactical/head-on | 8 |" in body
    # weave names the paper's PPO row: shown beside it, marked published, at the same density
    assert "| PPO — paper Table 2 (published) | low | 1000 | 100% |" in body
    assert "tactical/head-on" not in tables.marked_blocks(new)["low"]

    # a number edited by hand is found
    m = re.search(r"\| Weave \| low \| 8 \| (\d+\.\d)%", new)
    assert m
    readme.write_text(new.replace(m.group(0), m.group(0).replace(m.group(1), "12.3"), 1))
    assert len(tables.render_docs(lb, check=True)) == 1

    # a registered block missing from its file is an error naming both
    readme.write_text("no blocks\n")
    with pytest.raises(UserError, match="README.md: no block <!-- low:start -->"):
        tables.render_docs(lb, check=True)


def test_renderer_formats_from_one_column_list() -> None:
    heads = [c.header for c in report.COLUMNS]
    assert len(heads) == len(set(heads))
    assert {c.header for c in page_tables.MAIN_COLUMNS} <= set(heads)
    m = {"value": 0.5, "ci95": [0.25, 0.75]}
    assert report.fmt_metric("rate", m) == "50.0% [25.0, 75.0]"
    assert report.fmt_metric("rate", m, ci=False) == "50.0%"
    assert report.fmt_metric("mean", {"value": None, "ci95": [None, None]}) == "-"
    assert page_tables.fmt_published("rate", 4.1) == "4.1%"
    assert page_tables.fmt_published("mean", 953) == "953"


def test_no_other_table_generator_is_left() -> None:
    """The removed generators stay removed (their tables are DOC_BLOCKS now)."""
    for rel in (
        "cdr_bench/rl/baselines_report.py",
        "agents/diffusion_ac/report.py",
        "agents/tuning_table.py",
        "agents/diffusion_ac/make_multimodal.sh",
    ):
        assert not (ROOT / rel).exists(), rel


def _imports(path: Path) -> set[str]:
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            out.add(node.module)
    return out


def test_import_boundaries_of_the_renderer() -> None:
    """The leaderboard never imports the trainers, nor they it; the renderer sits in the
    evaluator's layer and imports neither."""
    pkg = ROOT / "cdr_bench"
    bad = {
        m
        for m in _imports(pkg / "evaluate" / "report.py")
        if m.startswith(("cdr_bench.leaderboard", "cdr_bench.rl"))
    }
    assert not bad, f"cdr_bench/evaluate/report.py imports {bad}"
    for f in sorted((pkg / "leaderboard").glob("*.py")):
        bad = {m for m in _imports(f) if m == "cdr_bench.rl" or m.startswith("cdr_bench.rl.")}
        assert not bad, f"{f.relative_to(ROOT)} imports the trainers: {bad}"
    for f in sorted((pkg / "rl").glob("*.py")):
        bad = {m for m in _imports(f) if m.startswith("cdr_bench.leaderboard")}
        assert not bad, f"{f.relative_to(ROOT)} imports the leaderboard: {bad}"
