"""``leaderboard/README.md`` and the self-contained ``leaderboard/index.html`` from the
leaderboard data (:func:`cdr_bench.leaderboard.data.build_data`) and the plots.

Both pages show the same tables: one per scenario (measured here, ranked), the entries, the
paper's published numbers in their own section, and "published vs measured here". The HTML page
has no external assets: CSS and the table-sorting script are inline, the plots are data URIs.
"""

from __future__ import annotations

import base64
import html
from dataclasses import dataclass
from typing import Any

from cdr_bench.leaderboard.data import COLUMNS
from cdr_bench.leaderboard.published import Published

HIGHER, LOWER = "▲", "▼"
GENERATOR = "cdr-bench leaderboard build"

INTRO = (
    "Every entry is a file in `submissions/`, scored by `cdr-bench evaluate` on identical "
    "episodes (episode i of a scenario has the same seed and traffic for every entry) in its "
    "own sandboxed process; the result files are in `results/`. Rates are per episode with 95 % "
    "Wilson intervals, means (steps of successful episodes, episode sums of the goal and safety "
    "rewards R_G / R_S) with 95 % bootstrap intervals. **Bold**: the best value of the column "
    "(not marked when every entry ties). {up} / {down}: significantly higher / lower than "
    "{ref} on the same episodes (95 % paired bootstrap interval of the difference excludes 0; "
    "`cdr-bench compare`). Rows are ranked by success rate, then LoS rate, then NMAC rate. "
    "Latency is the median / p99 time per decision in ms (batched calls, one thread) on the "
    "machine that last ran `build --evaluate`: it is machine-dependent and `--check` does not "
    "re-measure it."
)


@dataclass(frozen=True)
class Cell:
    text: str
    sort: float | str | None = None
    best: bool = False
    mark: str = ""


def _fmt_value(kind: str, v: float | None) -> str:
    if v is None:
        return "-"
    return f"{100 * v:.1f}%" if kind == "rate" else f"{v:.2f}"


def _fmt_ci(kind: str, m: dict[str, Any]) -> str:
    v = m["value"]
    if v is None:
        return "-"
    lo, hi = m["ci95"]
    if lo is None or hi is None:
        return _fmt_value(kind, v)
    if kind == "rate":
        return f"{100 * v:.1f}% [{100 * lo:.1f}, {100 * hi:.1f}]"
    return f"{v:.2f} [{lo:.2f}, {hi:.2f}]"


def _fmt_ms(x: float | None) -> str:
    return "-" if x is None else f"{x:.3g}"


def scenario_table(
    data: dict[str, Any], table: dict[str, Any]
) -> tuple[list[str], list[list[Cell]]]:
    names = {e["name"]: e["display_name"] for e in data["entries"]}
    head = ["#", "entry"] + [h for h, _, _, _ in COLUMNS] + ["latency ms med / p99"]
    rows = []
    for r in table["rows"]:
        ref = r["entry"] == data["reference"]
        row = [
            Cell(str(r["rank"]), r["rank"]),
            Cell(names[r["entry"]] + (" (reference)" if ref else ""), names[r["entry"]]),
        ]
        for _, key, kind, _ in COLUMNS:
            m = r["metrics"][key]
            vs = r["vs_reference"][key]
            mark = ""
            if isinstance(vs, dict) and vs["significant"]:
                mark = HIGHER if vs["direction"] == "higher" else LOWER
            row.append(Cell(_fmt_ci(kind, m), m["value"], r["entry"] in table["best"][key], mark))
        lat = r["latency_ms"]
        row.append(
            Cell(
                f"{_fmt_ms(lat['median'])} / {_fmt_ms(lat['p99'])}",
                lat["median"],
                r["entry"] in table["best"]["latency_ms"],
            )
        )
        rows.append(row)
    return head, rows


def entries_table(data: dict[str, Any]) -> tuple[list[str], list[list[Cell]]]:
    head = ["entry", "what", "agent", "checkpoint", "authors", "reference", "training", "sha256"]
    rows = []
    for e in data["entries"]:
        rows.append(
            [
                Cell(e["display_name"], e["display_name"]),
                Cell(e["description"]),
                Cell(f"`{e['agent']}`"),
                Cell(f"`{e['checkpoint']}`" if e["checkpoint"] else "-"),
                Cell(", ".join(e["authors"])),
                Cell(e["reference"]),
                Cell(f"`{e['training']}`" if e["training"] else "scripted (no training)"),
                Cell(f"`{e['agent_sha256'][:12]}`"),
            ]
        )
    return head, rows


