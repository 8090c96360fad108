"""``leaderboard/README.md`` and the self-contained ``leaderboard/index.html`` from the
leaderboard data (:func:`cdr_bench.leaderboard.data.build_data`), the plots and the recorded
replays.

Both pages open with a generated conclusion (:func:`conclusion`: who ranks first on the
headline score, whether the gap is significant, how the learned agents compare with ``mvp``),
then the ranking, the paper's Table 2 on the headline scenario beside it (marked published,
never ranked), success per tactical scenario, one table per scenario, the entries, the paper's
tables and "published vs measured here". The HTML page adds a filter by group (scripted,
learned, ablation, published), sortable tables and the replays: the same tactical episodes
flown by each replayed entry, side by side, drawn on canvases from the recorded trajectories.
It has no external assets: CSS, scripts and data are inline; the plots are the PNG files written
beside it (`plots/NAME`), linked rather than embedded, so the page stays small (0.2 MB).
"""

from __future__ import annotations

import json
from typing import Any
from urllib.parse import quote

from cdr_bench.evaluate.report import COLUMNS, Rows, fmt_metric, fmt_value, md_table
from cdr_bench.leaderboard.page_tables import (
    HEADROOM_NOTE,
    HIGHER,
    LOWER,
    claims_table,
    entries_table,
    esc,
    headroom_table,
    html_table,
    inline_md,
    published_table,
    rank_label,
    ranking_table,
    scenario_table,
    seeds_table,
    sensitivity_table,
    side_by_side_tables,
    signed,
    tactical_table,
)
from cdr_bench.leaderboard.published import Published
from cdr_bench.leaderboard.text import md_text

GENERATOR = "cdr-bench leaderboard build"

INTRO = (
    "Every entry is a file in `submissions/`, scored by `cdr-bench evaluate` on identical "
    "episodes (episode i of a scenario has the same seed and traffic for every entry) in its "
    "own sandboxed process; the result files are in `results/`. Rates are per episode with 95 % "
    "Wilson intervals, means (steps of successful episodes, episode sums of the goal and safety "
    "rewards R_G / R_S) with 95 % bootstrap intervals. Rows follow the ranking. **Bold**: the "
    "best value of a column where a better value cannot come from failing (success, clean "
    "success, LoS, NMAC, invalid actions, latency; never steps, timeouts or rewards), not "
    "marked when every entry ties. {up} / {down}: significantly higher / lower than "
    "{ref} on the same episodes (95 % paired bootstrap interval of the difference excludes 0; "
    "`cdr-bench compare`). Invalid is the share of decisions that chose a masked action. "
    "Latency is the median / p99 time per decision in ms (batched calls, one thread) on the "
    "machine that last ran `build --evaluate`: it is machine-dependent and `--check` does not "
    "re-measure it."
)

HEADLINE_NOTE = (
    "**Headline score: clean success on `{sc}`** — the share of episodes in which the ownship "
    "reaches its goal with no loss of separation at all, over the entry's training seeds: the "
    "mean of its seeds (up to four) or their interquartile mean (IQM, more than four), seeds "
    "that share a parent (trained on from one run) counted as one; a scripted entry is one run. "
    "Its 95 % interval is a two-level bootstrap: the seeds resampled, then the episodes of each "
    "resampled seed's run, so it holds the episode noise as well as the seed spread. Success "
    "alone does not separate the agents (an agent that flies through a LoS still succeeds, and "
    "on `{sc}` even one that never manoeuvres succeeds almost always); clean success counts the "
    "episodes a controller would accept and cannot be improved by failing. Paired differences "
    "average the per-episode difference over the seeds (every run flies the same episodes), "
    "with the same two-level bootstrap (seeds of each side, then the episodes, jointly for "
    "every run). A tie group: the best remaining score and the entries after it in score "
    "order, down to the first one significantly below it; it shares a rank (`2=`) and is "
    "ordered by extra path (km flown beyond the direct route by successful flights, lower "
    "first; never above a member with a significantly higher score). Between groups the order "
    "is strictly by score. "
    '"vs row above": the paired difference from the entry ranked just above, in points, '
    "{down} when significant. Beside it, from the seed each entry shows (its `checkpoint`), "
    "the extra path and the paper's five metrics on `{sc}` (success, LoS, NMAC, timeout, steps "
    "of successful episodes), and the training budget (transitions and seeds, from the entry's "
    "training logs; `-` for scripted agents). Groups: scripted, learned (learns from scratch), "
    "hybrid (MVP with a learned override), ablation. Efficiency (steps, extra path) is "
    "comparable only among agents that succeed equally often."
)

TACTICAL_NOTE = (
    "Success per tactical scenario, entries in ranking order. A family draws its encounter "
    "geometry per episode: success rate with its 95 % Wilson interval. A fixed scenario "
    "starts every episode from the same state (checked by resetting the simulator with every "
    "episode's seed): it is one encounter, shown as its single outcome (for an agent that draws "
    "its actions at random, how often the repeated encounter succeeded, without an interval)."
)

SEEDS_NOTE = (
    "Training seeds, aggregated as Agarwal et al. (2021) recommend (the `rliable` "
    "methods, with the episode noise added): each seed's checkpoint is scored on the same "
    "episodes; the ranked score of the clean success (the mean of the seeds up to {mean_up_to}, "
    "the interquartile mean, IQM, beyond; seeds that share a parent count as one), with a 95 % "
    "two-level bootstrap interval ({reps:,} resamples: the seeds resampled, then the episodes "
    "of each resampled seed's run); the IQM over every (seed, scenario) of the {ntasks} "
    "scenarios {tasks} (runs resampled within each scenario, then their episodes; seeds that "
    "share a parent are counted separately here); and the probability of improvement P(X > Y) "
    "on those scenarios: the chance that a random seed (or parent) of the entry scores above "
    "one of the comparator, averaged over the scenarios (ties count one half; 0.5: no "
    "difference), with the same two-level interval, so against a single run it still carries "
    "the episode noise. A scripted agent is one run. The per-scenario tables show one seed per "
    "entry (its `checkpoint`)."
)

