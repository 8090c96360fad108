"""Hostile text in submissions: the pages render data, never markup, and submission files are
read as defensively as scenario files.

* Load time: a display name with markup, a description over several lines (a forged heading,
  table and links), a script URL, invisible characters, a look-alike (``ΜVP`` with a Greek
  capital Mu beside ``MVP``) or a duplicate name, an alias bomb, duplicate keys, a 60 MB
  description, a file that is not UTF-8: each is one error naming the file and the field.
* Render time (the validation bypassed, the committed leaderboard data with the ``mvp`` entry's
  text replaced): ``leaderboard/README.md`` and ``index.html`` show the hostile text literally;
  opened in headless Chromium (the HTML page, and the README as the docs site's Markdown
  renders it), nothing of it runs.
"""

from __future__ import annotations

import html
import json
import re
import time
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import pytest

from cdr_bench.errors import UserError
from cdr_bench.leaderboard.published import load_published
from cdr_bench.leaderboard.render import render_html, render_markdown
from cdr_bench.leaderboard.submission import SubmissionError, load_submission, load_submissions
from cdr_bench.leaderboard.text import md_text, skeleton
from tests.leaderboard.conftest import ROOT, cdr, make_repo, submission_yaml
from tests.leaderboard.test_html_browser import CHROMIUM, chromium

LB = ROOT / "leaderboard"
PWN = "document.body.setAttribute('data-pwned','{}')"
SCRIPT_NAME = f"<script>{PWN.format('script')}</script>"
IMG_NAME = f'<img src=x onerror="{PWN.format("img")}">'
DESCRIPTION = (
    f'honest <img src=x onerror="{PWN.format("desc")}"> **bold** _em_ [click](https://evil.test/) '
    '![pixel](https://evil.test/p.png) `code` a \\| b {: onclick="alert(1)" } &amp; ~~s~~ '
    "<b>raw</b> $x$ <!-- c -->"
)
"""Passes validation (one line, no script URL): everything in it must render as text."""
FORGED = (
    "fine\n\n# Forged heading\n\n| a | b |\n|---|---|\n| x | y |\n\n"
    "![remote](https://evil.test/track.png) [run](javascript:alert(1))"
)
"""The description of the review: newlines that add a heading, a table, an image and a link."""

GOOD = submission_yaml("agents/direct/agent.py")


@pytest.fixture
def lb(tmp_path: Path) -> Path:
    return make_repo(tmp_path)


def write(lb: Path, text: str | bytes, name: str = "entry") -> Path:
    p = lb / "submissions" / f"{name}.yaml"
    if isinstance(text, bytes):
        p.write_bytes(text)
    else:
        p.write_text(text, encoding="utf-8")
    return p


def one_line_error(lb: Path, path: Path) -> str:
    """The error of loading ``path``: a SubmissionError of one line naming the file."""
    with pytest.raises(SubmissionError) as e:
        load_submission(path, lb.parent, load_published(lb).names)
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(f"{path}: "), msg
    assert len(msg) < 600, msg[:300]
    return msg


# ----------------------------------------------------------------------------------------------
# Load time: free text


TEXT_CASES = {
    "script name": ("display_name", SCRIPT_NAME, "letters, digits"),
    "img name": ("display_name", IMG_NAME, "letters, digits"),
    "forged description": ("description", FORGED, "one line"),
    "script link": ("description", "see [run](javascript:alert(1))", "script URL"),
    "data url": ("description", "![x](data:image/svg+xml,<svg onload=alert(1)>)", "script URL"),
    "bidi override": ("display_name", "MVP\u202e", "invisible character U+202E"),
    "zero width": ("display_name", "M\u200bVP", "invisible character U+200B"),
    "long name": ("display_name", "A" * 65, "at most 64 characters"),
    "long description": ("description", "a" * 401, "at most 400 characters"),
    "name with pipe": ("display_name", "MVP | 99 %", "letters, digits"),
    "name from punctuation": ("display_name", "-MVP", "starts with a letter or a digit"),
    "author over lines": ("authors", ["ok", "a\n# b"], "one line"),
    "reference url": ("reference", "https://evil.test/a b", "http(s) URL"),
    "reference scheme": ("reference", "javascript:alert(1)", "script URL"),
    "training backtick": ("training", "python t.py ` <img>", "backtick"),
    "forged trained_on": ("trained_on", FORGED, "one line"),
    "trained_on link": ("trained_on", "see [run](javascript:alert(1))", "script URL"),
}


