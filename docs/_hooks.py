"""Build hooks of the documentation site (``hooks:`` and the mkdocstrings ``extensions:`` of
mkdocs.yml). Not a page: ``exclude_docs`` keeps it out of the site.

* Generated parts are written into pages at build time from where they live:
  ``<!-- cdr-bench: env-card -->`` (``CDREnv``'s docstring), ``<!-- cdr-bench: gymnasium-tasks
  -->`` (``cdr_bench.GYMNASIUM_TASKS``), ``<!-- cdr-bench: scenario-fields -->`` (the schema),
  ``<!-- cdr-bench: section FILE "Heading" -->`` (the body of one section of a Markdown file of
  the repository, e.g. CONTRIBUTING.md) and ``<!-- cdr-bench: intro FILE -->`` (the text between
  its title and its first section). Links of included text are made relative to the page; a link
  to a file that is not part of the site becomes its path in code font; brackets that are not
  links are escaped. An unknown directive, file or heading fails the build.
* Each directive is closed by ``<!-- cdr-bench: end -->``; what lies between is what a reader of
  the page *in the repository* sees (GitHub shows no comment): the generated table itself for a
  generator, a link to the section for an include. The site build replaces it. ``python
  docs/_hooks.py`` rewrites it from the code, ``python docs/_hooks.py --check`` lists the pages
  where it is stale (``tests/test_doc_blocks.py`` fails on them).
* The generated leaderboard (``leaderboard/README.md``, its plots and ``index.html``) is added
  to the site as ``leaderboard/results.md`` and its files, read where it is committed.
* :class:`RstToMarkdown` (a griffe extension) turns the reStructuredText idioms of the package's
  docstrings into Markdown for mkdocstrings: ``:class:`x``` roles, ``::`` literal blocks,
  ``>>>`` examples and simple ``====`` tables; :class:`SimViews` (another) shows the state
  views of ``VectorEnv`` as the read-only properties they are.
"""

from __future__ import annotations

import posixpath
import re
import shlex
from pathlib import Path
from typing import Any

import griffe

REPO = Path(__file__).resolve().parents[1]
DIRECTIVE = re.compile(r"^<!-- cdr-bench: (.+?) -->$", flags=re.MULTILINE)
LEADERBOARD_FILES = {  # site path -> repository path
    "leaderboard/results.md": "leaderboard/README.md",
    "leaderboard/index.html": "leaderboard/index.html",
}


# -- reStructuredText idioms -> Markdown -----------------------------------------------------------

ROLE = re.compile(r":(?:py:)?(?:mod|class|func|meth|attr|data|obj|exc|const):`(~?)([^`]+)`")
RST_LINK = re.compile(r"`([^`<]+?) <(https?://[^>]+)>`__?")


def _role(m: re.Match[str]) -> str:
    target = m.group(2)
    return f"`{target.rsplit('.', 1)[-1] if m.group(1) else target}`"


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip())


def _fence_literal_blocks(lines: list[str]) -> list[str]:
    """``text::`` + indented block -> ``text:`` + fenced Python block; ``>>>`` runs fenced."""
    out: list[str] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        stripped = line.strip()
        if stripped.endswith("::") and not stripped.startswith(("-", "*", "|")):
            base = _indent(line)
            j = i + 1
            while j < len(lines) and not lines[j].strip():
                j += 1
            block: list[str] = []
            while j < len(lines) and (not lines[j].strip() or _indent(lines[j]) > base):
                block.append(lines[j])
                j += 1
            while block and not block[-1].strip():
                block.pop()
            if block:
                text = stripped[:-2].rstrip()
                if text:
                    out.append(" " * base + text + ":")
                deep = min(_indent(b) for b in block if b.strip())
                pad = " " * base
                out += ["", pad + "```python"] + [pad + b[deep:] for b in block] + [pad + "```", ""]
                i = j
                continue
        if stripped.startswith(">>>"):
            pad = " " * _indent(line)
            block = []
            while i < len(lines) and lines[i].strip().startswith((">>>", "...")):
                block.append(lines[i].strip())
                i += 1
            out += [pad + "```pycon"] + [pad + b for b in block] + [pad + "```"]
            continue
        out.append(line)
        i += 1
    return out


RST_BORDER = re.compile(r"^\s*=+( +=+)+\s*$")


