"""The tables that ``cdr-bench evaluate`` and ``cdr-bench report`` print, with one column list
(:data:`COLUMNS`: the metric registry of :mod:`cdr_bench.evaluate.metrics`) and one set of
number formats and table layouts (:func:`fmt_metric`, :class:`Cell`, :func:`md_table`). Pure
functions of result data (this module reads no file and evaluates nothing):

* the summary printed by ``cdr-bench evaluate`` and the Markdown of ``cdr-bench report``;
* the formats, cells and Markdown layout that the leaderboard's tables use too
  (:mod:`cdr_bench.leaderboard.page_tables`: the tables of ``leaderboard/README.md`` and
  ``index.html``; :mod:`cdr_bench.leaderboard.tables`: the tables in the marked blocks of the
  documentation).

It sits in the evaluator's layer so that ``cdr-bench evaluate`` and the leaderboard above it
share it; it imports nothing from the leaderboard or the trainers.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from cdr_bench.evaluate.metrics import METRICS, SYSTEM_METRICS, Metric

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


def fmt_ms(x: float | None) -> str:
    return "-" if x is None else f"{x:.3g}"


def fmt_latency(lat: dict[str, Any] | None) -> str:
    if not lat or lat.get("median") is None:
        return "-"
    return f"{fmt_ms(lat['median'])} / {fmt_ms(lat.get('p99'))}"


# ----------------------------------------------------------------------------------------------
# Cells and table formats (Markdown, plain text)


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


def _system_rows(result: dict[str, Any], ci: bool, label: str | None = None) -> Rows:
    rows = []
    for sc in result["scenarios"]:
        m = sc.get("system_metrics")
        if not m:
            continue
        row = [Cell(label)] if label is not None else []
        row += [Cell(sc["id"]), Cell(str(m["episodes"])), Cell(str(m["flights"]))]
        row += [Cell(fmt_metric(c.kind, m[c.key], ci)) for c in SYSTEM_METRICS]
        rows.append(row)
    return rows


def _system_head(short: bool) -> list[str]:
    cols = [(c.short or c.header) if short else c.header for c in SYSTEM_METRICS]
    return ["scenario", "episodes", "flights", *cols]


def summary_text(result: dict[str, Any], wide: bool = False) -> str:
    """Every scenario and role of one result, point values (intervals are in the JSON): the
    paper's five metrics and clean success in under 100 columns, or every column with
    ``wide``; then, for scenarios with several controlled aircraft, the system metrics
    (docs/model.md §10.1.3)."""
    if wide:
        table = text_table(_result_head(), _result_rows(result, ci=False))
    else:
        table = text_table(_compact_head(), _result_rows(result, ci=False, compact=True))
    out = f"agent {result['agent']['name']} ({result['agent']['path']})\n{table}"
    system = _system_rows(result, ci=False)
    if system:
        out += "\nsystem (every controlled aircraft; per flight unless stated)\n"
        out += text_table(_system_head(short=True), system, numeric_from=1)
    return out


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


SYSTEM_NOTE = (
    "System metrics, where an episode has several controlled aircraft: every controlled aircraft "
    "of an episode together (ownship, learning intruders, controlled traffic), the episode the "
    "unit (values are ratios of per-episode sums; 95 % intervals bootstrap the episodes). LoS "
    "and NMAC count pairs once, per hour flown by the controlled aircraft; delay and extra path "
    "per successful flight; delay spread: the standard deviation of delay across an episode's "
    "successful flights (docs/model.md §10.1.3)."
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
    system: Rows = []
    for _path, res in results:
        system += _system_rows(res, ci=True, label=res["agent"]["name"])
    if system:
        head = ["agent", *_system_head(short=False)]
        table += f"\n\n{SYSTEM_NOTE}\n\n" + md_table(head, system, numeric_from=2)
    return f"# cdr-bench results\n\n{REPORT_NOTE}\n\n{table}\n\nResult files:\n\n{files}\n"
