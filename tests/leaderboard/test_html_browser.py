"""``index.html`` opened in headless Chromium: the script runs, every table renders with its rows,
sorting by a column (requested through the URL fragment) reorders the rows, the group filter
hides the unticked groups, and a screenshot shows a page that is not blank with every replay
canvas drawn (the page marks each canvas it drew and where it sits; its pixels are checked)."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
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
        self.raw = ""
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


WIDTH = 1400


def chromium(page: Path, fragment: str, *args: str) -> str:
    assert CHROMIUM is not None
    r = subprocess.run(
        [
            CHROMIUM,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-dev-shm-usage",
            "--hide-scrollbars",
            "--force-device-scale-factor=1",
            f"--user-data-dir={page.parent / '.chromium-profile'}",
            "--virtual-time-budget=5000",
            *args,
            page.as_uri() + fragment,
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    return r.stdout


def dump_dom(page: Path, fragment: str = "") -> Tables:
    parser = Tables()
    parser.raw = chromium(page, fragment, f"--window-size={WIDTH},900", "--dump-dom")
    parser.feed(parser.raw)
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


def test_group_filter_hides_unticked_groups(repo: Path) -> None:
    page = repo / "leaderboard" / "index.html"
    data = json.loads((repo / "leaderboard" / "leaderboard.json").read_text())
    groups = {e["name"]: e["group"] for e in data["entries"]}
    assert sorted(groups.values()) == ["learned", "scripted"]
    dom = dump_dom(page)
    assert dom.body.get("data-hidden") == "0"
    dom = dump_dom(page, "#groups=learned")
    assert dom.body.get("data-groups-shown") == "learned"
    rows = re.findall(r'<tr data-group="(\w+)"( hidden="")?>', dom.raw)
    assert rows and all(bool(h) == (g != "learned") for g, h in rows)
    assert {g for g, h in rows if h} == {"scripted"}
    # the paper's numbers are a group too: hidden with it, shown otherwise
    sections = re.findall(r'<section data-group="published"( hidden="")?>', dom.raw)
    assert sections and all(sections)
    assert int(dom.body.get("data-hidden") or 0) == sum(1 for _, h in rows if h) + len(
        sections
    ) + sum(1 for g in re.findall(r'<figure data-group="(\w+)" hidden=""', dom.raw))


def test_screenshot_is_not_blank_and_every_replay_draws(repo: Path, tmp_path: Path) -> None:
    from PIL import Image

    page = repo / "leaderboard" / "index.html"
    data = json.loads((repo / "leaderboard" / "leaderboard.json").read_text())
    rp = data["replays"]
    traces = {
        e: json.loads((repo / "leaderboard" / rp["files"][e]).read_text())["traces"]
        for e in rp["entries"]
    }
    n_canvases = sum(1 for sid in rp["scenarios"] for e in rp["entries"] if sid in traces[e])
    assert n_canvases == 4  # two entries side by side on two scenarios
    dom = dump_dom(page)
    assert dom.body.get("data-replay-drawn") == str(n_canvases)
    rects = [
        tuple(int(v) for v in m.split(","))
        for m in re.findall(r'<canvas [^>]*data-rect="([0-9,]+)"', dom.raw)
    ]
    assert len(rects) == n_canvases
    assert all(320 <= w <= 324 and 320 <= h <= 324 for _, _, w, h in rects), rects
    height = max(y + h for _, y, _, h in rects) + 20
    shot = tmp_path / "page.png"
    chromium(page, "", f"--window-size={WIDTH},{height}", f"--screenshot={shot}")
    img = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    assert img.shape == (height, WIDTH, 3)
    # not blank: the top of the page (conclusion, ranking) has dark text on white
    dark = int((img[:600].sum(axis=2) < 200).sum())
    assert dark > 2000, f"only {dark} dark pixels at the top of the page: blank?"
    level = np.array([(0, 114, 178), (230, 159, 0), (0, 158, 115)])  # Okabe-Ito level colours
    for x, y, w, h in rects:
        pane = img[y + 2 : y + h - 2, x + 2 : x + w - 2]
        drawn = int((pane != 255).any(axis=2).sum())
        assert drawn > 500, f"replay canvas at {x},{y} is (nearly) empty: {drawn} pixels"
        # the ownship and the traffic are drawn in their level colours
        hits = (pane[:, :, None, :] == level[None, None]).all(axis=3).sum()
        assert hits > 20, f"replay canvas at {x},{y}: no aircraft drawn in a level colour"