def _rst_tables(lines: list[str]) -> list[str]:
    """Simple reStructuredText tables (``====  ====`` borders, a header row) -> Markdown."""
    out: list[str] = []
    i = 0
    while i < len(lines):
        if not RST_BORDER.match(lines[i]):
            out.append(lines[i])
            i += 1
            continue
        border = lines[i]
        starts = [m.start() for m in re.finditer(r"=+", border)]
        rows: list[list[str]] = []
        j = i + 1
        borders = 1
        while j < len(lines) and borders < 3:
            if RST_BORDER.match(lines[j]):
                borders += 1
            elif lines[j].strip():
                cells = [
                    lines[j][a:b].strip()
                    for a, b in zip(starts, starts[1:] + [len(lines[j])], strict=True)
                ]
                if lines[j][: starts[1]].strip() or not rows:
                    rows.append(cells)
                else:  # continuation line: its text belongs to the row above
                    rows[-1] = [f"{r} {c}".strip() for r, c in zip(rows[-1], cells, strict=True)]
            j += 1
        head, *body = rows
        out.append("| " + " | ".join(head) + " |")
        out.append("|" + "---|" * len(head))
        out += ["| " + " | ".join(c.replace("|", "\\|") for c in r) + " |" for r in body]
        i = j
    return out


def rst_to_markdown(text: str) -> str:
    text = RST_LINK.sub(r"[\1](\2)", ROLE.sub(_role, text))
    lines = text.split("\n")
    return "\n".join(_fence_literal_blocks(_rst_tables(lines)))