def published_tables(pub: Published) -> list[tuple[str, list[str], list[list[Cell]]]]:
    out = []
    for table, cols, cite in (
        ("Table 2", pub.columns2, pub.citation2),
        ("Table 3", pub.columns3, pub.citation3),
    ):
        head = ["agent" if table == "Table 2" else "variant", "density", *cols]
        rows = [
            [Cell(r.row, r.row), Cell(r.density, r.density)]
            + [Cell(f"{r.values[c]:g}", r.values[c]) for c in cols]
            for r in pub.table(table)
        ]
        out.append((f"{table} — {cite}", head, rows))
    return out


def side_by_side_tables(data: dict[str, Any]) -> list[tuple[str, list[str], list[list[Cell]]]]:
    names = {e["name"]: e["display_name"] for e in data["entries"]}
    kinds = {key: kind for _, key, kind, _ in COLUMNS}
    by_entry: dict[str, list[dict[str, Any]]] = {}
    for block in data["published_vs_measured"]:
        by_entry.setdefault(block["entry"], []).append(block)
    out = []
    for entry, blocks in by_entry.items():
        head = ["metric"]
        for b in blocks:
            head += [f"{b['scenario']} published", f"{b['scenario']} measured here"]
        cols = [r["column"] for r in blocks[0]["rows"]]
        rows = []
        for i, col in enumerate(cols):
            row = [Cell(col)]
            for b in blocks:
                r = b["rows"][i]
                kind = kinds.get(r["metric"], "mean")
                pub = f"{r['published']:g}" + ("%" if kind == "rate" else "")
                row += [Cell(pub, r["published"]), Cell(_fmt_ci(kind, r["measured"]))]
            rows.append(row)
        title = (
            f"{names[entry]} — published as “{blocks[0]['published_as']}” ({blocks[0]['table']})"
        )
        out.append((title, head, rows))
    return out


# ----------------------------------------------------------------------------------------------
# Markdown


def _md_cell(c: Cell) -> str:
    t = c.text.replace("|", "\\|")
    if c.best and t != "-":
        t = f"**{t}**"
    return f"{t} {c.mark}" if c.mark else t


