"""Every code block of README.md, CONTRIBUTING.md and docs/ runs as printed, or says why not.

A fenced block runs unless the line just above it (blank lines aside) is a marker
``<!-- not run: REASON -->`` (CONTRIBUTING.md, "Documentation code blocks"):

* ``python``: executed in this interpreter, in a scratch folder that links the repository's
  top-level files (so paths such as ``docs/tutorials/tight-medium.yaml`` resolve and outputs
  stay out of the checkout);
* ``bash``: ``bash -e -o pipefail`` in such a folder (``python`` and ``cdr-bench`` are this
  interpreter's);
* ``yaml``: a scenario, loaded (and so validated) by ``load_scenario``;
* a block that shows a file (``--8<-- "path"``): the file runs in a command of the same page
  (``python path`` or ``cdr-bench evaluate path``), or is a scenario that loads.

The examples in the docstrings the API pages render (``::`` literal blocks, ``>>>`` lines) run
too. Some commands' output is checked as well (the tutorials: ``CHECKS``).
"""

from __future__ import annotations

import ast
import importlib.util
import json
import math
import os
import re
import shlex
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOC_FILES = ["README.md", "CONTRIBUTING.md"] + sorted(
    p.relative_to(ROOT).as_posix() for p in (ROOT / "docs").rglob("*.md")
)
MARKER = re.compile(r"^\s*<!-- not run:(.*?)-->\s*$")
FENCE = re.compile(r"^(\s*)(`{3,}|~{3,})\s*([^`\s]*)(.*)$")
INCLUDE = re.compile(r'^--8<-- "([^"]+)"$')
RUNNABLE = {"python", "pycon", "bash", "yaml"}
NOT_LINKED = {".git", ".venv", "results", "runs", "site", ".bench", "__pycache__"}


@dataclass(frozen=True)
class Block:
    source: str  # the file it is read from (repository-relative)
    line: int  # of the opening fence (1-based)
    lang: str
    text: str
    reason: str | None = None  # None: runs; else the marker's reason ("" if it gave none)

    @property
    def id(self) -> str:
        return f"{self.source}:{self.line}"

    @property
    def include(self) -> str | None:
        m = INCLUDE.match(self.text.strip())
        return m.group(1) if m else None


def markdown_blocks(source: str) -> list[Block]:
    """The fenced blocks of a Markdown file, with the marker above each, if any."""
    lines = (ROOT / source).read_text(encoding="utf-8").split("\n")
    blocks: list[Block] = []
    i = 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        indent, fence, lang = len(m.group(1)), m.group(2), m.group(3)
        close = re.compile(rf"^\s*{re.escape(fence[0])}{{{len(fence)},}}\s*$")
        j = i + 1
        while j < len(lines) and not close.match(lines[j]):
            j += 1
        body = "\n".join(
            line[indent:] if not line[:indent].strip() else line.lstrip()
            for line in lines[i + 1 : j]
        )
        k = i - 1
        while k >= 0 and not lines[k].strip():
            k -= 1
        marker = MARKER.match(lines[k]) if k >= 0 else None
        reason = marker.group(1).strip() if marker else None
        blocks.append(Block(source, i + 1, lang, body + "\n", reason))
        i = j + 1
    return blocks


def _hooks():
    pytest.importorskip("griffe")
    spec = importlib.util.spec_from_file_location("docs_hooks", ROOT / "docs" / "_hooks.py")
    assert spec and spec.loader
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    return hooks


def api_modules() -> list[str]:
    """Source files of the modules whose docstrings the API pages render (``::: name``)."""
    files = set()
    for doc in DOC_FILES:
        for name in re.findall(r"^::: (\S+)", (ROOT / doc).read_text(), flags=re.MULTILINE):
            parts = name.split(".")
            while parts:
                candidate = ROOT.joinpath(*parts)
                if (candidate / "__init__.py").is_file():
                    files.add((candidate / "__init__.py").relative_to(ROOT).as_posix())
                    break
                if candidate.with_suffix(".py").is_file():
                    files.add(candidate.with_suffix(".py").relative_to(ROOT).as_posix())
                    break
                parts.pop()
    return sorted(files)


