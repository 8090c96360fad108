"""The tables of the leaderboard's pages (``leaderboard/README.md`` and ``index.html``), from the
leaderboard data (:func:`cdr_bench.leaderboard.data.build_data`): the headline ranking, the
seeds, the sensitivity study, the paper's claims, success per tactical scenario, one table per
scenario, the entries, the paper's tables and "published vs measured here"; their formats
(paired differences, training budgets, published numbers) and the sortable HTML table. Laid out
into the pages by :mod:`cdr_bench.leaderboard.render`. The number formats, cells and Markdown
layout are those of :mod:`cdr_bench.evaluate.report` (the tables ``cdr-bench evaluate`` and
``report`` print), from the same column list.

Text from a submission (display name, description, authors, reference, training command) enters
a cell escaped as Markdown (:func:`~cdr_bench.leaderboard.text.md_text`, or a code span); the
HTML page reads those escapes back (:func:`inline_md`), so the same cell is the literal text on
both pages and never markup.
"""

from __future__ import annotations

import html
import re
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from cdr_bench.evaluate.metrics import MAIN_METRICS
from cdr_bench.evaluate.report import (
    COLUMNS,
    LATENCY_HEADER,
    Cell,
    Column,
    Rows,
    fmt_latency,
    fmt_metric,
    fmt_value,
)
from cdr_bench.leaderboard.text import md_code, md_text

MAIN_COLUMNS: Sequence[Column] = MAIN_METRICS
"""The columns of the leaderboard and of the documentation tables (the metrics that are not
detail columns)."""

DENSITIES = ("low", "medium", "high")
"""The traffic-density scenarios, sparsest first."""


def fmt_published(kind: str, v: float | None) -> str:
    """A number of the paper as transcribed (rates are already in %)."""
    if v is None:
        return "-"
    return f"{v:g}%" if kind == "rate" else f"{v:g}"


# ----------------------------------------------------------------------------------------------
# HTML: the one escape, inline Markdown and the sortable table


def esc(s: str) -> str:
    """``s`` as HTML text or a quoted attribute value (``&``, ``<``, ``>`` and both quotes
    escaped): the one escape of every HTML page the benchmark writes."""
    return html.escape(s, quote=True)


_MD_ESCAPE = re.compile(r"\\([!-/:-@\[-`{-~])|&(amp|lt|gt|quot|#[0-9]{1,7});")
"""A Markdown backslash escape (of ASCII punctuation) or a character reference."""
_PLACEHOLDER = 0xF0000
"""Escaped characters wait as private-use characters (refused in submitted text) while the
code spans and bold are found."""


def inline_md(s: str) -> str:
    """Markdown text as HTML: `code` and **bold** (the only inline Markdown the pages use),
    backslash escapes and character references (:func:`~.text.md_text` writes them) as the
    character they stand for; everything else escaped."""
    kept: list[tuple[str, str]] = []  # (as written, the character)

    def hold(m: re.Match[str]) -> str:
        if m.group(1) is not None:
            ch = m.group(1)
        elif m.group(2).startswith("#"):
            code = int(m.group(2)[1:])
            if not 0 < code <= 0x10FFFF or 0xD800 <= code <= 0xDFFF:
                return m.group(0)  # not a character: left as written (and escaped)
            ch = chr(code)
        else:
            ch = {"amp": "&", "lt": "<", "gt": ">", "quot": '"'}[m.group(2)]
        kept.append((m.group(0), ch))
        return chr(_PLACEHOLDER + len(kept) - 1)

    def back(text: str, literal: bool) -> str:
        return "".join(
            esc(kept[ord(c) - _PLACEHOLDER][0 if literal else 1])
            if _PLACEHOLDER <= ord(c) < _PLACEHOLDER + len(kept)
            else c
            for c in text
        )

    parts = esc(_MD_ESCAPE.sub(hold, s)).split("`")
    for i in range(len(parts)):
        parts[i] = f"<code>{back(parts[i], True)}</code>" if i % 2 else parts[i]
    text = "".join(parts)
    bits = text.split("**")
    for i in range(1, len(bits), 2):
        bits[i] = f"<strong>{bits[i]}</strong>"
    return back("".join(bits), False)


def html_table(
    tid: str, head: Sequence[str], rows: Rows, cls: str = "", groups: Sequence[str] | None = None
) -> str:
    """A sortable HTML table (``data-sort`` keys; the page's script sorts on click); ``groups``:
    one per row, written as the row's ``data-group`` (the page's filter hides groups)."""
    out = [
        '<div class="scroll">',
        f'<table id="{esc(tid)}" class="{esc(("sortable " + cls).strip())}">',
    ]
    out.append("<thead><tr>" + "".join(f"<th>{inline_md(h)}</th>" for h in head) + "</tr></thead>")
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
# The tables of the pages

HIGHER, LOWER = "▲", "▼"


def signed(x: float) -> str:
    """``x`` with its sign and one decimal; a non-zero ``x`` that one decimal would show as 0.0
    keeps its sign and one significant digit (``-0.04``), so that an interval that excludes 0
    never reads as reaching it; exactly 0 is ``+0.0``."""
    r = round(x, 1) + 0.0  # + 0.0: no "-0.0"
    if r == 0.0 and x != 0.0:
        return f"{x:+.1g}"
    return f"{r:+.1f}"


