"""Every results table of cdr-bench, with one column list (:data:`COLUMNS`: the metric registry
of :mod:`cdr_bench.evaluate.metrics`) and one set of number formats. Pure functions of result
data (this module reads no file and evaluates nothing):

* the summary printed by ``cdr-bench evaluate`` and the Markdown of ``cdr-bench report``;
* the leaderboard's tables (per scenario, entries, published, published vs measured), laid out
  into ``leaderboard/README.md`` and ``index.html`` by :mod:`cdr_bench.leaderboard.render`;
* the tables in the marked blocks of ``README.md``, ``agents/BASELINES.md`` and
  ``agents/diffusion_ac/README.md``, whose inputs (the leaderboard's result files, the paper's
  published tables, training, tuning and latency logs) :mod:`cdr_bench.leaderboard.tables`
  gathers (``cdr-bench leaderboard build`` / ``render-docs``).

It sits in the evaluator's layer so that ``cdr-bench evaluate`` and the leaderboard above it
share it; it imports nothing from the leaderboard or the trainers.
"""

from __future__ import annotations

import html
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from cdr_bench.actions import decode
from cdr_bench.evaluate.metrics import MAIN_METRICS, METRICS, Metric

Column = Metric
"""A column of the results tables is a registered metric (:class:`~cdr_bench.evaluate.metrics.
Metric`: ``header``, ``key``, ``kind`` (its number format: ``rate`` in %, ``mean``, ``per_h``),
``higher``, ``detail``, ``short``)."""

COLUMNS: Sequence[Column] = METRICS
"""The one column list, read from the metric registry at each use
(:data:`cdr_bench.evaluate.metrics.METRICS`): the paper's five metrics, clean success, the goal
and safety rewards, the share of masked (invalid) actions, two outcome details and the field
metrics (docs/model.md §10.1; per flight unless stated), then any metric added with
:func:`~cdr_bench.evaluate.metrics.register_metric`."""

MAIN_COLUMNS: Sequence[Column] = MAIN_METRICS
"""The columns of the leaderboard and of the documentation tables (the metrics that are not
detail columns)."""

DENSITIES = ("low", "medium", "high")
LATENCY_HEADER = "latency ms med / p99"


# ----------------------------------------------------------------------------------------------
# Formats


def fmt_value(kind: str, v: float | None) -> str:
    if v is None:
        return "-"
    if kind == "per_h":
        return f"{v:.3g}"
    return f"{100 * v:.1f}%" if kind == "rate" else f"{v:.2f}"


def fmt_metric(kind: str, m: dict[str, Any], ci: bool = True) -> str:
    """A measured metric ``{"value", "ci95"}``: point value, with its 95 % interval if ``ci``."""
    v = m.get("value")
    if v is None:
        return "-"
    lo, hi = m.get("ci95") or (None, None)
    if not ci or lo is None or hi is None:
        return fmt_value(kind, v)
    if kind == "rate":
        return f"{100 * v:.1f}% [{100 * lo:.1f}, {100 * hi:.1f}]"
    if kind == "per_h":
        return f"{v:.3g} [{lo:.3g}, {hi:.3g}]"
    return f"{v:.2f} [{lo:.2f}, {hi:.2f}]"


def fmt_published(kind: str, v: float | None) -> str:
    """A number of the paper as transcribed (rates are already in %)."""
    if v is None:
        return "-"
    return f"{v:g}%" if kind == "rate" else f"{v:g}"


def fmt_ms(x: float | None) -> str:
    return "-" if x is None else f"{x:.3g}"


def fmt_latency(lat: dict[str, Any] | None) -> str:
    if not lat or lat.get("median") is None:
        return "-"
    return f"{fmt_ms(lat['median'])} / {fmt_ms(lat.get('p99'))}"


# ----------------------------------------------------------------------------------------------
# Cells and table formats (Markdown, plain text, HTML)


@dataclass(frozen=True)
class Cell:
    text: str
    sort: float | str | None = None
    best: bool = False
    mark: str = ""


Rows = list[list[Cell]]