@pytest.mark.parametrize("case", sorted(TEXT_CASES))
def test_hostile_text_is_refused_at_load_time(lb: Path, case: str) -> None:
    field, value, what = TEXT_CASES[case]
    text = "".join(ln + "\n" for ln in GOOD.splitlines() if not ln.startswith(f"{field}:"))
    p = write(lb, text + f"{field}: {json.dumps(value)}\n")
    msg = one_line_error(lb, p)
    assert f": {field}" in msg and what in msg, msg


def test_every_text_problem_of_a_file_is_reported_at_once(lb: Path) -> None:
    p = write(
        lb,
        GOOD
        + f"display_name: {json.dumps(SCRIPT_NAME)}\ndescription: {json.dumps(FORGED)}\n"
        + "colour: red\n",
    )
    with pytest.raises(SubmissionError) as e:
        load_submission(p, lb.parent)
    fields = [f for f, _ in e.value.problems]
    assert fields == ["colour", "display_name", "description"], fields
    assert str(e.value).splitlines()[0] == f"{p}: 3 errors:"


def test_the_injection_description_passes_validation(lb: Path) -> None:
    s = load_submission(write(lb, GOOD + f"description: {json.dumps(DESCRIPTION)}\n"), lb.parent)
    assert s.description == DESCRIPTION


# ----------------------------------------------------------------------------------------------
# Load time: look-alike and duplicate names


@pytest.mark.parametrize(
    "name",
    [
        "Weave",  # the same
        "weave",  # case
        "Ｗｅａｖｅ",  # full-width (NFKC)
        "Wеave",  # Cyrillic e
        "WEAVE",
        "Wéave",  # an accent
    ],
)
def test_a_name_that_looks_like_another_entrys_is_refused(lb: Path, name: str) -> None:
    p = write(lb, GOOD + f"display_name: {json.dumps(name)}\n", "zz-impostor")
    with pytest.raises(UserError) as e:
        load_submissions(lb, load_published(lb).names)
    msg = str(e.value)
    assert "\n" not in msg
    assert msg.startswith(f"{p}: display_name: "), msg
    assert "/weave.yaml" in msg
    assert ("the same as" if name == "Weave" else "looks like") in msg


def test_greek_mvp_beside_mvp_and_a_second_mvp_are_refused(lb: Path) -> None:
    write(lb, GOOD + "display_name: MVP\n", "mvp")
    write(lb, GOOD + "display_name: ΜVP\n", "x-greek")  # Greek capital Mu
    write(lb, GOOD + "display_name: MVP\n", "y-second")
    with pytest.raises(UserError) as e:
        load_submissions(lb, load_published(lb).names)
    lines = str(e.value).splitlines()
    assert len(lines) == 2, lines  # both impostors, each on its line
    assert any("x-greek.yaml: display_name: 'ΜVP' looks like 'MVP'" in ln for ln in lines), lines
    assert any("y-second.yaml: display_name: 'MVP' the same as 'MVP'" in ln for ln in lines)


def test_skeleton_folds_scripts_case_width_and_look_alike_digits() -> None:
    assert skeleton("ΜVP") == skeleton("MVP") == skeleton("mvp") == skeleton("МVР")
    assert skeleton("Safe-DQN-I") == skeleton("Safe-DQN-l") == skeleton("Safe-DQN-1")
    assert skeleton("PPO") == skeleton("PP0") == skeleton("ＰＰＯ")
    assert skeleton("MVP") != skeleton("MVPs")
    names = [s.display_name for s in load_submissions(LB, load_published(LB).names)]
    assert len({skeleton(n) for n in names}) == len(names)  # the committed entries differ


def test_every_file_with_an_error_is_named_at_once(lb: Path) -> None:
    a = write(lb, GOOD + "display_name: '<b>'\n", "a")
    b = write(lb, GOOD + "agent: agents/direct/agent.py\n", "b")
    with pytest.raises(UserError) as e:
        load_submissions(lb)
    msg = str(e.value)
    assert f"{a}: display_name" in msg and f"{b}: " in msg and "duplicate key" in msg


# ----------------------------------------------------------------------------------------------
# Load time: the file itself (the scenario files' hardened reader)


