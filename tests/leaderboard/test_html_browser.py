"""``index.html`` opened in headless Chromium: the script runs, every table renders with its rows,
and sorting by a column (requested through the URL fragment) reorders the rows."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import pytest

CHROMIUM = next(
    (shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)),
    None,
)

pytestmark = pytest.mark.skipif(
    CHROMIUM is None,
    reason="headless Chromium not installed (apt-get install -y chromium); the rendered-page "
    "test needs a real browser",
)


class Tables(HTMLParser):
    """Tables of a DOM dump: id -> list of rows (cell texts), and the body's attributes."""

    def __init__(self) -> None:
        super().__init__()
        self.tables: dict[str, list[list[str]]] = {}
        self.body: dict[str, str | None] = {}
        self._table: str | None = None
        self._row: list[str] | None = None
        self._cell: list[str] | None = None
        self._in_body = False

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if tag == "body":
            self.body = a
        elif tag == "table":
            self._table = a.get("id") or f"anon-{len(self.tables)}"
            self.tables[self._table] = []
        elif tag == "tbody":
            self._in_body = True
        elif tag == "tr" and self._in_body:
            self._row = []
        elif tag == "td" and self._row is not None:
            self._cell = []

    def handle_endtag(self, tag: str) -> None:
        if tag == "td" and self._row is not None and self._cell is not None:
            self._row.append("".join(self._cell).strip())
            self._cell = None
        elif tag == "tr" and self._row is not None and self._table is not None:
            self.tables[self._table].append(self._row)
            self._row = None
        elif tag == "tbody":
            self._in_body = False
        elif tag == "table":
            self._table = None

    def handle_data(self, data: str) -> None:
        if self._cell is not None:
            self._cell.append(data)


def dump_dom(page: Path, fragment: str = "") -> Tables:
    assert CHROMIUM is not None
    r = subprocess.run(
        [
            CHROMIUM,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-dev-shm-usage",
            f"--user-data-dir={page.parent / '.chromium-profile'}",
            "--virtual-time-budget=5000",
            "--dump-dom",
            page.as_uri() + fragment,
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    parser = Tables()
    parser.feed(r.stdout)
    return parser


def test_page_renders_its_tables_and_sorts(repo: Path) -> None:
    lb = repo / "leaderboard"
    data = json.loads((lb / "leaderboard.json").read_text())
    page = lb / "index.html"
    dom = dump_dom(page)
    n_tables = len(re.findall(r"<table ", page.read_text()))
    # the inline script ran and wired every table
    assert dom.body.get("data-sortable-tables") == str(n_tables)
    assert len(dom.tables) == n_tables
    for t in data["tables"]:
        tid = "table-scenario-" + t["scenario"].replace("/", "-")
        rows = dom.tables[tid]
        assert len(rows) == len(t["rows"])
        assert [r[1].replace(" (reference)", "") for r in rows] == [
            next(e["display_name"] for e in data["entries"] if e["name"] == row["entry"])
            for row in t["rows"]
        ]
    assert len(dom.tables["table-published-0"]) == 15  # Table 2: five agents x three densities

    # sort the low table by the LoS column (index 3), ascending then descending
    los = [r["metrics"]["los_rate"]["value"] for r in data["tables"][0]["rows"]]
    for direction, rev in (("ascending", False), ("descending", True)):
        dom = dump_dom(page, f"#sort=table-scenario-low:3:{direction}")
        shown = [float(r[3].split("%")[0]) for r in dom.tables["table-scenario-low"]]
        assert shown == sorted((round(100 * v, 1) for v in los), reverse=rev)