CLAIMS_NOTE = (
    "Every claim of the paper that cdr-bench can test, beside our measurement, with the rule "
    "that decides it (fixed in `cdr_bench/leaderboard/claims.py` before the numbers). The "
    "paper's numbers come from its own simulator, so a number outside our interval says that "
    "this benchmark does not reproduce it, not that the paper mis-measured its own. Measured on "
    "the seed each entry shows (the ablations' probability of improvement: over every seed); "
    "reduced budgets are named. A yes/no outcome per episode (success, LoS, NMAC) is tested "
    "with McNemar's exact test on the discordant episodes (p and A+/B- / A-/B+ counts), the "
    "same numbers as `cdr-bench compare`; a statement that combines several tests (better "
    "than each baseline) is Holm-corrected; a test with too few discordant episodes to reject "
    'even if all fell one way is **not measurable**, not "not held".'
)

GROUP_LABEL = {
    "scripted": "scripted",
    "learned": "learned",
    "hybrid": "hybrid (MVP + learned)",
    "ablation": "ablation",
    "published": "published (paper)",
}


def _seeds_note(data: dict[str, Any]) -> str:
    sd = data["seeds"]
    return SEEDS_NOTE.format(
        reps=sd["resamples"],
        mean_up_to=sd.get("mean_up_to", 4),
        ntasks=len(sd["tasks"]),
        tasks=", ".join(f"`{t}`" for t in sd["tasks"]),
    )


def sensitivity_note(data: dict[str, Any]) -> str:
    """What the sensitivity table shows and where its trials come from."""
    st = data["sensitivity"]
    scen = ", ".join(f"`{s}` ({n} episodes)" for s, n in st["scenarios"])
    b = [x for x in st.get("budgets", []) if isinstance(x, int)]
    budget = (
        f"Every trial trained for {b[0]:,} transitions, a fraction of the reference recipe's "
        "(the claims give the share): an early-training study, not the trends at the full "
        "budget. "
        if len(b) == 1
        else ""
    )
    return (
        f"Diffusion-AC trained once per grid value and seed, one factor varied at a time around "
        f"the defaults ({st['trials']} trials landed, in `{st['source']}` relative to this "
        f"folder; `sweeps/sensitivity.yaml`). Each trial's number is the mean over {scen} of "
        "the ownship's success rate (the episode reward for the Polyak coefficient, as the "
        "paper plots it). The temperature is held fixed over training and is in units of the "
        "per-state standard deviation of Q (the trainer's `--tau-relative`), the paper's in "
        "units of Q, so only its trend compares. The paper's numbers are those its text "
        "states (`published/fig7.yaml`; its own simulator, five runs per value). Each "
        "factor's verdict is in the claims table, judged on the clean success (success "
        "without any loss of separation; success itself is nearly saturated here), the "
        "paper's metric beside it; "
        f"a factor is judged once every value has {st['min_seeds']} seeds. {budget}Plot: "
        "`plots/sensitivity.png` (the paper's metrics)."
    )


def _anchor(sid: str) -> str:
    return "scenario-" + sid.replace("/", "-")


def _names(data: dict[str, Any]) -> dict[str, str]:
    """Display names escaped as Markdown text (the HTML page reads them with ``inline_md``)."""
    return {e["name"]: md_text(e["display_name"]) for e in data["entries"]}


def _all_names(data: dict[str, Any]) -> dict[str, str]:
    """:func:`_names` of the entries of both tracks."""
    ma = (data.get("multi_agent") or {}).get("entries", [])
    return _names(data) | {e["name"]: md_text(e["display_name"]) for e in ma}


def _pct(m: dict[str, Any]) -> str:
    return fmt_metric("rate", m)


def _pp(d: dict[str, Any], sign: float = 1.0) -> str:
    lo, hi = d["ci95"]
    a, b = sorted((sign * lo, sign * hi))
    return f"{signed(100 * sign * d['diff'])} points [{signed(100 * a)}, {signed(100 * b)}]"


def _vs_baseline(data: dict[str, Any], vs: list[dict[str, Any]], what: str) -> str:
    """One paragraph: how the entries of one group (``vs``: their paired differences from the
    baseline over seeds, in ranking order) compare with the baseline; '' without any."""
    rk = data["ranking"]
    base = rk["baseline"]
    if base is None or not vs:
        return ""
    names = _names(data)
    rows = {r["entry"]: r for r in rk["rows"]}
    sig = {v["entry"]: v.get("significant_holm", v["significant"]) for v in vs}
    better = [v["entry"] for v in vs if sig[v["entry"]] and v["diff"] > 0]
    worse = [v["entry"] for v in vs if sig[v["entry"]] and v["diff"] < 0]
    same = [v["entry"] for v in vs if not sig[v["entry"]]]
    best = vs[0]
    parts = []
    for label, group in (
        ("significantly above", better),
        ("not significantly different from", same),
        ("significantly below", worse),
    ):
        if group:
            verb = "is" if len(group) == 1 else "are"
            who = ", ".join(names[g] for g in group)
            parts.append(f"{len(group)} {verb} {label} it ({who})")
    one = len(vs) == 1
    label = what.format(s="" if one else "s", v="s" if one else "", base=names[base])
    return (
        f"Against {names[base]} (scripted resolver, rank {rank_label(rows[base])}, "
        f"{_pct(rows[base]['headline'])}), of the {len(vs)} {label} "
        + "; ".join(parts)
        + f". The best of them, {names[best['entry']]} (rank {rank_label(rows[best['entry']])}), "
        f"differs from {names[base]} by {_pp(best)} (paired, averaged over seeds). "
        f"Each is tested against {names[base]} (two-sided bootstrap p-value of the paired "
        f"difference), Holm-corrected over the {len(vs)} tests at 5 %."
    )