def alias_bomb() -> str:
    lines = ['a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    lines += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]" for i in range(1, 10)]
    return GOOD + "\n".join(lines) + "\ndescription: *a9\n"


FILE_CASES: dict[str, tuple[Any, str]] = {
    "alias bomb": (alias_bomb, "anchors (&name) are not allowed in submission files"),
    "alias only": (lambda: GOOD + "description: *x\n", "not valid YAML"),
    "duplicate agent": (
        lambda: GOOD + "agent: agents/weave/agent.py\n",
        "duplicate key 'agent' (first given on line 1)",
    ),
    "60 MB description": (
        lambda: GOOD + "description: " + "x" * (60 << 20) + "\n",
        "file larger than 1024 KiB",
    ),
    "not utf-8": (
        lambda: (GOOD + "description: caf\xe9\n").encode("latin-1"),
        "not UTF-8 text (byte 0xe9",
    ),
    "nested": (lambda: GOOD + "description: " + "[" * 200 + "]" * 200 + "\n", "nested more"),
    "nul bytes": (lambda: GOOD.encode() + b"description: a\x00b\n", "binary file"),
    "tag": (lambda: GOOD + "description: !!python/object:os.system x\n", "tags"),
}


@pytest.mark.parametrize("case", sorted(FILE_CASES))
def test_hostile_file_is_a_one_line_error_in_bounded_time(lb: Path, case: str) -> None:
    make, what = FILE_CASES[case]
    p = write(lb, make())
    t0 = time.monotonic()
    msg = one_line_error(lb, p)
    assert time.monotonic() - t0 < 5
    assert what in msg, msg


def test_cli_names_a_hostile_file_in_one_line(lb: Path) -> None:
    write(lb, alias_bomb(), "bomb")
    r = cdr("leaderboard", "build", cwd=lb.parent, timeout=120)
    assert r.returncode == 2, r.stderr[-2000:]
    assert "Traceback" not in r.stderr
    assert r.stderr.strip().count("\n") == 0, r.stderr[-2000:]
    assert "bomb.yaml" in r.stderr and "not allowed in submission files" in r.stderr


# ----------------------------------------------------------------------------------------------
# Render time: the committed leaderboard data with hostile text (validation bypassed)


def hostile_data(name: str, description: str) -> dict[str, Any]:
    data = json.loads((LB / "leaderboard.json").read_text(encoding="utf-8"))
    (mvp,) = [e for e in data["entries"] if e["name"] == "mvp"]
    mvp.update(
        display_name=name,
        description=description,
        authors=[f"<b>{name}</b>", "x_y_"],
        reference="https://evil.test/?a=<script>",
        training=None,
    )
    return data


def pages(data: dict[str, Any]) -> tuple[str, str]:
    """(README.md, index.html) rendered from ``data`` (the replays read where committed)."""
    pub = load_published(LB)
    replays = {}
    for n in data["replays"]["entries"]:
        replays[n] = json.loads((LB / "results" / f"{n}.replays.json").read_text())
    return render_markdown(data, pub, []), render_html(data, pub, {}, "test", replays)


class Page(HTMLParser):
    """Tags, attributes and the text of every table cell of an HTML page."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.tags: list[tuple[str, dict[str, str | None]]] = []
        self.cells: list[str] = []
        self._cell: list[str] | None = None

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append((tag, dict(attrs)))
        if tag in ("td", "th"):
            self._cell = []

    def handle_endtag(self, tag: str) -> None:
        if tag in ("td", "th") and self._cell is not None:
            self.cells.append("".join(self._cell))
            self._cell = None

    def handle_data(self, data: str) -> None:
        if self._cell is not None:
            self._cell.append(data)


def parse(text: str) -> Page:
    p = Page()
    p.feed(text)
    return p


def assert_inert(page: Page, *, scripts: int) -> None:
    """No handler attribute, no link, image, bold or script tag beyond the page's own."""
    for tag, attrs in page.tags:
        assert not [a for a in attrs if a.lower().startswith("on")], (tag, attrs)
        assert tag not in ("img", "b", "iframe"), (tag, attrs)
        assert tag != "a" or str(attrs.get("href")).startswith("#"), (tag, attrs)
        for v in attrs.values():
            assert "javascript:" not in (v or "").lower(), (tag, attrs)
    assert sum(t == "script" for t, _ in page.tags) == scripts


NAMES = [SCRIPT_NAME, IMG_NAME, "_Evil_ *name* [x](y) `z` \\ & ~ {: a}"]


@pytest.mark.parametrize("name", NAMES, ids=["script", "img", "markdown"])
def test_markdown_page_escapes_every_submitted_text(name: str) -> None:
    md, _ = pages(hostile_data(name, DESCRIPTION))
    for raw in ("<script", "<img", "<b>", "<!--"):
        assert raw not in md, raw
    assert not re.search(r"(?<!\\)\]\(https://evil|(?<!\\)\{: onclick", md)  # no link, no attr
    esc_name = md_text(name)
    assert f"**{esc_name}** " in md or f"Against {esc_name} " in md  # the conclusion
    # every row of the entries table has as many cells as its header
    table = md.split("## Entries", 1)[1].split("\n\n")[1].splitlines()
    cells = [len(re.findall(r"(?<!\\)\|", re.sub(r"\\\\", "", row))) for row in table]
    assert len(set(cells)) == 1, cells


def test_forged_description_stays_on_its_table_row() -> None:
    md, _ = pages(hostile_data("MVP", FORGED))
    assert not any(ln.startswith(("# Forged", "| a | b |", "![remote]")) for ln in md.splitlines())
    assert "\\[run\\](javascript:alert(1))" in md  # shown, not a link


@pytest.mark.parametrize("name", NAMES, ids=["script", "img", "markdown"])
def test_html_page_shows_every_submitted_text_literally(name: str) -> None:
    _, page = pages(hostile_data(name, DESCRIPTION))
    p = parse(page)
    assert_inert(p, scripts=2)  # the replay data and the page's own script
    assert name in p.cells and DESCRIPTION in p.cells, [c for c in p.cells if "honest" in c]
    assert f"<b>{name}</b>, x_y_" in p.cells
    assert f"P(better than {name})" in p.cells  # a header of the seeds table
    text = html.unescape(re.sub(r"<[^>]+>", "", page))
    assert f"{name} ranks first" in text or f"Against {name} " in text


def python_markdown(md: str) -> str:
    """README.md as the docs site's Markdown renders it (Python-Markdown with the extensions of
    mkdocs.yml that come with it)."""
    markdown = pytest.importorskip("markdown")
    return str(
        markdown.markdown(md, extensions=["tables", "attr_list", "md_in_html", "admonition", "toc"])
    )


@pytest.mark.parametrize("name", NAMES, ids=["script", "img", "markdown"])
def test_docs_site_markdown_renders_the_text_literally(name: str) -> None:
    md, _ = pages(hostile_data(name, DESCRIPTION))
    p = parse(python_markdown(md))
    for tag, attrs in p.tags:
        assert not [a for a in attrs if a.lower().startswith("on")], (tag, attrs)
        assert tag not in ("script", "iframe", "b"), (tag, attrs)
        assert not (tag == "img" and "evil" in str(attrs.get("src"))), attrs
        assert not (tag == "a" and "evil" in str(attrs.get("href"))), attrs
    assert name in p.cells and DESCRIPTION in p.cells, [c for c in p.cells if "honest" in c]
    assert f"<b>{name}</b>, x_y_" in p.cells
    assert "https://evil.test/?a=<script>" in p.cells


# ----------------------------------------------------------------------------------------------
# Headless Chromium: nothing runs

needs_chromium = pytest.mark.skipif(
    CHROMIUM is None,
    reason="headless Chromium not installed (apt-get install -y chromium)",
)


def dom(page: Path) -> str:
    """The page's DOM after its scripts ran (the browser tests' headless Chromium)."""
    return chromium(page, "", "--dump-dom")


def body_attrs(text: str) -> dict[str, str | None]:
    p = parse(text)
    return next(a for t, a in p.tags if t == "body")


@needs_chromium
def test_chromium_runs_nothing_of_the_injection_on_the_html_page(tmp_path: Path) -> None:
    for i, name in enumerate(NAMES[:2]):
        _, page = pages(hostile_data(name, DESCRIPTION))
        f = tmp_path / f"index-{i}.html"
        f.write_text(page, encoding="utf-8")
        body = body_attrs(dom(f))
        assert body.get("data-sortable-tables"), body  # the page's own script ran
        assert "data-pwned" not in body, body


@needs_chromium
def test_chromium_runs_nothing_of_the_injection_on_the_docs_page(tmp_path: Path) -> None:
    for i, name in enumerate(NAMES[:2]):
        md, _ = pages(hostile_data(name, DESCRIPTION))
        f = tmp_path / f"results-{i}.html"
        f.write_text(
            "<!DOCTYPE html><html><head><meta charset='utf-8'></head><body>"
            f"{python_markdown(md)}<script>document.body.setAttribute('data-ran','1')</script>"
            "</body></html>",
            encoding="utf-8",
        )
        body = body_attrs(dom(f))
        assert body.get("data-ran") == "1", body
        assert "data-pwned" not in body, body