def _md_cell(c: Cell) -> str:
    t = c.text.replace("|", "\\|")
    if c.best and t != "-":
        t = f"**{t}**"
    return f"{t} {c.mark}" if c.mark else t


def md_table(
    head: Sequence[str], rows: Rows, numeric_from: int = 2, text_from: int | None = None
) -> str:
    """Markdown; columns from ``numeric_from`` on (up to ``text_from``) are right-aligned."""
    end = len(head) if text_from is None else text_from
    align = ["---:" if numeric_from <= i < end else "---" for i in range(len(head))]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(align) + "|"]
    lines += ["| " + " | ".join(_md_cell(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def text_table(head: Sequence[str], rows: Rows, numeric_from: int = 2) -> str:
    """Plain text, columns padded; columns from ``numeric_from`` on are right-aligned."""
    grid = [list(head)] + [[c.text for c in r] for r in rows]
    widths = [max(len(r[i]) for r in grid) for i in range(len(head))]

    def line(r: list[str]) -> str:
        return "  ".join(
            c.rjust(w) if i >= numeric_from else c.ljust(w)
            for i, (c, w) in enumerate(zip(r, widths, strict=True))
        ).rstrip()

    out = [line(grid[0]), "  ".join("-" * w for w in widths)]
    return "\n".join(out + [line(r) for r in grid[1:]])


def esc(s: str) -> str:
    """``s`` as HTML text or a quoted attribute value (``&``, ``<``, ``>`` and both quotes
    escaped): the one escape of every HTML page the benchmark writes."""
    return html.escape(s, quote=True)


def inline_md(s: str) -> str:
    """Escape, then render `code` and **bold** (the only inline Markdown the pages use)."""
    parts = esc(s).split("`")
    for i in range(1, len(parts), 2):
        parts[i] = f"<code>{parts[i]}</code>"
    text = "".join(parts)
    bits = text.split("**")
    for i in range(1, len(bits), 2):
        bits[i] = f"<strong>{bits[i]}</strong>"
    return "".join(bits)


def html_table(
    tid: str, head: Sequence[str], rows: Rows, cls: str = "", groups: Sequence[str] | None = None
) -> str:
    """A sortable HTML table (``data-sort`` keys; the page's script sorts on click); ``groups``:
    one per row, written as the row's ``data-group`` (the page's filter hides groups)."""
    out = [
        '<div class="scroll">',
        f'<table id="{esc(tid)}" class="{esc(("sortable " + cls).strip())}">',
    ]
    out.append("<thead><tr>" + "".join(f"<th>{esc(h)}</th>" for h in head) + "</tr></thead>")
    out.append("<tbody>")
    for i, r in enumerate(rows):
        tds = []
        for c in r:
            attrs = ""
            if c.sort is not None:
                attrs += f' data-sort="{esc(str(c.sort))}"'
            if c.best and c.text != "-":
                attrs += ' class="best"'
            mark = f'<span class="mark">{c.mark}</span>' if c.mark else ""
            tds.append(f"<td{attrs}>{inline_md(c.text)}{mark}</td>")
        tr = "<tr>" if groups is None else f'<tr data-group="{esc(groups[i])}">'
        out.append(tr + "".join(tds) + "</tr>")
    out.append("</tbody></table></div>")
    return "\n".join(out)


# ----------------------------------------------------------------------------------------------
# The leaderboard's tables (from the data of :func:`cdr_bench.leaderboard.data.build_data`)

HIGHER, LOWER = "▲", "▼"


def fmt_diff(kind: str, d: dict[str, Any] | None) -> str:
    """A paired difference ``{diff, ci95, significant}``: points (pp) for rates, with its 95 %
    interval; ``▲``/``▼`` when significant."""
    if d is None or d.get("diff") is None:
        return "-"
    scale, unit = (100.0, " pp") if kind == "rate" else (1.0, "")

    def f(x: float) -> str:
        return f"{round(scale * x, 1) + 0.0:+.1f}"  # + 0.0: no "-0.0"

    lo, hi = d["ci95"]
    ci = "" if lo is None or hi is None else f" [{f(lo)}, {f(hi)}]"
    mark = (f" {HIGHER}" if d["diff"] > 0 else f" {LOWER}") if d["significant"] else ""
    return f"{f(d['diff'])}{unit}{ci}{mark}"


def fmt_budget(b: dict[str, Any] | None) -> tuple[str, str]:
    """Training transitions and seeds of an entry (``-`` for a scripted or undeclared one)."""
    if not b or b.get("transitions") is None:
        return "-", "-"
    t = b["transitions"]
    text = f"{t:,}" if isinstance(t, int) else f"{t[0]:,}-{t[1]:,}"
    return text + (" (declared)" if b.get("source") == "declared" else ""), str(b["seeds"])


def _transitions(b: dict[str, Any] | None) -> int | None:
    t = (b or {}).get("transitions")
    return t if isinstance(t, int) or t is None else t[0]


def _kinds() -> dict[str, str]:
    return {c.key: c.kind for c in COLUMNS}


def _headers() -> dict[str, str]:
    return {c.key: c.header for c in COLUMNS}


def ranking_table(data: dict[str, Any]) -> tuple[list[str], Rows, list[str]]:
    """The headline ranking (``data["ranking"]``): rank, entry, group, the headline score with
    its interval, the paired gap to the row above, the tie-break, the paper's five metrics on
    the headline scenario, and the training budget. Returns (header, rows, group per row)."""
    rk = data["ranking"]
    ent = {e["name"]: e for e in data["entries"]}
    five = list(rk["rows"][0]["metrics"]) if rk["rows"] else []
    header, kind = _headers(), _kinds()
    head = [
        "#",
        "entry",
        "group",
        f"{header[rk['metric']]} ({rk['scenario']})",
        "vs row above",
        header[rk["tie_break"]],
        *[header[k] for k in five],
        "training transitions",
        "seeds",
    ]
    rows: Rows = []
    for r in rk["rows"]:
        e = ent[r["entry"]]
        tied = f" (tied with #{r['tied_with']})" if r.get("tied_with") else ""
        budget, seeds = fmt_budget(e["budget"])
        h, tb = r["headline"], r["tie_break"]
        rows.append(
            [
                Cell(f"{r['rank']}{tied}", r["rank"]),
                Cell(e["display_name"], e["display_name"]),
                Cell(e["group"], e["group"]),
                Cell(fmt_metric("rate", h), h["value"], r["rank"] == 1),
                Cell(fmt_diff("rate", r["vs_above"]), (r["vs_above"] or {}).get("diff")),
                Cell(fmt_metric("mean", tb), tb["value"]),
            ]
            + [
                Cell(fmt_value(kind[k], r["metrics"][k]["value"]), r["metrics"][k]["value"])
                for k in five
            ]
            + [
                Cell(budget, _transitions(e["budget"])),
                Cell(seeds, None if seeds == "-" else int(seeds)),
            ]
        )
    return head, rows, [ent[r["entry"]]["group"] for r in rk["rows"]]


def seeds_table(data: dict[str, Any]) -> tuple[list[str], Rows, list[str]]:
    """Aggregates over training seeds (``data["seeds"]``), entries in ranking order: the number
    of seeds, the headline score of each seed, its interquartile mean (IQM) with the
    stratified-bootstrap interval (none for one seed), the IQM over the tasks, and the
    probability of improvement over each comparator on those tasks."""
    sd = data["seeds"]
    ent = {e["name"]: e for e in data["entries"]}
    rank = {r["entry"]: r["rank"] for r in data["ranking"]["rows"]}
    label = {c: ent[c]["display_name"] for c in sd["comparators"]}
    sc = sd["scenario"]
    head = [
        "#",
        "entry",
        "seeds",
        f"clean success on {sc}, per seed",
        f"IQM over seeds ({sc})",
        f"IQM over seeds x {len(sd['tasks'])} scenarios",
        *[f"P(better than {label[c]})" for c in sd["comparators"]],
    ]

    def iv(m: dict[str, Any]) -> str:
        return fmt_metric("rate", {"value": m["iqm"], "ci95": m["ci95"]})

    rows: Rows = []
    for r in sd["rows"]:
        h, t = r["headline"], r["tasks"]
        per = " ".join(f"{100 * v:.1f}" for v in h["per_run"])
        row = [
            Cell(str(rank[r["entry"]]), rank[r["entry"]]),
            Cell(ent[r["entry"]]["display_name"], ent[r["entry"]]["display_name"]),
            Cell(str(h["runs"]), h["runs"]),
            Cell(per if h["runs"] > 1 else f"{per} (one run)", h["min"]),
            Cell(iv(h), h["iqm"]),
            Cell(iv(t), t["iqm"]),
        ]
        for c in sd["comparators"]:
            p = r["p_improvement"].get(c)
            if p is None:
                row.append(Cell("-"))
                continue
            lo, hi = p["ci95"] or (None, None)
            txt = f"{p['value']:.2f}" + ("" if lo is None else f" [{lo:.2f}, {hi:.2f}]")
            row.append(Cell(txt, p["value"]))
        rows.append(row)
    return head, rows, [ent[r["entry"]]["group"] for r in sd["rows"]]


def study_value(metric: str, x: float | None, sd: float | None = None) -> str:
    """A sensitivity-study number: a success rate in %, a reward as is; ``± sd`` if given."""
    if x is None:
        return "-"
    if metric == "success_rate":
        return f"{100 * x:.1f} %" + ("" if sd is None else f" ± {100 * sd:.1f}")
    return f"{x:.2f}" + ("" if sd is None else f" ± {sd:.2f}")


def sensitivity_table(data: dict[str, Any]) -> tuple[list[str], Rows]:
    """The sensitivity study (paper Fig. 7) beside the paper's numbers (``data["sensitivity"]``):
    one row per factor and grid value."""
    head = [
        "factor",
        "value",
        "paper's pick",
        "measured: mean ± sd over seeds",
        "seeds",
        "per seed",
        "paper (published)",
    ]
    rows: Rows = []
    for fac in (data.get("sensitivity") or {}).get("factors", []):
        m = fac["metric"]
        for p in fac["points"]:
            paper = p["paper"]
            rows.append(
                [
                    Cell(f"{fac['name']} ({'success' if m == 'success_rate' else 'reward'})"),
                    Cell(p["value"]),
                    Cell("yes" if p["recommended"] else ""),
                    Cell(study_value(m, p["mean"], p["sd"]), p["mean"]),
                    Cell(str(len(p["values"])), len(p["values"])),
                    Cell(", ".join(study_value(m, v) for v in p["values"]) or "-"),
                    Cell(
                        "-"
                        if paper is None
                        else (f"{paper:g} %" if m == "success_rate" else f"{paper:g}"),
                        paper,
                    ),
                ]
            )
    return head, rows


def claims_table(data: dict[str, Any]) -> tuple[list[str], Rows]:
    """The paper's claims beside our measurement and the verdict (``data["claims"]``)."""
    head = ["claim of the paper", "where", "published", "measured here", "verdict", "decided by"]
    rows: Rows = [
        [
            Cell(c["claim"]),
            Cell(c["source"]),
            Cell(c["published"]),
            Cell(c["measured"]),
            Cell(c["verdict"], c["verdict"], c["verdict"] == "held"),
            Cell(c["test"]),
        ]
        for c in data.get("claims", [])
    ]
    return head, rows


def tactical_table(data: dict[str, Any]) -> tuple[list[str], Rows, list[str]]:
    """Success per tactical scenario, entries in ranking order: a family's success rate with
    its 95 % interval, a fixed encounter's single outcome (``data["tactical"]``)."""
    ent = {e["name"]: e for e in data["entries"]}
    tac = data["tactical"]
    head = ["#", "entry"] + [
        f"{t['scenario']} ({'fixed' if t['fixed'] else 'family'})" for t in tac
    ]
    rows: Rows = []
    groups = []
    for r in data["ranking"]["rows"]:
        row = [Cell(str(r["rank"]), r["rank"]), Cell(ent[r["entry"]]["display_name"])]
        for t in tac:
            c = t["cells"].get(r["entry"])
            if c is None:
                row.append(Cell("-"))
            elif c["kind"] == "rate":
                row.append(Cell(fmt_metric("rate", c), c["value"]))
            else:
                row.append(Cell(c["text"], c["text"]))
        rows.append(row)
        groups.append(ent[r["entry"]]["group"])
    return head, rows, groups


def scenario_table(data: dict[str, Any], table: dict[str, Any]) -> tuple[list[str], Rows]:
    """One scenario, entries in ranking order; a fixed encounter (every episode the same
    start) without intervals."""
    names = {e["name"]: e["display_name"] for e in data["entries"]}
    ci = not table.get("fixed", False)
    head = ["#", "entry"] + [c.header for c in MAIN_COLUMNS] + [LATENCY_HEADER]
    rows = []
    for r in table["rows"]:
        ref = r["entry"] == data["reference"]
        row = [
            Cell(str(r["rank"]), r["rank"]),
            Cell(names[r["entry"]] + (" (reference)" if ref else ""), names[r["entry"]]),
        ]
        for c in MAIN_COLUMNS:
            m = r["metrics"][c.key]
            vs = r["vs_reference"][c.key]
            mark = ""
            if isinstance(vs, dict) and vs["significant"]:
                mark = HIGHER if vs["direction"] == "higher" else LOWER
            row.append(
                Cell(
                    fmt_metric(c.kind, m, ci), m["value"], r["entry"] in table["best"][c.key], mark
                )
            )
        lat = r["latency_ms"]
        row.append(Cell(fmt_latency(lat), lat["median"], r["entry"] in table["best"]["latency_ms"]))
        rows.append(row)
    return head, rows


def entries_table(data: dict[str, Any]) -> tuple[list[str], Rows, list[str]]:
    """Every entry, by group (``data["groups"]`` order), then as submitted. Returns (header,
    rows, group per row)."""
    head = [
        "entry",
        "group",
        "what",
        "agent",
        "checkpoint",
        "authors",
        "reference",
        "training",
        "training transitions",
        "seeds",
        "sha256",
    ]
    order = {g: i for i, g in enumerate(data.get("groups", []))}
    entries = sorted(data["entries"], key=lambda e: order.get(e.get("group"), len(order)))
    rows = []
    for e in entries:
        budget, seeds = fmt_budget(e.get("budget"))
        rows.append(
            [
                Cell(e["display_name"], e["display_name"]),
                Cell(e.get("group", "-")),
                Cell(e["description"]),
                Cell(f"`{e['agent']}`"),
                Cell(f"`{e['checkpoint']}`" if e["checkpoint"] else "-"),
                Cell(", ".join(e["authors"])),
                Cell(e["reference"]),
                Cell(f"`{e['training']}`" if e["training"] else "scripted (no training)"),
                Cell(budget),
                Cell(seeds),
                Cell(f"`{e['agent_sha256'][:12]}`"),
            ]
        )
    return head, rows, [e.get("group", "") for e in entries]


def published_table(
    first: str, columns: Sequence[str], rows: Iterable[tuple[str, str, Mapping[str, float]]]
) -> tuple[list[str], Rows]:
    """One of the paper's tables as transcribed: ``(row name, density, column -> value)``."""
    head = [first, "density", *columns]
    out = [
        [Cell(name, name), Cell(density, density)]
        + [Cell(f"{values[c]:g}", values[c]) for c in columns]
        for name, density, values in rows
    ]
    return head, out


def side_by_side_tables(data: dict[str, Any]) -> list[tuple[str, list[str], Rows]]:
    names = {e["name"]: e["display_name"] for e in data["entries"]}
    kinds = _kinds()
    by_entry: dict[tuple[str, str], list[dict[str, Any]]] = {}  # (entry, paper row): blocks
    for block in data["published_vs_measured"]:
        by_entry.setdefault((block["entry"], block["published_as"]), []).append(block)
    out = []
    for (entry, _), blocks in by_entry.items():
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
                row += [
                    Cell(fmt_published(kind, r["published"]), r["published"]),
                    Cell(fmt_metric(kind, r["measured"])),
                ]
            rows.append(row)
        title = (
            f"{names[entry]} — published as “{blocks[0]['published_as']}” ({blocks[0]['table']})"
        )
        out.append((title, head, rows))
    return out


# ----------------------------------------------------------------------------------------------
# One result file: ``cdr-bench evaluate`` (plain text) and ``cdr-bench report`` (Markdown)


def _result_rows(
    result: dict[str, Any], ci: bool, label: str | None = None, compact: bool = False
) -> Rows:
    rows = []
    latency = result.get("timing", {}).get("decision_latency", {})
    cols = [c for c in COLUMNS if c.short] if compact else list(COLUMNS)
    for sc in result["scenarios"]:
        lat = fmt_latency(latency.get(sc["id"], {}).get("per_decision_ms"))
        for role, m in sc["metrics"].items():
            row = [Cell(label)] if label is not None else []
            row += [Cell(sc["id"]), Cell(role), Cell(str(m["episodes"]))]
            row += [Cell(fmt_metric(c.kind, m[c.key], ci)) for c in cols]
            rows.append(row if compact else row + [Cell(lat)])
    return rows


def _result_head() -> list[str]:
    return ["scenario", "aircraft", "episodes", *[c.header for c in COLUMNS], LATENCY_HEADER]


def _compact_head() -> list[str]:
    return ["scenario", "aircraft", "episodes", *[c.short for c in COLUMNS if c.short]]


def summary_text(result: dict[str, Any], wide: bool = False) -> str:
    """Every scenario and role of one result, point values (intervals are in the JSON): the
    paper's five metrics and clean success in under 100 columns, or every column with
    ``wide``."""
    if wide:
        table = text_table(_result_head(), _result_rows(result, ci=False))
    else:
        table = text_table(_compact_head(), _result_rows(result, ci=False, compact=True))
    return f"agent {result['agent']['name']} ({result['agent']['path']})\n{table}"


REPORT_NOTE = (
    "Rates are per episode with 95 % Wilson intervals; means (steps of successful episodes, "
    "episode sums of the goal and safety rewards R_G / R_S) with 95 % bootstrap intervals. LoS "
    "counts episodes with at least one loss of separation whatever the outcome (an NMAC is also "
    "a LoS); success, NMAC, timeout, ended by LoS (only where a LoS ends the episode) and "
    "boundary (only where leaving the sector ends it) partition the episodes. Invalid is the "
    "share of decisions that chose a masked action. Field metrics are per flight (extra path "
    "and delay over successful flights, severity over flights with a LoS; docs/model.md §10.1). "
    "Latency is per decision (one batched call / "
    "decisions in it), in ms, machine-dependent."
)


def report_markdown(results: list[tuple[str, dict[str, Any]]]) -> str:
    """``cdr-bench report``: one Markdown table over several results, one row per agent,
    scenario and role, every metric with its 95 % interval; then the files."""
    rows: Rows = []
    for _path, res in results:
        rows += _result_rows(res, ci=True, label=res["agent"]["name"])
    files = "\n".join(
        f"- `{p}`: agent `{r['agent']['path']}` sha256 `{r['agent']['sha256'][:16]}`, "
        f"base seed {r['base_seed']}, {sum(s['episodes'] for s in r['scenarios'])} episodes, "
        f"cdr-bench {r['versions'].get('cdr-bench')}"
        for p, r in results
    )
    table = md_table(["agent", *_result_head()], rows, numeric_from=3)
    return f"# cdr-bench results\n\n{REPORT_NOTE}\n\n{table}\n\nResult files:\n\n{files}\n"


# ----------------------------------------------------------------------------------------------
# The tables of the documentation (the inputs are gathered by cdr_bench.leaderboard.tables)


@dataclass(frozen=True)
class PaperRow:
    """A row of the paper's tables, shown beside a measured row of the same scenario."""

    label: str
    scenario: str
    episodes: int | None
    values: Mapping[str, float]
    """Metric key (as in :data:`COLUMNS`) -> value as published (rates in %)."""


def measured_table(
    entries: Iterable[tuple[str, dict[str, Any], Sequence[PaperRow]]],
    scenarios: Sequence[str] | None = None,
    ci: bool = True,
) -> str:
    """Ownship metrics of results (``(label, result, paper rows)``), one row per result and
    scenario (``scenarios``: these only, in the result's order), each followed by the paper's
    rows of the same scenario, marked *published*."""
    head = ["agent", "scenario", "episodes", *[c.header for c in MAIN_COLUMNS]]
    rows: Rows = []
    for label, res, paper in entries:
        for sc in res["scenarios"]:
            if scenarios is not None and sc["id"] not in scenarios:
                continue
            m = sc["metrics"]["ownship"]
            rows.append(
                [Cell(label), Cell(sc["id"]), Cell(str(m["episodes"]))]
                + [Cell(fmt_metric(c.kind, m[c.key], ci)) for c in MAIN_COLUMNS]
            )
            for p in paper:
                if p.scenario == sc["id"]:
                    rows.append(
                        [
                            Cell(p.label),
                            Cell(p.scenario),
                            Cell("-" if p.episodes is None else str(p.episodes)),
                        ]
                        + [Cell(fmt_published(c.kind, p.values.get(c.key))) for c in MAIN_COLUMNS]
                    )
    return md_table(head, rows, numeric_from=2)


_PSI = {-1: "left", 0: "hold", 1: "right"}
_V = {-1: "slower", 0: "keep", 1: "faster"}
_H = {-1: "descend", 0: "level", 1: "climb"}


def action_label(a: int) -> str:
    p, v, h = decode(a)
    return f"{a} {_PSI[p]}/{_V[v]}/{_H[h]}"


def multimodality_table(runs: Iterable[tuple[str, dict[str, Any]]]) -> str:
    """``cdr-bench multimodal`` results (``(label, its JSON)``): first-action samples, and the
    mean number of manoeuvre families (left, right, climb, descend, speed) per episode that the
    successful samples reach, beside the mean the search finds (docs/model.md §10.4)."""
    head = [
        "agent",
        "scenario",
        "episodes x samples",
        "families per episode",
        "found by search",
        "follow-on success",
        "modes (successful)",
        "normalised entropy",
        "distinct first actions",
        "most sampled first actions (share of all samples)",
    ]
    rows: Rows = []
    for label, d in runs:
        counts = d["all"]
        top = sorted(range(len(counts)), key=lambda a: (-counts[a], a))[:3]
        total = sum(counts) or 1
        tops = ", ".join(
            f"{action_label(a)} ({100 * counts[a] / total:.0f} %)" for a in top if counts[a]
        )
        fam, found = d.get("families_mean"), d.get("feasible_families_mean")
        thr = d.get("threshold")
        ent = d.get("normalised_entropy")
        rows.append(
            [
                Cell(label),
                Cell(d["scenario"]),
                Cell(f"{d.get('episodes', 1)} x {d['samples']}"),
                Cell("-" if fam is None else f"{fam:.2f}"),
                Cell("-" if found is None else f"{found:.2f}"),
                Cell(fmt_value("rate", d["success_rate"])),
                Cell(f"{d['modes']}" + ("" if thr is None else f" (≥ {100 * thr:g} %)")),
                Cell("-" if ent is None else f"{ent:.3f}"),
                Cell(str(sum(1 for c in counts if c))),
                Cell(tops or "-"),
            ]
        )
    return md_table(head, rows, numeric_from=2, text_from=len(head) - 1)


def latency_table(runs: Iterable[tuple[str, dict[str, Any]]]) -> str:
    """``cdr-bench latency`` results (``(label, its JSON)``): one decision per call, and per
    decision at the largest batch measured."""
    head = [
        "agent",
        "threads",
        "median ms / decision (batch 1)",
        "p99 ms (batch 1)",
        "largest batch",
        "median ms / decision (largest batch)",
    ]
    rows: Rows = []
    for label, d in runs:
        by_batch = {r["batch"]: r for r in d["rows"]}
        one = by_batch.get(1)
        big = by_batch[max(by_batch)]
        rows.append(
            [
                Cell(label),
                Cell(str(d.get("threads", "-"))),
                Cell("-" if one is None else fmt_ms(one["median_ms_per_decision"])),
                Cell("-" if one is None else fmt_ms(one["p99_ms"])),
                Cell(str(big["batch"])),
                Cell(fmt_ms(big["median_ms_per_decision"])),
            ]
        )
    return md_table(head, rows, numeric_from=1)


def latency_detail_table(d: dict[str, Any]) -> str:
    """Every batch size of one ``cdr-bench latency`` result."""
    head = ["batch", "calls", "median ms / call", "p99 ms / call", "median ms / decision"]
    rows = [
        [
            Cell(str(r["batch"])),
            Cell(str(r.get("calls", "-"))),
            Cell(f"{r['median_ms']:.3f}"),
            Cell(f"{r['p99_ms']:.3f}"),
            Cell(f"{r['median_ms_per_decision']:.4f}"),
        ]
        for r in d["rows"]
    ]
    note = f"{d.get('threads', '-')} thread(s), scenario `{d.get('scenario', '-')}`."
    return md_table(head, rows, numeric_from=0) + "\n\n" + note


def training_summary(final: dict[str, Any], log: str, stages: int | None = None) -> str:
    """One sentence from the ``final`` line of a Diffusion-AC training log."""
    of = f" of {stages}" if stages else ""
    return (
        f"Training (`{log}`): {final['step']:,} transitions, {final['updates']:,} updates, "
        f"{final['wall_s'] / 60:.0f} min wall, final DPSC stage {final['stage']}{of}."
    )


def quick_eval_table(runs: Iterable[tuple[str, dict[str, Any]]], scenario: str) -> str:
    """The trainers' own quick evaluation (``final`` lines of training logs) on ``scenario``."""
    head = ["run", "transitions", "success", "LoS", "NMAC", "timeout", "episodes"]
    rows: Rows = []
    for label, f in runs:
        e = f[f"eval/{scenario}"]
        rows.append(
            [Cell(label), Cell(f"{f['step']:,}")]
            + [Cell(fmt_value("rate", e[k])) for k in ("success", "los", "nmac", "timeout")]
            + [Cell(str(e["episodes"]))]
        )
    return md_table(head, rows, numeric_from=1)


TUNING_FLAGS = ("ent_coef", "combine", "lr", "n_envs", "curriculum", "scenario", "total_steps")


def tuning_table(runs: Iterable[tuple[str, str, dict[str, Any], list[dict[str, Any]]]]) -> str:
    """Tuning runs (``(agent, run, its arguments, its log lines)``): the trainer's quick
    evaluation per density, or the last rolling training success of a run cut before its
    budget."""
    head = [
        "agent",
        "run",
        "key flags",
        "transitions",
        "DPSC stage",
        "success low / medium / high",
        "LoS low / medium / high",
    ]
    rows: Rows = []
    for agent, run, args, lines in runs:
        finals = [r["final"] for r in lines if "final" in r]
        flags = ", ".join(f"{k}={args[k]}" for k in TUNING_FLAGS if k in args)
        if finals:
            f = finals[-1]
            ev = [f[f"eval/{d}"] for d in DENSITIES]
            cells = [
                f"{f['step']:,}",
                str(f["stage"]),
                " / ".join(f"{e['success']:.2f}" for e in ev),
                " / ".join(f"{e['los']:.2f}" for e in ev),
            ]
        else:
            last = lines[-1]
            cells = [
                f"{last['step']:,} (cut)",
                str(last.get("curriculum/stage", "-")),
                f"rolling training success {last.get('charts/success_rolling', 0):.2f}",
                "-",
            ]
        rows.append([Cell(agent), Cell(run), Cell(flags)] + [Cell(c) for c in cells])
    return md_table(head, rows, numeric_from=3, text_from=5)