def conclusion(data: dict[str, Any]) -> list[str]:
    """The generated conclusion (Markdown paragraphs): who ranks first on the headline score,
    whether the gap is significant, how the learned agents compare with the baseline."""
    rk = data["ranking"]
    names = _names(data)
    rows = {r["entry"]: r for r in rk["rows"]}
    header = {c.key: c.header for c in COLUMNS}
    lead = rows[rk["leader"]]
    n = next(t["episodes"] for t in data["tables"] if t["scenario"] == rk["scenario"])
    out = []
    lh = lead["headline"]
    if lh.get("seeds", 1) <= 1:
        over = "one run"
    elif lh["units"] == 1:
        over = f"mean of {lh['seeds']} seeds that share one parent, counted as one run"
    else:
        over = f"{lh['aggregate']} over {lh['seeds']} seeds"
    kind = {"hybrid": "a hybrid built on MVP", "learned": "a learned agent"}.get(
        lead["group"], f"a {lead['group']} entry"
    )
    first = (
        f"**{names[rk['leader']]}** ({kind}) ranks first on the headline score, "
        f"{header[rk['metric']]} on `{rk['scenario']}`: {_pct(lh)} ({over}, {n} episodes; "
        "95 % two-level bootstrap over seeds and episodes)."
    )
    tied = [t for t in rk["tied"] if t != rk["leader"]]
    if tied:
        tb = ", ".join(
            f"{names[t]} {fmt_metric('mean', rows[t]['tie_break'], ci=False)} km"
            for t in rk["tied"]
        )
        others = ", ".join(f"{names[t]} ({_pct(rows[t]['headline'])})" for t in tied)
        first += (
            f" Its lead is not significant: in its tie group (the entries after it in score "
            f"order, down to the first one significantly below it) are {others}; the group is "
            f"ordered by extra path ({tb})."
        )
    if rk["runner_up"] is not None and rk["gap"] is not None:
        ru, gap = rk["runner_up"], rk["gap"]
        if tied:
            first += (
                f" Every other entry is significantly below the top score: the best of them, "
                f"{names[ru]} ({_pct(rows[ru]['headline'])}), by {_pp(gap)} against "
                f"{names[gap['from']]}"
            )
        else:
            first += (
                f" Its lead over the runner-up, {names[ru]} ({_pct(rows[ru]['headline'])}), "
                f"is significant: {_pp(gap)}"
            )
        first += (
            " (95 % paired bootstrap on the same episodes, averaged over seeds; one comparison, "
            "not corrected for the tests below)."
        )
    out.append(first)
    for group, what in (
        ("learned", "learned agent{s} that learn{v} from scratch"),
        ("hybrid", "hybrid{s} built on {base} ({base} with a learned override)"),
    ):
        para = _vs_baseline(data, rk.get(f"{group}_vs_baseline", []), what)
        if para:
            out.append(para)
    succ = {r["entry"]: r["metrics"]["success_rate"]["value"] for r in rk["rows"]}
    learned = [succ[r["entry"]] for r in rk["rows"] if r["group"] == "learned"]
    if "direct" in succ and learned and succ["direct"] is not None:
        out.append(
            f"Success alone hardly separates them: on `{rk['scenario']}` {names['direct']}, "
            f"which never manoeuvres, succeeds in {fmt_value('rate', succ['direct'])} of the "
            f"episodes, the learned agents in {fmt_value('rate', min(learned))}–"
            f"{fmt_value('rate', max(learned))}."
        )
    hr = data.get("headroom")
    if hr:
        m, top = hr["metrics"][rk["metric"]], hr["vs_top"]
        out.append(
            f"Headroom: a planner that knows the future of the traffic (not an agent, not "
            f"ranked) reaches a clean success of {fmt_metric('rate', m)} on the same episodes, "
            f"{100 * top['diff']:.1f} points above the top score."
        )
    return out


def table2_beside(pub: Published, scenario: str) -> tuple[str, list[str], Rows]:
    """The paper's Table 2 rows on the headline scenario, as published."""
    rows = [(r.row, r.density, r.values) for r in pub.table("Table 2") if r.density == scenario]
    title = (
        f"The paper's Table 2 on {scenario} — published, from the paper's own simulator; "
        "not measured here and never ranked"
    )
    return (title, *published_table("agent", pub.columns2, rows))


def published_tables(pub: Published) -> list[tuple[str, list[str], Rows]]:
    """The paper's Tables 2 and 3 as transcribed: (title, header, rows)."""
    out = []
    for table, first, cols, cite in (
        ("Table 2", "agent", pub.columns2, pub.citation2),
        ("Table 3", "variant", pub.columns3, pub.citation3),
    ):
        rows = [(r.row, r.density, r.values) for r in pub.table(table)]
        out.append((f"{table} — {cite}", *published_table(first, cols, rows)))
    return out