class RstToMarkdown(griffe.Extension):
    """Rewrites every docstring of the loaded package (mkdocstrings renders Markdown)."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = rst_to_markdown(obj.docstring.value)


class SimViews(griffe.Extension):
    """Shows the attributes ``name = _SimView[dtype]("...")`` of :class:`cdr_bench.VectorEnv`
    (live read-only views of the simulator's arrays) as the read-only properties they are, of
    type ``NDArray[dtype]``, instead of class attributes with that value."""

    def on_attribute_instance(self, *, attr: griffe.Attribute, **kwargs: Any) -> None:
        view = attr.value
        if isinstance(view, griffe.ExprCall) and isinstance(view.function, griffe.ExprSubscript):
            if str(view.function.left) == "_SimView":
                attr.annotation = griffe.ExprSubscript(
                    griffe.ExprName("NDArray", parent=attr), view.function.slice
                )
                attr.labels = {"property"}
                attr.value = None


# -- generated page parts --------------------------------------------------------------------------


def env_card() -> str:
    from cdr_bench.docs import env_card as card

    return rst_to_markdown(re.sub(r"^#### ", "## ", card(), flags=re.MULTILINE))


def gymnasium_tasks() -> str:
    from cdr_bench import GYMNASIUM_TASKS

    rows = ["| id | scenario | `max_episode_steps` |", "|---|---|---:|"]
    for task_id, kwargs, steps in GYMNASIUM_TASKS:
        scenario = f"`{kwargs['scenario']}`" if "scenario" in kwargs else "any: `scenario=...`"
        rows.append(f"| `{task_id}` | {scenario} | {steps if steps else 'the scenario horizon'} |")
    return "\n".join(rows)


MD_LINK = re.compile(r"(!?)\[([^\]]*)\]\(([^)\s]+)\)")


def _relink(text: str, source: str, page: str) -> str:
    """Links of ``text`` (from the repository file ``source``) made relative to the site page
    ``page``; a link to a file the site does not hold becomes its path in code font."""
    site_of = {repo: site for site, repo in LEADERBOARD_FILES.items()}

    def fix(m: re.Match[str]) -> str:
        bang, label, target = m.groups()
        if re.match(r"^[a-z][a-z0-9+.-]*:|^#", target):
            return m.group(0)
        path, _, anchor = target.partition("#")
        repo = posixpath.normpath(posixpath.join(posixpath.dirname(source), path))
        site = repo[len("docs/") :] if repo.startswith("docs/") else site_of.get(repo)
        if site is None:
            return f"`{repo}`" if label in (path, repo, f"`{path}`") else f"{label} (`{repo}`)"
        rel = posixpath.relpath(site, posixpath.dirname(page) or ".")
        return f"{bang}[{label}]({rel}{'#' + anchor if anchor else ''})"

    return _escape_brackets(MD_LINK.sub(fix, text))


CODE_SPAN = re.compile(r"(`+)(?:[^`\n]|\n(?![ \t]*\n))*?\1")  # may wrap, not across paragraphs
NOT_A_LINK = re.compile(r"(?<![\\!])\[([^\[\]]*)\](?!\()")


def _escape_prose(text: str) -> str:
    parts, last = [], 0
    for m in CODE_SPAN.finditer(text):
        parts += [NOT_A_LINK.sub(r"\\[\1\\]", text[last : m.start()]), m.group(0)]
        last = m.end()
    return "".join(parts) + NOT_A_LINK.sub(r"\\[\1\\]", text[last:])


def _escape_brackets(text: str) -> str:
    """Brackets that are not a link, outside code, escaped: ``[lo, hi] [0, 360]`` is prose on
    GitHub, but Markdown (and mkdocs-autorefs) would read it as a reference link."""
    chunks, prose, fenced = [], [], False
    for line in text.split("\n"):
        if line.lstrip().startswith("```"):
            if not fenced:
                chunks.append(_escape_prose("\n".join(prose)))
                prose = []
            fenced = not fenced
            chunks.append(line)
        elif fenced:
            chunks.append(line)
        else:
            prose.append(line)
    if prose:
        chunks.append(_escape_prose("\n".join(prose)))
    return "\n".join(chunks)


def _sections(path: str) -> tuple[list[str], list[tuple[int, int, str]]]:
    lines = (REPO / path).read_text(encoding="utf-8").split("\n")
    heads, fenced = [], False
    for i, line in enumerate(lines):
        if line.startswith("```"):
            fenced = not fenced
        m = None if fenced else re.match(r"^(#+) (.*)$", line)
        if m:
            heads.append((i, len(m.group(1)), m.group(2).strip()))
    return lines, heads


def section(path: str, heading: str) -> str:
    """The body of the section ``heading`` of a Markdown file of the repository (up to the next
    heading of the same or a higher level)."""
    lines, heads = _sections(path)
    for k, (i, level, text) in enumerate(heads):
        if text == heading:
            end = next((j for j, lv, _ in heads[k + 1 :] if lv <= level), len(lines))
            return "\n".join(lines[i + 1 : end]).strip()
    raise ValueError(f"{path} has no heading {heading!r}")


def intro(path: str) -> str:
    """The text of a Markdown file between its title and its first section."""
    lines, heads = _sections(path)
    if len(heads) < 2 or heads[0][1] != 1:
        raise ValueError(f"{path}: expected a title and a section")
    return "\n".join(lines[heads[0][0] + 1 : heads[1][0]]).strip()


def scenario_fields() -> str:
    from cdr_bench.docs import scenario_fields as fields

    return _escape_brackets(fields())  # ranges such as [0.0, 360.0] are not links


GENERATORS = {
    "env-card": env_card,
    "gymnasium-tasks": gymnasium_tasks,
    "scenario-fields": scenario_fields,
}
INCLUDES = {"section": section, "intro": intro}


END = "<!-- cdr-bench: end -->"
PAIR = re.compile(
    r"^<!-- cdr-bench: (?!end -->)([^\n]+?) -->\n(?:(.*?)\n)?<!-- cdr-bench: end -->$",
    flags=re.MULTILINE | re.DOTALL,
)


def _split(directive: str, page: str) -> tuple[str, list[str]]:
    name, *args = shlex.split(directive)
    if name not in GENERATORS and name not in INCLUDES:
        known = sorted(GENERATORS) + sorted(INCLUDES)
        raise ValueError(f"{page}: unknown directive {directive!r} (known: {known})")
    return name, args


def _expand(m: re.Match[str], page: str) -> str:
    """The site's text for one directive (with or without its end marker)."""
    name, args = _split(m.group(1), page)
    if name in GENERATORS:
        return GENERATORS[name](*args)
    return _relink(INCLUDES[name](*args), args[0], page)


def github_slug(heading: str) -> str:
    """The anchor GitHub gives a heading (lower case, punctuation dropped, spaces to dashes)."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def repository_text(directive: str, page: str) -> str:
    """What a reader of the page in the repository sees for one directive: the generated text
    itself, or a link to the included part (``page`` is relative to ``docs/``)."""
    name, args = _split(directive, page)
    if name in GENERATORS:
        return GENERATORS[name](*args)
    source = args[0]
    INCLUDES[name](*args)  # the file and heading exist
    link = posixpath.relpath(source, posixpath.dirname(posixpath.join("docs", page)))
    if name == "intro":
        return f"*The introduction of [{source}]({link}), shown here on the documentation site.*"
    anchor = f"{link}#{github_slug(args[1])}"
    return f'*Section "{args[1]}" of [{source}]({anchor}), shown here on the documentation site.*'


NOT_RUN = re.compile(r"^\s*<!-- not run:.*-->\s*$")


def _drop_not_run_markers(text: str) -> str:
    """The ``<!-- not run: ... -->`` lines above code blocks (tests/test_doc_blocks.py) are for
    the repository's readers and tests; inside a list item, Python-Markdown would end the list
    at them."""
    out, fenced = [], False
    for line in text.split("\n"):
        if re.match(r"^\s*(```|~~~)", line):
            fenced = not fenced
        if fenced or not NOT_RUN.match(line):
            out.append(line)
    return "\n".join(out)


def page_markdown(markdown: str, page: str) -> str:
    """A page as the site shows it: every directive (and what lies up to its end marker)
    replaced by its generated or included text, and no not-run markers."""
    text = PAIR.sub(lambda m: _expand(m, page), markdown)
    if re.search(rf"^{re.escape(END)}$", text, flags=re.MULTILINE):
        raise ValueError(f"{page}: {END} without a directive before it")
    return _drop_not_run_markers(DIRECTIVE.sub(lambda m: _expand(m, page), text))


def repository_markdown(markdown: str, page: str) -> str:
    """A page as it should be committed: every directive closed by its end marker, with the
    current repository text between them."""

    def fill(m: re.Match[str]) -> str:
        text = repository_text(m.group(1), page)
        return f"<!-- cdr-bench: {m.group(1)} -->\n\n{text}\n\n{END}"

    text = PAIR.sub(fill, markdown)
    parts = re.split(
        r"(^<!-- cdr-bench: [^\n]+? -->\n.*?^<!-- cdr-bench: end -->$)",
        text,
        flags=re.MULTILINE | re.DOTALL,
    )
    for i in range(0, len(parts), 2):  # outside the pairs: lone directives get their end
        parts[i] = DIRECTIVE.sub(fill, parts[i])
    return "".join(parts)


def stale_pages(docs: Path = REPO / "docs") -> list[str]:
    """Pages under ``docs`` whose committed generated parts are not what the code gives now."""
    stale = []
    for path in sorted(docs.rglob("*.md")):
        page = path.relative_to(docs).as_posix()
        text = path.read_text(encoding="utf-8")
        if repository_markdown(text, page) != text:
            stale.append(page)
    return stale


def on_page_markdown(markdown: str, page: Any, **kwargs: Any) -> str:
    return page_markdown(markdown, page.file.src_uri)


def on_files(files: Any, config: Any) -> Any:
    from mkdocs.structure.files import File

    entries = dict(LEADERBOARD_FILES)
    for png in sorted((REPO / "leaderboard" / "plots").glob("*.png")):
        entries[f"leaderboard/plots/{png.name}"] = f"leaderboard/plots/{png.name}"
    for site_path, repo_path in entries.items():
        files.append(File.generated(config, site_path, abs_src_path=str(REPO / repo_path)))
    return files


def main(argv: list[str] | None = None) -> int:
    import argparse

    p = argparse.ArgumentParser(
        description="Rewrite the generated parts of the pages under docs/ (between "
        "'<!-- cdr-bench: NAME -->' and '<!-- cdr-bench: end -->') from the code."
    )
    p.add_argument("--check", action="store_true", help="only list stale pages (exit code 1)")
    a = p.parse_args(argv)
    if a.check:
        stale = stale_pages()
        for page in stale:
            print(f"stale: docs/{page} (run: python docs/_hooks.py)")
        return 1 if stale else 0
    docs = REPO / "docs"
    for path in sorted(docs.rglob("*.md")):
        text = path.read_text(encoding="utf-8")
        new = repository_markdown(text, path.relative_to(docs).as_posix())
        if new != text:
            path.write_text(new, encoding="utf-8")
            print(f"wrote {path.relative_to(REPO)}")
    return 0


if __name__ == "__main__":
    import sys

    sys.path.insert(0, str(REPO))
    sys.exit(main())