def docstring_blocks(source: str) -> list[Block]:
    """The examples of every docstring of a module: ``::`` literal blocks (Python) and ``>>>``
    runs, found as the documentation site finds them (``docs/_hooks.py``)."""
    hooks = _hooks()
    tree = ast.parse((ROOT / source).read_text(encoding="utf-8"))
    blocks = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        doc = ast.get_docstring(node)
        if not doc or ("::" not in doc and ">>>" not in doc):
            continue
        line = node.body[0].lineno if node.body else 1
        md = hooks.rst_to_markdown(doc)
        for b in re.finditer(r"^(\s*)```(python|pycon)\n(.*?)^\1```", md, re.M | re.S):
            text = "\n".join(ln[len(b.group(1)) :] for ln in b.group(3).split("\n"))
            if b.group(2) == "pycon":
                text = "\n".join(re.sub(r"^(>>>|\.\.\.) ?", "", ln) for ln in text.split("\n"))
            blocks.append(Block(source, line, "python", text))
    return blocks


ALL_MARKDOWN = [b for source in DOC_FILES for b in markdown_blocks(source)]


def _runnable() -> list[Block]:
    blocks = [b for b in ALL_MARKDOWN if b.reason is None]
    try:
        blocks += [b for source in api_modules() for b in docstring_blocks(source)]
    except pytest.skip.Exception:
        pass
    return blocks


RUN = _runnable()


def test_every_block_runs_or_says_why_not():
    assert len(ALL_MARKDOWN) >= 30  # the parser found the blocks
    problems = []
    for b in ALL_MARKDOWN:
        if b.reason is not None:
            if len(b.reason) < 10:
                problems.append(f"{b.id}: the not-run marker gives no reason")
            continue
        if b.lang not in RUNNABLE:
            problems.append(
                f"{b.id}: a {b.lang or 'plain'} block cannot run; make it python/bash/yaml or "
                "put '<!-- not run: REASON -->' on the line above it"
            )
        if b.include and not (ROOT / b.include).is_file():
            problems.append(f"{b.id}: shows {b.include}, which does not exist")
        elif b.include and b.include.endswith(".py") and not _runs_on_page(b):
            problems.append(f"{b.id}: shows {b.include}, but no command of the page runs it")
    for source in DOC_FILES:  # a marker always sits right above a block
        lines = (ROOT / source).read_text().split("\n")
        marked = {b.line for b in ALL_MARKDOWN if b.source == source and b.reason is not None}
        for n, line in enumerate(lines, 1):
            if MARKER.match(line) and not _in_code(source, n):
                nxt = next((k for k in range(n + 1, len(lines) + 1) if lines[k - 1].strip()), 0)
                if nxt not in marked:
                    problems.append(f"{source}:{n}: a not-run marker that no block follows")
    assert not problems, "\n".join(problems)


def _in_code(source: str, line: int) -> bool:
    return any(
        b.source == source and b.line < line <= b.line + b.text.count("\n") for b in ALL_MARKDOWN
    )


def _runs_on_page(block: Block) -> bool:
    """A bash block of the same page runs the file the block shows."""
    for b in ALL_MARKDOWN:
        if b.source == block.source and b.lang == "bash" and b.reason is None:
            for words in (shlex.split(ln, comments=True) for ln in b.text.split("\n")):
                if block.include in words and words[:1] in (["python"], ["cdr-bench"]):
                    return True
    return False


@pytest.fixture
def scratch(tmp_path: Path) -> Path:
    """A folder that looks like the repository root (links to its top-level files) and keeps
    what the commands write."""
    for entry in ROOT.iterdir():
        if entry.name not in NOT_LINKED:
            (tmp_path / entry.name).symlink_to(entry)
    return tmp_path


def _environment() -> dict[str, str]:
    bin_dir = str(Path(sys.executable).parent)
    return {
        **os.environ,
        "PATH": bin_dir + os.pathsep + os.environ.get("PATH", ""),
        "PYTHONWARNINGS": "ignore",
        "NO_MKDOCS_2_WARNING": "1",
    }