def md_table(head: list[str], rows: list[list[Cell]], numeric_from: int = 2) -> str:
    align = ["---" if i < numeric_from else "---:" for i in range(len(head))]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(align) + "|"]
    lines += ["| " + " | ".join(_md_cell(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def _anchor(sid: str) -> str:
    return "scenario-" + sid.replace("/", "-")


def render_markdown(data: dict[str, Any], pub: Published, plots: list[str]) -> str:
    ref = next(e["display_name"] for e in data["entries"] if e["name"] == data["reference"])
    out = [
        "# cdr-bench leaderboard",
        "",
        "Generated by `cdr-bench leaderboard build` from the submissions and result files in "
        "this folder; do not edit by hand (`cdr-bench leaderboard build --check` fails if this "
        "page differs from what the code produces). The same tables, sortable, with the plots: "
        "`index.html`. How to add an entry: CONTRIBUTING.md, “Add a leaderboard entry”.",
        "",
        INTRO.format(up=HIGHER, down=LOWER, ref=ref),
        "",
        "## Measured here",
        "",
    ]
    for t in data["tables"]:
        head, rows = scenario_table(data, t)
        out += [
            f"### {t['scenario']}",
            "",
            f"{t['description']} — {t['episodes']} episodes per entry.",
            "",
            md_table(head, rows),
            "",
        ]
    head, rows = entries_table(data)
    out += ["## Entries", "", md_table(head, rows, numeric_from=len(head)), ""]
    out += [
        "## Published numbers (the paper; not measured here)",
        "",
        "Transcribed verbatim in `published/` (rates in %, 1000 episodes per density in the "
        "paper, its own simulator: its episodes average ~300 steps where cdr-bench's physics "
        "gives tens). Claims, shown as published: never ranked with the tables above.",
        "",
    ]
    for title, head, rows in published_tables(pub):
        out += [f"### {title}", "", md_table(head, rows), ""]
    out += [
        "## Published vs measured here",
        "",
        "Entries that reproduce a row of the paper (`published_as` in their submission), the "
        "paper's number beside ours with its 95 % interval. Steps are not comparable across the "
        "two simulators (see above); the rewards only in sign and order.",
        "",
    ]
    sbs = side_by_side_tables(data)
    if not sbs:
        out += ["No entry names a published row yet.", ""]
    for title, head, rows in sbs:
        out += [f"### {title}", "", md_table(head, rows, numeric_from=1), ""]
    out += ["## Plots", ""]
    for p in plots:
        out += [f"![{p}](plots/{p})", ""]
    out += [
        "## Reproduce",
        "",
        "```bash",
        "cdr-bench leaderboard build --evaluate     # re-run every submission (sandboxed), "
        "then render",
        "cdr-bench leaderboard build                # render from the result files only",
        "cdr-bench leaderboard build --check        # re-run and compare with this folder",
        "```",
        "",
    ]
    return "\n".join(out)


# ----------------------------------------------------------------------------------------------
# HTML

_CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;margin:2rem auto;max-width:1400px;
padding:0 1rem;color:#1b1f24;line-height:1.45}
h1{margin-bottom:.2rem}h2{margin-top:2.2rem;border-bottom:1px solid #d0d7de;padding-bottom:.3rem}
table{border-collapse:collapse;margin:.6rem 0 1.2rem;font-size:.86rem}
th,td{border:1px solid #d0d7de;padding:.3rem .5rem;text-align:right;white-space:nowrap}
th:nth-child(-n+2),td:nth-child(-n+2){text-align:left}
th{background:#f6f8fa;position:sticky;top:0}
table.sortable th{cursor:pointer;user-select:none}
table.sortable th[aria-sort=ascending]::after{content:" \\25B2"}
table.sortable th[aria-sort=descending]::after{content:" \\25BC"}
td.best{font-weight:700;background:#dafbe1}
.mark{color:#6e7781;margin-left:.2rem}
.note{color:#57606a;max-width:75rem}
.published{background:#fff8c5}
img{max-width:100%;border:1px solid #d0d7de;margin:.4rem 0}
code{background:#f6f8fa;padding:0 .2rem}
nav a{margin-right:1rem}
.scroll{overflow-x:auto}
"""

_JS = """
(function(){
  function key(td){var v=td.getAttribute('data-sort');
    if(v===null||v===''){return null}var n=Number(v);return isNaN(n)?v.toLowerCase():n}
  function sortTable(table,col,dir){
    var body=table.tBodies[0],rows=Array.prototype.slice.call(body.rows);
    rows.sort(function(a,b){var x=key(a.cells[col]),y=key(b.cells[col]);
      if(x===null&&y===null){return 0}if(x===null){return 1}if(y===null){return -1}
      var c=x<y?-1:(x>y?1:0);return dir==='descending'?-c:c});
    rows.forEach(function(r){body.appendChild(r)});
    Array.prototype.forEach.call(table.tHead.rows[0].cells,function(th,i){
      if(i===col){th.setAttribute('aria-sort',dir)}else{th.removeAttribute('aria-sort')}});
  }
  var tables=document.querySelectorAll('table.sortable');
  Array.prototype.forEach.call(tables,function(table){
    Array.prototype.forEach.call(table.tHead.rows[0].cells,function(th,i){
      th.addEventListener('click',function(){
        sortTable(table,i,th.getAttribute('aria-sort')==='ascending'?'descending':'ascending')});
    });
  });
  var m=/^#sort=([^:]+):(\\d+):(ascending|descending)$/.exec(location.hash);
  if(m){var t=document.getElementById(m[1]);if(t){sortTable(t,Number(m[2]),m[3])}}
  document.body.setAttribute('data-sortable-tables',String(tables.length));
})();
"""


def _esc(s: str) -> str:
    return html.escape(s, quote=True)


def _inline_md(s: str) -> str:
    """Escape, then render `code` and **bold** (the only inline Markdown the pages use)."""
    parts = _esc(s).split("`")
    for i in range(1, len(parts), 2):
        parts[i] = f"<code>{parts[i]}</code>"
    text = "".join(parts)
    bits = text.split("**")
    for i in range(1, len(bits), 2):
        bits[i] = f"<strong>{bits[i]}</strong>"
    return "".join(bits)


def html_table(tid: str, head: list[str], rows: list[list[Cell]], cls: str = "") -> str:
    out = [
        '<div class="scroll">',
        f'<table id="{_esc(tid)}" class="{_esc(("sortable " + cls).strip())}">',
    ]
    out.append("<thead><tr>" + "".join(f"<th>{_esc(h)}</th>" for h in head) + "</tr></thead>")
    out.append("<tbody>")
    for r in rows:
        tds = []
        for c in r:
            attrs = ""
            if c.sort is not None:
                attrs += f' data-sort="{_esc(str(c.sort))}"'
            if c.best and c.text != "-":
                attrs += ' class="best"'
            mark = f'<span class="mark">{c.mark}</span>' if c.mark else ""
            tds.append(f"<td{attrs}>{_inline_md(c.text)}{mark}</td>")
        out.append("<tr>" + "".join(tds) + "</tr>")
    out.append("</tbody></table></div>")
    return "\n".join(out)


def render_html(
    data: dict[str, Any], pub: Published, plots: dict[str, bytes], matplotlib_version: str
) -> str:
    ref = next(e["display_name"] for e in data["entries"] if e["name"] == data["reference"])
    b: list[str] = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width,initial-scale=1">',
        f'<meta name="generator" content="{GENERATOR}; plots: matplotlib {matplotlib_version}">',
        "<title>cdr-bench leaderboard</title>",
        f"<style>{_CSS}</style></head><body>",
        "<h1>cdr-bench leaderboard</h1>",
        '<nav><a href="#measured">Measured here</a><a href="#entries">Entries</a>'
        '<a href="#published">Published (paper)</a><a href="#side-by-side">Published vs '
        'measured</a><a href="#plots">Plots</a></nav>',
        f'<p class="note">{_inline_md(INTRO.format(up=HIGHER, down=LOWER, ref=ref))} '
        "Click a column header to sort.</p>",
        '<h2 id="measured">Measured here</h2>',
    ]
    for t in data["tables"]:
        head, rows = scenario_table(data, t)
        b += [
            f'<h3 id="{_anchor(t["scenario"])}">{_esc(t["scenario"])}</h3>',
            f'<p class="note">{_esc(t["description"])} — {t["episodes"]} episodes per entry.</p>',
            html_table("table-" + _anchor(t["scenario"]), head, rows),
        ]
    head, rows = entries_table(data)
    b += ['<h2 id="entries">Entries</h2>', html_table("table-entries", head, rows)]
    b += [
        '<h2 id="published">Published numbers (the paper; not measured here)</h2>',
        '<p class="note">Transcribed verbatim (rates in %). Claims from the paper\'s own '
        "simulator, shown as published and never ranked with the measured tables.</p>",
    ]
    for i, (title, head, rows) in enumerate(published_tables(pub)):
        b += [
            f"<h3>{_esc(title)}</h3>",
            html_table(f"table-published-{i}", head, rows, "published"),
        ]
    b += [
        '<h2 id="side-by-side">Published vs measured here</h2>',
        '<p class="note">The paper\'s number beside ours with its 95 % interval. Steps are '
        "not comparable across the two simulators.</p>",
    ]
    sbs = side_by_side_tables(data)
    if not sbs:
        b.append("<p>No entry names a published row yet.</p>")
    for i, (title, head, rows) in enumerate(sbs):
        b += [f"<h3>{_esc(title)}</h3>", html_table(f"table-side-{i}", head, rows)]
    b.append('<h2 id="plots">Plots</h2>')
    for name, png in plots.items():
        uri = "data:image/png;base64," + base64.b64encode(png).decode("ascii")
        b.append(
            f'<figure><img alt="{_esc(name)}" src="{uri}"><figcaption>{_esc(name)}'
            "</figcaption></figure>"
        )
    b += [f"<script>{_JS}</script>", "</body></html>", ""]
    return "\n".join(b)