def fmt_diff(kind: str, d: dict[str, Any] | None) -> str:
    """A paired difference ``{diff, ci95, significant}``: points (pp) for rates, with its 95 %
    interval; ``▲``/``▼`` when significant."""
    if d is None or d.get("diff") is None:
        return "-"
    scale, unit = (100.0, " pp") if kind == "rate" else (1.0, "")

    def f(x: float) -> str:
        return signed(scale * x)

    lo, hi = d["ci95"]
    ci = "" if lo is None or hi is None else f" [{f(lo)}, {f(hi)}]"
    mark = (f" {HIGHER}" if d["diff"] > 0 else f" {LOWER}") if d["significant"] else ""
    return f"{f(d['diff'])}{unit}{ci}{mark}"


def fmt_budget(b: dict[str, Any] | None) -> tuple[str, str]:
    """Training transitions and seeds of an entry (``-`` for a scripted or undeclared one); an
    entry trained on from another's run shows the total and both parts."""
    if not b or b.get("transitions") is None:
        return "-", "-"
    t = b["transitions"]
    text = f"{t:,}" if isinstance(t, int) else f"{t[0]:,}-{t[1]:,}"
    if isinstance(t, int) and isinstance(b.get("parent_transitions"), int):
        p = b["parent_transitions"]
        text = f"{t + p:,} ({p:,} of its parent + {t:,})"
    return text + (" (declared)" if b.get("source") == "declared" else ""), str(b["seeds"])


def _transitions(b: dict[str, Any] | None) -> int | None:
    t = (b or {}).get("transitions")
    if isinstance(t, int) and isinstance((b or {}).get("parent_transitions"), int):
        return t + b["parent_transitions"]  # type: ignore[index]
    return t if isinstance(t, int) or t is None else t[0]


def _kinds() -> dict[str, str]:
    return {c.key: c.kind for c in COLUMNS}


def _headers() -> dict[str, str]:
    return {c.key: c.header for c in COLUMNS}


HEADROOM_NOTE = (
    "**Headroom, not ranked.** What is possible on the same {n} episodes of `{sc}`: a planner "
    "that knows the future of the traffic (`cdr_bench/evaluate/headroom.py`) tries, in a copy "
    "of each episode, the follow-on manoeuvres of the tactical search (hold, then a turn, a "
    "hold and a return to the goal, with a target speed and levels; simplest first) and keeps "
    "the first after which the ownship reaches its goal with no LoS. It is not an agent (no "
    "submission can see the traffic's future) and its rate is a lower bound of what is "
    "possible: it stops at the first clean plan and searches one family of plans. Its decisions "
    "are in its log, and `leaderboard build --check` replays them like any entry's. Beside it: "
    "its paired difference with {base} on the same episodes (episodes clean for the planner and "
    "not for {base}, and the reverse; McNemar's exact test) and its distance to the top score."
)


def headroom_table(data: dict[str, Any]) -> tuple[list[str], Rows]:
    """The headroom row (``data["headroom"]``): the planner's headline score with its interval,
    its paired difference with the baseline, its distance to the top score, the tie-break and
    the paper's five metrics."""
    hr = data["headroom"]
    ent = {e["name"]: e for e in data["entries"]}
    header, kind = _headers(), _kinds()
    m, vb, vt = hr["metrics"], hr["vs_baseline"], hr["vs_top"]
    key, tie = data["ranking"]["metric"], data["ranking"]["tie_break"]
    rest = [k for k in m if k != key]
    base = ent[vb["entry"]]["display_name"]
    top = ent[vt["entry"]]["display_name"]
    head = [
        "reference",
        f"{header[key]} ({hr['scenario']})",
        f"vs {md_text(base)} (paired)",
        f"vs top score ({md_text(top)})",
        *[header[k] for k in rest],
    ]
    row = [
        Cell("Clairvoyant planner (knows the traffic; not an agent)"),
        Cell(fmt_metric("rate", m[key]), m[key]["value"]),
        Cell(
            f"{100 * vb['diff']:+.1f} pp ({vb['better']} vs {vb['worse']} episodes, "
            f"McNemar exact p = {vb['p']:.2g})",
            vb["diff"],
        ),
        Cell(f"{100 * vt['diff']:+.1f} pp", vt["diff"]),
        *[Cell(fmt_metric(kind[k], m[k], ci=k == tie), m[k]["value"]) for k in rest],
    ]
    return head, [row]


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
        "trained on",
        "training transitions (total)",
        "seeds",
    ]
    rows: Rows = []
    for r in rk["rows"]:
        e = ent[r["entry"]]
        budget, seeds = fmt_budget(e["budget"])
        h, tb = r["headline"], r["tie_break"]
        rows.append(
            [
                Cell(rank_label(r), r["rank"]),
                Cell(md_text(e["display_name"]), e["display_name"]),
                Cell(e["group"], e["group"]),
                Cell(fmt_metric("rate", h) + _over_seeds(h), h["value"], r["rank"] == 1),
                Cell(fmt_diff("rate", r["vs_above"]), (r["vs_above"] or {}).get("diff")),
                Cell(fmt_metric("mean", tb), tb["value"]),
            ]
            + [
                Cell(fmt_value(kind[k], r["metrics"][k]["value"]), r["metrics"][k]["value"])
                for k in five
            ]
            + [
                Cell(md_text(e["trained_on"]) if e.get("trained_on") else "-", e.get("trained_on")),
                Cell(budget, _transitions(e["budget"])),
                Cell(seeds, None if seeds == "-" else int(seeds)),
            ]
        )
    return head, rows, [ent[r["entry"]]["group"] for r in rk["rows"]]