def _headroom_note(data: dict[str, Any]) -> str:
    hr = data["headroom"]
    base = _names(data)[hr["vs_baseline"]["entry"]]
    return HEADROOM_NOTE.format(n=hr["episodes"], sc=hr["scenario"], base=base)


def render_markdown(data: dict[str, Any], pub: Published, plots: list[str]) -> str:
    ref = _names(data)[data["reference"]]
    rk = data["ranking"]
    out = [
        "# cdr-bench leaderboard",
        "",
        "Generated by `cdr-bench leaderboard build` from the submissions and result files in "
        "this folder; do not edit by hand (`cdr-bench leaderboard build --check` fails if this "
        "page differs from what the code produces). The same tables, sortable and filterable "
        "by group, with the plots and the replays of tactical episodes: `index.html`. How to "
        "add an entry: CONTRIBUTING.md, “Add a leaderboard entry”.",
        "",
        "## In one minute",
        "",
    ]
    for para in conclusion(data):
        out += [para, ""]
    head, rows, _ = ranking_table(data)
    out += [
        f"## Ranking: clean success on {rk['scenario']}",
        "",
        md_table(head, rows, numeric_from=3, text_from=len(head)),
        "",
        HEADLINE_NOTE.format(sc=rk["scenario"], down=LOWER),
        "",
    ]
    if data.get("headroom"):
        head, rows = headroom_table(data)
        out += [
            "### Headroom: what knowing the traffic achieves on the same episodes (not ranked)",
            "",
            md_table(head, rows, numeric_from=1),
            "",
            _headroom_note(data),
            "",
        ]
    title, head, rows = table2_beside(pub, rk["scenario"])
    out += [f"### {title}", "", md_table(head, rows), ""]
    head, rows, _ = seeds_table(data)
    out += ["## Seeds", "", _seeds_note(data), "", md_table(head, rows, numeric_from=2), ""]
    head, rows = claims_table(data)
    out += ["## Claims of the paper", "", CLAIMS_NOTE, "", md_table(head, rows, numeric_from=9), ""]
    if data.get("sensitivity"):
        head, rows = sensitivity_table(data)
        out += ["## Sensitivity (paper Fig. 7)", "", sensitivity_note(data), "",
                md_table(head, rows, numeric_from=3, text_from=5), ""]  # fmt: skip
    if data["tactical"]:
        head, rows, _ = tactical_table(data)
        out += ["## Tactical scenarios", "", TACTICAL_NOTE, "", md_table(head, rows), ""]
    out += _multi_agent_md(data)
    out += ["## Measured here, per scenario", "", INTRO.format(up=HIGHER, down=LOWER, ref=ref), ""]
    for t in data["tables"]:
        head, rows = scenario_table(data, t)
        fixed = " A fixed encounter: values without intervals." if t["fixed"] else ""
        out += [
            f"### {t['scenario']}",
            "",
            f"{t['description']} — {t['episodes']} episodes per entry.{fixed}",
            "",
            md_table(head, rows),
            "",
        ]
    head, rows, _ = entries_table(data)
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
    rp = data["replays"]
    if rp["entries"]:
        out += [
            "## Replays",
            "",
            f"`index.html` replays the first {rp['episodes']} episodes of "
            f"{', '.join(f'`{s}`' for s in rp['scenarios'])} (one of a multi-agent scenario) "
            f"side by side for {', '.join(_all_names(data)[n] for n in rp['entries'])}, drawn "
            "in the page from the "
            "trajectories recorded by the scorer (`results/<entry>.replays.json`).",
            "",
        ]
    out += [
        "## Reproduce",
        "",
        "```bash",
        "cdr-bench leaderboard build --evaluate     # re-run every submission (sandboxed), "
        "then render",
        "cdr-bench leaderboard build                # render from the result files only",
        "cdr-bench leaderboard build --check        # re-run and compare with this folder",
        "cdr-bench leaderboard render-docs          # only the tables in the repository's docs",
        "```",
        "",
        "`build` also rewrites the results tables in the marked blocks of the repository's "
        "README.md, agents/BASELINES.md and agents/diffusion_ac/README.md from these result "
        "files (rendered by `cdr_bench/evaluate/report.py`, the one table renderer; which block "
        "shows what: `cdr_bench/leaderboard/tables.py`).",
        "",
    ]
    return "\n".join(out)


def _multi_agent_md(data: dict[str, Any]) -> list[str]:
    """The multi-agent track's section (nothing without an entry in it)."""
    from cdr_bench.leaderboard import multi_agent as ma

    track = data.get("multi_agent")
    if not track:
        return []
    head, rows, _ = ma.ranking_table(track)
    out = ["## Multi-agent track: every aircraft controlled", ""]
    for para in ma.conclusion(track, ma._names(track)):
        out += [para, ""]
    out += [
        f"### Ranking: clean flights on {track['scenario']}",
        "",
        md_table(head, rows, numeric_from=4),
        "",
        ma.note(track),
        "",
    ]
    for t in track["tables"]:
        head, rows = ma.scenario_table(track, t)
        out += [f"### {t['scenario']} (system)", "", t["description"], "",
                md_table(head, rows, numeric_from=2), ""]  # fmt: skip
    return out