def _needs(code: str) -> None:
    """Skip when a package a Python block imports is not installed (an extra)."""
    for node in ast.walk(ast.parse(code)):
        names = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            names = [node.module]
        for name in names:
            pytest.importorskip(name.split(".")[0])


def run_bash(text: str, cwd: Path) -> str:
    r = subprocess.run(
        ["bash", "-e", "-o", "pipefail", "-c", text],
        cwd=cwd,
        env=_environment(),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stdout[-4000:]
    return r.stdout


def _trains(b: Block) -> bool:
    """A block that trains or starts Ray: tens of seconds (tests/conftest.py starts them early)."""
    return b.lang == "bash" and any(
        k in b.text for k in ("cdr-bench train", "--total-timesteps", "rllib_ppo.py")
    )


@pytest.mark.parametrize(
    "block",
    [pytest.param(b, marks=pytest.mark.slow) if _trains(b) else b for b in RUN],
    ids=[f"{b.id}-{b.lang}" for b in RUN],
)
def test_block_runs_as_printed(block: Block, scratch: Path, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.chdir(scratch)
    if block.include:
        if block.include.endswith((".yaml", ".yml")):
            from cdr_bench import load_scenario

            load_scenario(block.include)
        else:  # the command of the page that runs it is a block of its own
            path = ROOT / block.include
            compile(path.read_text(encoding="utf-8"), str(path), "exec")
        return
    if block.lang in ("python", "pycon"):
        _needs(block.text)
        exec(compile(block.text, block.id, "exec"), {"__name__": "__doc_block__"})
        return
    if block.lang == "yaml":
        from cdr_bench import load_scenario

        path = scratch / "block.yaml"
        path.write_text(block.text)
        load_scenario(str(path))
        return
    assert block.lang == "bash", block.id
    check = next((f for key, f in CHECKS.items() if key in block.text), None)
    if check is not None:
        for module in getattr(check, "needs", ()):
            pytest.importorskip(module)
    out = run_bash(block.text, scratch)
    if check is not None:
        check(out, scratch)


# -- what some commands must print or write ---------------------------------------------------


def json_lines(output: str) -> list[dict]:
    return [json.loads(line) for line in output.splitlines() if line.startswith("{")]


def _needs_modules(*modules: str) -> Callable[[Callable], Callable]:
    def mark(f: Callable) -> Callable:
        f.needs = modules  # type: ignore[attr-defined]
        return f

    return mark


def _episodes(path: Path) -> list[dict]:
    from cdr_bench.evaluate.results import log_text

    for name in (path.name + ".jsonl.xz", path.name + ".jsonl.gz", path.name + ".jsonl"):
        p = path.with_name(name)
        if p.is_file():
            return [json.loads(line) for line in log_text(p).splitlines() if line.strip()]
    raise AssertionError(f"no per-episode file beside {path}")


def check_cli_tour(out: str, cwd: Path) -> None:
    assert "tactical/head-on" in out and "# high  sha256 " in out  # list, show
    assert "ok    docs/tutorials/tight-medium.yaml" in out  # validate
    assert "ownship.start_clearance_km" in out  # fields
    assert (cwd / "head-on.gif").stat().st_size > 0


def check_evaluate_tutorial(out: str, cwd: Path) -> None:
    from cdr_bench.evaluate.results import read_result

    assert "$ cdr-bench evaluate" in out and "$ cdr-bench compare" in out
    summary = json_lines(out)[-1]
    folder = cwd / "results" / "tutorial"
    mine, direct = read_result(folder / "level_change.json"), read_result(folder / "direct.json")
    (scenario,) = mine["scenarios"]
    assert scenario["id"] == "medium" and scenario["episodes"] == 20
    assert summary["success_rate"] == scenario["metrics"]["ownship"]["success_rate"]["value"]
    assert len(_episodes(folder / "level_change")) == 20
    # the same episodes for both agents, and the conflict-driven level change pays off
    assert scenario["seeds_sha256"] == direct["scenarios"][0]["seeds_sha256"]
    assert summary["los_rate"] < direct["scenarios"][0]["metrics"]["ownship"]["los_rate"]["value"]
    assert "los_rate" in out.split("$ cdr-bench compare", 1)[1]


def check_typed_evaluation(out: str, cwd: Path) -> None:
    assert (cwd / "results" / "level_change_agent" / "medium.json").is_file()
    assert "los_rate" in out.rsplit("wrote", 1)[-1]  # the comparison's table


def check_add_a_scenario(out: str, cwd: Path) -> None:
    assert "ok " in out and "tight-medium" in out
    assert "did you mean 'traffic'" in out and "separation.los_km" in out  # the broken copy
    assert "18 intruders on 6 airways" in out and "ends the episode: True" in out
    outcomes = json_lines(out)[-1]
    assert sum(outcomes.values()) == 5
    assert set(outcomes) <= {"success", "los", "nmac", "boundary", "timeout"}


@_needs_modules("torch")
def check_ppo_tutorial(out: str, cwd: Path) -> None:
    import torch

    *updates, summary = json_lines(out)
    assert [u["update"] for u in updates] == list(range(1, 9))  # 2048 / (8 x 32)
    assert updates[-1]["global_step"] == summary["global_step"] == 2048
    assert all(math.isfinite(u[k]) for u in updates for k in ("pg_loss", "v_loss", "entropy"))
    assert 0 < updates[0]["entropy"] <= math.log(27) + 1e-6  # a categorical over 27 actions
    assert summary["invalid_actions"] == 0  # the masked categorical never picks a masked action
    policy = cwd / "runs" / "ppo-vector-env" / "policy.pt"
    state = torch.load(policy, weights_only=True)
    assert state["actor.4.weight"].shape == (27, 64)
    # scored by the evaluator: the trained state dict through agents/ppo_tutorial, on the same
    # validation episodes as direct and mvp, and the paired differences of cdr-bench compare
    from cdr_bench.evaluate.compare import compare
    from cdr_bench.evaluate.loader import file_sha256
    from cdr_bench.evaluate.results import read_result
    from cdr_bench.evaluate.seeds import SPLITS

    runs = {n: read_result(policy.parent / f"{n}.json") for n in ("ppo", "direct", "mvp")}
    assert runs["ppo"]["agent"]["checkpoint_override"]["sha256"] == file_sha256(policy)
    assert {r["agent"]["name"] for r in runs.values()} == {"ppo_tutorial", "direct", "mvp"}
    assert {r["base_seed"] for r in runs.values()} == {SPLITS["validation"]}
    assert summary["eval_split"] == "validation" and summary["eval_episodes"] == 16
    clean = runs["ppo"]["scenarios"][0]["metrics"]["ownship"]["clean_success_rate"]
    assert summary["clean_success"] == clean["value"] and 0.0 <= clean["value"] <= 1.0
    for base in ("direct", "mvp"):
        rows = compare(policy.parent / f"{base}.json", policy.parent / "ppo.json")["rows"]
        (row,) = [
            r for r in rows if r["metric"] == "clean_success_rate" and r["aircraft"] == "ownship"
        ]
        assert row["a"] == summary[f"{base}_clean_success"]
        assert summary[f"minus_{base}"] == pytest.approx(row["diff"])
        assert summary[f"minus_{base}_ci95"] == pytest.approx(row["ci95"])


@_needs_modules("ray", "torch")
def check_rllib_tutorial(out: str, cwd: Path) -> None:
    row, summary = json_lines(out)[-2:]
    assert row["iteration"] == 1 and summary["env_steps"] >= 128
    assert (cwd / "runs" / "rllib-tutorial" / "checkpoint").is_dir()
    # the greedy module flew two episodes: two outcomes for the ownship and each intruder
    assert set(summary["outcomes"]) == {"ownship_0", "intruder_0", "intruder_1"}
    assert all(sum(c.values()) == 2 for c in summary["outcomes"].values())


@_needs_modules("torch")
def check_shared_policy_tutorial(out: str, cwd: Path) -> None:
    import torch

    decoder = json.JSONDecoder()
    runs = [decoder.raw_decode(out, m.start())[0] for m in re.finditer(r"^\{$", out, re.M)]
    assert [r["algorithm"] for r in runs] == ["ippo", "mappo"]
    for run in runs:
        assert run["steps"] >= 20_000 and run["updates"] >= 1, run
        ck = torch.load(
            cwd / "runs" / f"{run['algorithm']}-tiny" / "checkpoint.pt", weights_only=True
        )
        assert ck["config"]["algorithm"] == run["algorithm"]
        assert ck["state_dict"]["4.weight"].shape == (27, 64)
    # the system table of both evaluations: the same 10 episodes, 49 flights each
    rows = [ln.split() for ln in out.splitlines() if ln.startswith("marl/high-all")]
    system = [r for r in rows if r[1] == "10"]  # scenario, episodes, flights, ...
    assert len(system) == 2 and all(r[2] == "490" for r in system), rows
    for path in ("results/mappo-tiny/high-all.json", "results/mvp/high-all.json"):
        assert (cwd / path).is_file()


def check_template(out: str, cwd: Path) -> None:
    assert (cwd / "results" / "template" / "medium.json").is_file()


def check_tutorial_test_score(out: str, cwd: Path) -> None:
    """The command gives the committed test result of the tutorial's policy (the file the
    tutorial's table is rendered from): the same episodes, the same per-episode records."""
    from cdr_bench.evaluate.results import read_episodes, read_result

    new, old = cwd / "results" / "test" / "ppo_tutorial.json", ROOT / TUTORIAL_TEST
    a, b = read_result(new, metrics=False), read_result(old, metrics=False)
    assert a["scenarios"] == b["scenarios"] and a["agent"]["sha256"] == b["agent"]["sha256"]
    assert read_episodes(new, a) == read_episodes(old, b)
    assert a["episodes_sha256"] == b["episodes_sha256"]


TUTORIAL_TEST = "agents/ppo_tutorial/analysis/test/result.json"


CHECKS: dict[str, Callable[[str, Path], None]] = {
    "cdr-bench scenarios list": check_cli_tour,
    "python docs/tutorials/evaluate_your_agent.py": check_evaluate_tutorial,
    "cdr-bench compare results/direct/medium.json": check_typed_evaluation,
    "python docs/tutorials/add_a_scenario.py": check_add_a_scenario,
    "python docs/tutorials/ppo_vector_env.py --total-timesteps": check_ppo_tutorial,
    "python docs/tutorials/rllib_ppo.py --iterations": check_rllib_tutorial,
    "cdr-bench evaluate agents/template/agent.py": check_template,
    "cdr-bench evaluate agents/ppo_tutorial --scenario high": check_tutorial_test_score,
    "cdr-bench train ippo --scenario marl/high-all": check_shared_policy_tutorial,
}
"""Commands whose output is checked beyond their exit status (key: a part of the block)."""


def test_every_check_has_its_block():
    bash = [b.text for b in RUN if b.lang == "bash"]
    for key in CHECKS:
        assert sum(key in text for text in bash) == 1, key


# -- references ----------------------------------------------------------------------------------


def test_generated_parts_of_the_pages_are_current():
    """The env card, Gymnasium ids, scenario fields and include links committed in docs/ pages
    are what docs/_hooks.py makes of the code now."""
    stale = _hooks().stale_pages()
    assert not stale, f"stale generated parts in {stale}: run python docs/_hooks.py"


SECTION_REF = re.compile(r"(?<![\w/.-])(README|CONTRIBUTING)(?:\.md)?(?:'s)?,?\s+\"([^\"]{1,60})\"")


def _headings(source: str, run_in: bool = False) -> set[str]:
    """The headings of a Markdown file; with ``run_in``, also the bold words that open a
    paragraph (``**How the leaderboard ranks.**``), which CONTRIBUTING.md uses as sections."""
    text = (ROOT / source).read_text(encoding="utf-8")
    text = re.sub(r"^```.*?^```", "", text, flags=re.M | re.S)
    heads = {m.strip() for m in re.findall(r"^#+ (.+)$", text, flags=re.MULTILINE)}
    if run_in:
        heads |= {m.strip() for m in re.findall(r"^\*\*([^*\n]+?)\.?\*\*", text, flags=re.M)}
    return heads


def test_section_references_resolve():
    """'README, "Section"' and 'CONTRIBUTING.md, "Section"' name headings (or a paragraph's bold
    opening words) that exist, in the docs, in the tutorial scripts and in the agent template
    (which points to README's "Observation Space")."""
    sources = DOC_FILES + [
        p.relative_to(ROOT).as_posix()
        for p in [*(ROOT / "docs" / "tutorials").glob("*.py"), ROOT / "agents/template/agent.py"]
    ]
    heads = {
        "README": _headings("README.md", run_in=True),
        "CONTRIBUTING": _headings("CONTRIBUTING.md", run_in=True),
    }
    missing = []
    for source in sources:
        text = (ROOT / source).read_text(encoding="utf-8")
        for m in SECTION_REF.finditer(text):
            if " ".join(m.group(2).split()) not in heads[m.group(1)]:
                missing.append(f"{source}: {m.group(0)!r}")
        if source == "CONTRIBUTING.md":
            for m in re.finditer(r"\(see \"([^\"]+)\"\)", text):
                if m.group(1) not in heads["CONTRIBUTING"]:
                    missing.append(f"{source}: {m.group(0)!r}")
    assert not missing, "\n".join(missing)


LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")


def test_relative_links_resolve_in_the_repository():
    """Every relative link of the docs names a file of the repository, and an anchor into a
    Markdown file names one of its headings (as GitHub spells anchors). The leaderboard pages
    the site build adds (docs/_hooks.py) count as present."""
    hooks = _hooks()
    site_only = {f"docs/{p}" for p in hooks.LEADERBOARD_FILES}
    broken = []
    for source in DOC_FILES:
        text = (ROOT / source).read_text(encoding="utf-8")
        text = re.sub(r"^\s*```.*?^\s*```", "", text, flags=re.M | re.S)
        text = re.sub(r"`[^`\n]*`", "", text)
        for target in LINK.findall(text):
            if re.match(r"^[a-z][a-z0-9+.-]*:", target):
                continue
            path, _, anchor = target.partition("#")
            rel = os.path.normpath(os.path.join(os.path.dirname(source), path)) if path else source
            if rel in site_only:
                continue
            if not (ROOT / rel).exists():
                broken.append(f"{source}: {target} (no {rel})")
            elif anchor and rel.endswith(".md") and not rel.startswith("docs/api/"):
                slugs = {hooks.github_slug(h) for h in _headings(rel)}
                if anchor not in slugs:
                    broken.append(f"{source}: {target} (no heading #{anchor} in {rel})")
    assert not broken, "\n".join(broken)


def test_inline_help_calls_work():
    """`help(X)` quoted in the docs works, and shows the env card where it says so."""
    import pydoc

    import cdr_bench

    calls = {
        m
        for source in DOC_FILES
        for m in re.findall(r"`help\(([\w.]+)\)`", (ROOT / source).read_text(encoding="utf-8"))
    }
    assert "cdr_bench.CDREnv" in calls
    for expr in calls:
        obj = eval(expr, {"cdr_bench": cdr_bench})  # a dotted name
        text = pydoc.render_doc(obj, renderer=pydoc.plaintext)
        if expr.endswith("CDREnv"):
            assert "Observation Space" in text and "goal_sin_rel" in text


REPO_PATH = re.compile(
    r"`((?:docs|agents|cdr_bench|scenarios|leaderboard|benchmarks|sweeps|tests|examples|\.ci)"
    r"/[\w./-]*(?:\.\w+|/))`"
)  # a file (with an extension) or a folder (a trailing slash); not a Gymnasium id


def test_repository_paths_named_in_the_docs_exist():
    """A file or folder of the repository named in code font (`docs/...`, `examples/...`, ...)
    exists; names with placeholders (`<entry>`, `*`, `my-agent`, `mine/`) are examples."""
    missing = []
    for source in DOC_FILES:
        text = (ROOT / source).read_text(encoding="utf-8")
        text = re.sub(r"^\s*```.*?^\s*```", "", text, flags=re.M | re.S)
        for path in REPO_PATH.findall(text):
            if re.search(r"my[-_]|/mine/|\.\.\.", path):
                continue
            if not (ROOT / path.rstrip("/")).exists():
                missing.append(f"{source}: {path}")
    assert not missing, "\n".join(missing)