def rank_label(r: dict[str, Any]) -> str:
    """A ranking row's rank: ``3``, or ``2=`` for every member of a tie group (the group's
    first position, shared)."""
    shared = r.get("shared_rank", r["rank"])
    return f"{shared}=" if r.get("tie_group_size", 1) > 1 else str(r["rank"])


def _over_seeds(h: dict[str, Any]) -> str:
    """How a ranked score aggregates the entry's runs: ``mean of 3 seeds``, ``IQM of 5
    seeds``, ``3 seeds, one parent``; nothing for one run."""
    seeds, units = h.get("seeds", 1), h.get("units", 1)
    if seeds <= 1:
        return ""
    if units == 1:
        return f", {seeds} seeds of one parent (one run)"
    par = "" if units == seeds else f" ({units} independent)"
    return f", {h.get('aggregate', 'mean')} of {seeds} seeds{par}"


def seeds_table(data: dict[str, Any]) -> tuple[list[str], Rows, list[str]]:
    """Aggregates over training seeds (``data["seeds"]``), entries in ranking order: the number
    of seeds, the headline score of each seed, its interquartile mean (IQM) with the
    stratified-bootstrap interval (none for one seed), the IQM over the tasks, and the
    probability of improvement over each comparator on those tasks."""
    sd = data["seeds"]
    ent = {e["name"]: e for e in data["entries"]}
    rank = {r["entry"]: r["rank"] for r in data["ranking"]["rows"]}
    label = {c: md_text(ent[c]["display_name"]) for c in sd["comparators"]}
    sc = sd["scenario"]
    head = [
        "#",
        "entry",
        "seeds",
        f"clean success on {sc}, per seed",
        f"ranked score over seeds ({sc})",
        f"IQM over seeds x {len(sd['tasks'])} scenarios",
        *[f"P(better than {label[c]})" for c in sd["comparators"]],
    ]

    def iv(m: dict[str, Any]) -> str:
        return fmt_metric("rate", {"value": m.get("score", m["iqm"]), "ci95": m["ci95"]})

    rows: Rows = []
    for r in sd["rows"]:
        h, t = r["headline"], r["tasks"]
        per = " ".join(f"{100 * v:.1f}" for v in h["per_run"])
        row = [
            Cell(str(rank[r["entry"]]), rank[r["entry"]]),
            Cell(md_text(ent[r["entry"]]["display_name"]), ent[r["entry"]]["display_name"]),
            Cell(
                str(h["runs"])
                + (
                    ""
                    if len(r.get("units", [])) in (0, h["runs"])
                    else f" ({len(r['units'])} independent: shared parent)"
                ),
                h["runs"],
            ),
            Cell(per if h["runs"] > 1 else f"{per} (one run)", h["min"]),
            Cell(f"{iv(h)} ({h.get('aggregate', 'IQM')})", h.get("score", h["iqm"])),
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
        "clean success: mean ± sd (judged)",
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
                    Cell(
                        study_value("success_rate", p.get("clean_mean"), p.get("clean_sd")),
                        p.get("clean_mean"),
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
        row = [Cell(str(r["rank"]), r["rank"]), Cell(md_text(ent[r["entry"]]["display_name"]))]
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
    raw = {e["name"]: e["display_name"] for e in data["entries"]}
    names = {k: md_text(v) for k, v in raw.items()}
    ci = not table.get("fixed", False)
    head = ["#", "entry"] + [c.header for c in MAIN_COLUMNS] + [LATENCY_HEADER]
    rows = []
    for r in table["rows"]:
        ref = r["entry"] == data["reference"]
        row = [
            Cell(str(r["rank"]), r["rank"]),
            Cell(names[r["entry"]] + (" (reference)" if ref else ""), raw[r["entry"]]),
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
                Cell(md_text(e["display_name"]), e["display_name"]),
                Cell(e.get("group", "-")),
                Cell(md_text(e["description"])),
                Cell(md_code(e["agent"])),
                Cell(md_code(e["checkpoint"]) if e["checkpoint"] else "-"),
                Cell(md_text(", ".join(e["authors"]))),
                Cell(md_text(e["reference"])),
                Cell(md_code(e["training"]) if e["training"] else "scripted (no training)"),
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
    """Published vs measured, per entry and paper row: (Markdown title, header, rows)."""
    names = {e["name"]: md_text(e["display_name"]) for e in data["entries"]}
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