def _multi_agent_html(data: dict[str, Any]) -> list[str]:
    from cdr_bench.leaderboard import multi_agent as ma

    track = data.get("multi_agent")
    if not track:
        return []
    head, rows, groups = ma.ranking_table(track)
    b = [
        '<h2 id="multi-agent">Multi-agent track: every aircraft controlled</h2>',
        '<div class="conclusion">',
        *[f"<p>{inline_md(p)}</p>" for p in ma.conclusion(track, ma._names(track))],
        "</div>",
        f"<h3>Ranking: clean flights on {esc(track['scenario'])}</h3>",
        html_table("table-multi-agent", head, rows, groups=groups),
        f'<p class="note">{inline_md(ma.note(track))}</p>',
    ]
    for t in track["tables"]:
        head, rows = ma.scenario_table(track, t)
        b += [
            f'<h3 id="ma-{_anchor(t["scenario"])}">{esc(t["scenario"])} (system)</h3>',
            f'<p class="note">{esc(t["description"])}</p>',
            html_table("table-ma-" + _anchor(t["scenario"]), head, rows),
        ]
    return b


# ----------------------------------------------------------------------------------------------
# HTML

_CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;margin:2rem auto;max-width:1400px;
padding:0 1rem;color:#1b1f24;line-height:1.45}
h1{margin-bottom:.2rem}h2{margin-top:2.2rem;border-bottom:1px solid #d0d7de;padding-bottom:.3rem}
table{border-collapse:collapse;margin:.6rem 0 1.2rem;font-size:.86rem}
th,td{border:1px solid #d0d7de;padding:.3rem .5rem;text-align:right;white-space:nowrap}
th:nth-child(-n+2),td:nth-child(-n+2){text-align:left}
th{background:#f6f8fa}
table.sortable th{cursor:pointer;user-select:none}
table.sortable th[aria-sort=ascending]::after{content:" \\25B2"}
table.sortable th[aria-sort=descending]::after{content:" \\25BC"}
td.best{font-weight:700;background:#dafbe1}
.mark{color:#6e7781;margin-left:.2rem}
.note{color:#57606a;max-width:75rem}
.published{background:#fff8c5}
.conclusion{background:#f6f8fa;border-left:4px solid #0072B2;padding:.5rem 1rem;max-width:75rem}
#filter{position:sticky;top:0;background:#fff;padding:.4rem 0;border-bottom:1px solid #d0d7de;
z-index:2}
#filter label{margin-right:1rem}
[hidden]{display:none!important}
img{max-width:100%;border:1px solid #d0d7de;margin:.4rem 0}
code{background:#f6f8fa;padding:0 .2rem}
nav a{margin-right:1rem}
.scroll{overflow-x:auto}
.replay{margin:1rem 0 2rem}
.replay .controls{margin:.3rem 0}
.replay .controls>*{margin-right:.6rem;vertical-align:middle}
.replay .panes{display:flex;flex-wrap:wrap;gap:.8rem}
.replay figure{margin:0}
.replay canvas{border:1px solid #d0d7de;background:#fff}
.replay figcaption{font-size:.85rem;max-width:320px}
.key{font-size:.85rem;color:#57606a}
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
  /* options in the fragment: #sort=TABLE:COLUMN:DIRECTION&groups=learned,scripted */
  var opts={};
  location.hash.replace(/^#/,'').split('&').forEach(function(p){var i=p.indexOf('=');
    if(i>0){opts[p.slice(0,i)]=decodeURIComponent(p.slice(i+1))}});
  var m=/^([^:]+):(\\d+):(ascending|descending)$/.exec(opts.sort||'');
  if(m){var t=document.getElementById(m[1]);if(t){sortTable(t,Number(m[2]),m[3])}}
  document.body.setAttribute('data-sortable-tables',String(tables.length));

  /* the group filter: hides every element of an unticked group */
  var boxes=Array.prototype.slice.call(document.querySelectorAll('#filter input'));
  function applyFilter(){
    var on={};boxes.forEach(function(b){on[b.value]=b.checked});
    var hidden=0;
    Array.prototype.forEach.call(document.querySelectorAll('[data-group]'),function(el){
      var h=!on[el.getAttribute('data-group')];el.hidden=h;if(h){hidden++}});
    document.body.setAttribute('data-groups-shown',
      boxes.filter(function(b){return b.checked}).map(function(b){return b.value}).join(','));
    document.body.setAttribute('data-hidden',String(hidden));
  }
  if(opts.groups!==undefined){var want=opts.groups.split(',');
    boxes.forEach(function(b){b.checked=want.indexOf(b.value)>=0})}
  boxes.forEach(function(b){b.addEventListener('change',applyFilter)});
  applyFilter();

  /* replays: the same episodes side by side, drawn from the recorded trajectories */
  var el=document.getElementById('replay-data');
  if(!el){return}
  var RD=JSON.parse(el.textContent);
  var LEVEL=['#0072B2','#E69F00','#009E73'], LOS='#D55E00';
  var drawnCanvases=0;
  function bounds(ts){
    var x0=1e9,y0=1e9,x1=-1e9,y1=-1e9;
    function add(x,y){x0=Math.min(x0,x);y0=Math.min(y0,y);x1=Math.max(x1,x);y1=Math.max(y1,y)}
    /* the encounter: every aircraft of every frame (a far goal is an arrow at the edge) */
    ts.forEach(function(t){
      t.frames.forEach(function(f){f.c.forEach(function(a){add(a[0],a[1])});
        f.b.forEach(function(a){add(a[0],a[1])})});
    });
    var pad=ts[0].los_km*1.5,w=x1-x0+2*pad,h=y1-y0+2*pad,side=Math.max(w,h,8*ts[0].los_km);
    var cx=(x0+x1)/2,cy=(y0+y1)/2;
    return {x0:cx-side/2,y0:cy-side/2,x1:cx+side/2,y1:cy+side/2};
  }
  var NAMES={success:'success',los:'LoS',nmac:'NMAC',timeout:'timeout',
    boundary:'left the sector'};
  function outcome(t){var o=t.outcomes[0],n=t.frames.length-1;
    return (NAMES[o]||o)+(o==='success'?' in ':' at step ')+n+(o==='success'?' steps':'')}
  function drawTrace(cv,t,k,bb){
    var ctx=cv.getContext('2d'),W=cv.width,H=cv.height;
    var s=Math.min(W/(bb.x1-bb.x0),(H-24)/(bb.y1-bb.y0));
    function X(x){return (x-bb.x0)*s+(W-(bb.x1-bb.x0)*s)/2}
    function Y(y){return H-((y-bb.y0)*s+(H-24-(bb.y1-bb.y0)*s)/2)}
    k=Math.min(k,t.frames.length-1);
    var f=t.frames[k];
    ctx.fillStyle='#ffffff';ctx.fillRect(0,0,W,H);
    /* scale bar */
    var bar=[1,2,5,10,20,50,100,200].filter(function(v){return v*s<W/3}).pop()||1;
    ctx.strokeStyle='#57606a';ctx.lineWidth=2;ctx.beginPath();
    ctx.moveTo(10,H-10);ctx.lineTo(10+bar*s,H-10);ctx.stroke();
    ctx.fillStyle='#57606a';ctx.font='11px sans-serif';ctx.fillText(bar+' km',14+bar*s,H-6);
    /* goals: a crossed circle, or an arrow at the edge pointing to a goal out of view */
    t.goals_km.forEach(function(g,m){ctx.strokeStyle='#1b1f24';ctx.fillStyle='#1b1f24';
      ctx.lineWidth=1.5;var gx=X(g[0]),gy=Y(g[1]);
      if(gx>8&&gx<W-8&&gy>22&&gy<H-8){
        ctx.beginPath();ctx.arc(gx,gy,6,0,2*Math.PI);ctx.stroke();
        ctx.beginPath();ctx.moveTo(gx-4,gy);ctx.lineTo(gx+4,gy);
        ctx.moveTo(gx,gy-4);ctx.lineTo(gx,gy+4);ctx.stroke();return}
      var a0=t.frames[0].c[m],ox=X(a0[0]),oy=Y(a0[1]),ang=Math.atan2(gy-oy,gx-ox);
      var r=Math.min(W,H-24)/2-14,ex=W/2+r*Math.cos(ang),ey=(H+24)/2+r*Math.sin(ang);
      var d=Math.round(Math.hypot(g[0]-a0[0],g[1]-a0[1]));
      ctx.save();ctx.translate(ex,ey);ctx.rotate(ang);ctx.beginPath();
      ctx.moveTo(8,0);ctx.lineTo(-4,5);ctx.lineTo(-4,-5);ctx.closePath();ctx.fill();
      ctx.restore();ctx.font='10px sans-serif';
      ctx.fillText('goal '+d+' km',Math.min(Math.max(ex-30,2),W-70),ey+(ey>H/2?-9:16))});
    /* trails of the controlled aircraft */
    t.ids.forEach(function(_,m){ctx.strokeStyle=m===0?'#1b1f24':'#6e7781';ctx.lineWidth=1;
      ctx.setLineDash(m===0?[]:[3,3]);ctx.beginPath();
      for(var j=0;j<=k;j++){var a=t.frames[j].c[m];
        if(j===0){ctx.moveTo(X(a[0]),Y(a[1]))}else{ctx.lineTo(X(a[0]),Y(a[1]))}}
      ctx.stroke();ctx.setLineDash([])});
    /* background aircraft: disc in the colour of their level */
    f.b.forEach(function(a){ctx.fillStyle=LEVEL[a[2]]||'#000';ctx.beginPath();
      ctx.arc(X(a[0]),Y(a[1]),5,0,2*Math.PI);ctx.fill();
      ctx.fillStyle='#1b1f24';ctx.font='10px sans-serif';
      ctx.fillText('FL'+a[2],X(a[0])+7,Y(a[1])-5)});
    /* controlled aircraft: ownship a triangle, learning intruders squares; LoS ring */
    f.c.forEach(function(a,m){
      var x=X(a[0]),y=Y(a[1]),prev=t.frames[Math.max(k-1,0)].c[m],
        nxt=t.frames[Math.min(k+1,t.frames.length-1)].c[m];
      var dx=(k>0?a[0]-prev[0]:nxt[0]-a[0]),dy=(k>0?a[1]-prev[1]:nxt[1]-a[1]);
      var ang=(dx===0&&dy===0)?0:Math.atan2(-dy,dx);
      ctx.strokeStyle=f.los[m]?LOS:'#afb8c1';ctx.lineWidth=f.los[m]?3:1;
      ctx.setLineDash(f.los[m]?[]:[4,4]);ctx.beginPath();
      ctx.arc(x,y,t.los_km*s,0,2*Math.PI);ctx.stroke();ctx.setLineDash([]);
      ctx.save();ctx.translate(x,y);ctx.rotate(ang);ctx.beginPath();
      if(m===0){ctx.moveTo(9,0);ctx.lineTo(-6,6);ctx.lineTo(-6,-6);ctx.closePath()}
      else{ctx.rect(-5,-5,10,10)}
      ctx.fillStyle=a[3]?(LEVEL[a[2]]||'#000'):'#ffffff';ctx.fill();
      ctx.strokeStyle='#1b1f24';ctx.lineWidth=2;ctx.stroke();ctx.restore();
      ctx.fillStyle='#1b1f24';ctx.font='bold 10px sans-serif';
      ctx.fillText((m===0?'own ':'')+'FL'+a[2],x+9,y+12);
    });
    var last=k===t.frames.length-1;
    ctx.fillStyle=f.los.some(function(v){return v})?LOS:'#1b1f24';ctx.font='12px sans-serif';
    ctx.fillText('step '+k+'/'+(t.frames.length-1)+(last?'  '+outcome(t):'')
      +(f.los.some(function(v){return v})?'  LoS':''),8,14);
    if(!cv.hasAttribute('data-drawn')){drawnCanvases++;
      document.body.setAttribute('data-replay-drawn',String(drawnCanvases))}
    var r=cv.getBoundingClientRect();
    cv.setAttribute('data-drawn',String(k));
    cv.setAttribute('data-rect',[Math.round(r.left+window.scrollX),Math.round(r.top+window.scrollY),
      Math.round(r.width),Math.round(r.height)].join(','));
  }
  Array.prototype.forEach.call(document.querySelectorAll('.replay'),function(box){
    var sc=RD.scenarios[box.getAttribute('data-scenario')];
    var canvases=Array.prototype.slice.call(box.querySelectorAll('canvas'));
    var slider=box.querySelector('input[type=range]'),btn=box.querySelector('button'),
      label=box.querySelector('.step'),sel=box.querySelector('select');
    var ep=0,frame=0,timer=null;
    function traces(){return canvases.map(function(c){return sc[c.getAttribute('data-entry')][ep]})}
    function draw(){
      var ts=traces(),bb=bounds(ts),
        n=Math.max.apply(null,ts.map(function(t){return t.frames.length}));
      frame=Math.min(frame,n-1);slider.max=String(n-1);slider.value=String(frame);
      label.textContent='step '+frame+' / '+(n-1);
      canvases.forEach(function(c,i){drawTrace(c,ts[i],frame,bb);
        var cap=c.parentNode.querySelector('.outcome');
        if(cap){cap.textContent='ownship: '+outcome(ts[i])}});
      return n;
    }
    function stop(){if(timer){clearInterval(timer);timer=null}btn.textContent='play'}
    btn.addEventListener('click',function(){
      if(timer){stop();return}
      var n=draw();if(frame>=n-1){frame=0}
      btn.textContent='pause';
      timer=setInterval(function(){frame++;var n=draw();if(frame>=n-1){stop()}},250);
    });
    slider.addEventListener('input',function(){stop();frame=Number(slider.value);draw()});
    sel.addEventListener('change',function(){stop();ep=Number(sel.value);frame=1e9;draw()});
    frame=1e9;draw();  /* open on the last step: whole tracks and outcomes at a glance */
  });
})();
"""


def _groups_of(data: dict[str, Any], table: dict[str, Any]) -> list[str]:
    group = {e["name"]: e["group"] for e in data["entries"]}
    return [group[r["entry"]] for r in table["rows"]]


def _replay_html(data: dict[str, Any], replays: dict[str, dict[str, Any]]) -> list[str]:
    rp = data["replays"]
    if not rp["entries"]:
        return []
    ma = (data.get("multi_agent") or {}).get("entries", [])
    names = _all_names(data)
    group = {e["name"]: e["group"] for e in [*data["entries"], *ma]}
    payload: dict[str, Any] = {"scenarios": {}}
    b = [
        '<h2 id="replays">Replays: the same episodes side by side</h2>',
        '<p class="note">The first episodes of each replayed scenario (the same seeds '
        "as the evaluation; one episode of a multi-agent scenario, where every controlled "
        "aircraft is a square), flown by each replayed entry, drawn from the trajectories the "
        "scorer recorded (<code>results/&lt;entry&gt;.replays.json</code>). Play, pause, or drag "
        "the slider; the panes move together. Each opens on its last step.</p>",
        '<p class="key">▲ ownship (solid trail) · ■ learning intruder (dashed trail) · ● '
        "background traffic · colour = flight level: "
        '<span style="color:#0072B2">■ FL0</span> <span style="color:#E69F00">■ FL1</span> '
        '<span style="color:#009E73">■ FL2</span> (hollow: no longer flying) · ring = LoS '
        'distance around the aircraft, <span style="color:#D55E00">red</span> during a loss of '
        "separation · ⊕ goal (an arrow at the edge when out of view).</p>",
    ]
    for sid in rp["scenarios"]:
        who = [n for n in rp["entries"] if sid in replays[n]["traces"]]
        payload["scenarios"][sid] = {n: replays[n]["traces"][sid] for n in who}
        eps = replays[who[0]]["traces"][sid]
        options = "".join(
            f'<option value="{i}">episode {t["episode"]} (seed {t["seed"]})</option>'
            for i, t in enumerate(eps)
        )
        b += [
            f'<div class="replay" data-scenario="{esc(sid)}">',
            f"<h3>{esc(sid)}</h3>",
            '<div class="controls"><button type="button">play</button>'
            f'<select aria-label="episode">{options}</select>'
            '<input type="range" min="0" max="0" value="0" aria-label="step">'
            '<span class="step"></span></div>',
            '<div class="panes">',
        ]
        for n in who:
            b.append(
                f'<figure data-group="{esc(group[n])}"><canvas width="320" height="320" '
                f'data-entry="{esc(n)}"></canvas><figcaption><strong>{inline_md(names[n])}</strong>'
                ' <span class="outcome"></span></figcaption></figure>'
            )
        b += ["</div></div>"]
    blob = json.dumps(payload, sort_keys=True, separators=(",", ":")).replace("</", "<\\/")
    b.append(f'<script type="application/json" id="replay-data">{blob}</script>')
    return b


def render_html(
    data: dict[str, Any],
    pub: Published,
    plots: dict[str, bytes],
    matplotlib_version: str,
    replays: dict[str, dict[str, Any]] | None = None,
) -> str:
    """The page; ``replays``: entry -> its replays file (those named by ``data["replays"]``)."""
    ref = _names(data)[data["reference"]]
    rk = data["ranking"]
    filt = "".join(
        f'<label><input type="checkbox" value="{g}" checked> {esc(GROUP_LABEL.get(g, g))}</label>'
        for g in data["groups"]
    )
    b: list[str] = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width,initial-scale=1">',
        f'<meta name="generator" content="{GENERATOR}; plots: matplotlib {matplotlib_version}">',
        "<title>cdr-bench leaderboard</title>",
        f"<style>{_CSS}</style></head><body>",
        f'<div id="filter"><strong>Show:</strong> {filt}</div>',
        "<h1>cdr-bench leaderboard</h1>",
        '<nav><a href="#ranking">Ranking</a><a href="#seeds">Seeds</a><a href="#claims">Claims</a>'
        '<a href="#sensitivity">Sensitivity</a><a href="#tactical">Tactical</a>'
        '<a href="#replays">Replays</a><a href="#multi-agent">Multi-agent track</a>'
        '<a href="#measured">Per scenario</a>'
        '<a href="#plots">Plots</a><a href="#entries">Entries</a>'
        '<a href="#published">Published (paper)</a><a href="#side-by-side">Published vs '
        "measured</a></nav>",
        '<div class="conclusion" id="conclusion">',
        *[f"<p>{inline_md(p)}</p>" for p in conclusion(data)],
        "</div>",
        f'<h2 id="ranking">Ranking: clean success on {esc(rk["scenario"])}</h2>',
    ]
    head, rows, groups = ranking_table(data)
    b += [
        html_table("table-ranking", head, rows, groups=groups),
        f'<p class="note">{inline_md(HEADLINE_NOTE.format(sc=rk["scenario"], down=LOWER))} '
        "Click a column header to sort; tick the groups to show at the top.</p>",
    ]
    if data.get("headroom"):
        head, rows = headroom_table(data)
        b += [
            '<section id="headroom">',
            "<h3>Headroom: what knowing the traffic achieves on the same episodes (not ranked)"
            "</h3>",
            html_table("table-headroom", head, rows),
            f'<p class="note">{inline_md(_headroom_note(data))}</p>',
            "</section>",
        ]
    title, head, rows = table2_beside(pub, rk["scenario"])
    b += [
        '<section data-group="published">',
        f"<h3>{esc(title)}</h3>",
        html_table("table-published-beside", head, rows, "published"),
        "</section>",
    ]
    head, rows, groups = seeds_table(data)
    b += [
        '<h2 id="seeds">Seeds</h2>',
        f'<p class="note">{inline_md(_seeds_note(data))}</p>',
        html_table("table-seeds", head, rows, groups=groups),
    ]
    head, rows = claims_table(data)
    b += [
        '<h2 id="claims">Claims of the paper</h2>',
        f'<p class="note">{inline_md(CLAIMS_NOTE)}</p>',
        html_table("table-claims", head, rows),
    ]
    if data.get("sensitivity"):
        head, rows = sensitivity_table(data)
        b += [
            '<h2 id="sensitivity">Sensitivity (paper Fig. 7)</h2>',
            f'<p class="note">{inline_md(sensitivity_note(data))}</p>',
            html_table("table-sensitivity", head, rows),
        ]
    if data["tactical"]:
        head, rows, groups = tactical_table(data)
        b += [
            '<h2 id="tactical">Tactical scenarios</h2>',
            f'<p class="note">{inline_md(TACTICAL_NOTE)}</p>',
            html_table("table-tactical", head, rows, groups=groups),
        ]
    b += _replay_html(data, replays or {})
    b += _multi_agent_html(data)
    b += [
        '<h2 id="measured">Measured here, per scenario</h2>',
        f'<p class="note">{inline_md(INTRO.format(up=HIGHER, down=LOWER, ref=ref))}</p>',
    ]
    for t in data["tables"]:
        head, rows = scenario_table(data, t)
        fixed = " A fixed encounter: values without intervals." if t["fixed"] else ""
        b += [
            f'<h3 id="{_anchor(t["scenario"])}">{esc(t["scenario"])}</h3>',
            f'<p class="note">{esc(t["description"])} — {t["episodes"]} episodes per '
            f"entry.{fixed}</p>",
            html_table("table-" + _anchor(t["scenario"]), head, rows, groups=_groups_of(data, t)),
        ]
    b.append('<h2 id="plots">Plots</h2>')
    for name in plots:  # written beside the page, as plots/NAME (linked, not embedded)
        b.append(
            f'<figure><img alt="{esc(name)}" src="plots/{quote(name)}" loading="lazy">'
            f"<figcaption>{esc(name)}</figcaption></figure>"
        )
    head, rows, groups = entries_table(data)
    b += ['<h2 id="entries">Entries</h2>', html_table("table-entries", head, rows, groups=groups)]
    b += [
        '<section data-group="published">',
        '<h2 id="published">Published numbers (the paper; not measured here)</h2>',
        '<p class="note">Transcribed verbatim (rates in %). Claims from the paper\'s own '
        "simulator, shown as published and never ranked with the measured tables.</p>",
    ]
    for i, (title, head, rows) in enumerate(published_tables(pub)):
        b += [
            f"<h3>{esc(title)}</h3>",
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
        b += [f"<h3>{inline_md(title)}</h3>", html_table(f"table-side-{i}", head, rows)]
    b += ["</section>", f"<script>{_JS}</script>", "</body></html>", ""]
    return "\n".join(b)
