"""Tables from result files: the plain-text summary printed by ``cdr-bench evaluate`` and the
Markdown reference table written by ``cdr-bench report`` (results/README.md). Reads results only.
"""

from __future__ import annotations

import re
import textwrap
from typing import Any

_COLUMNS = (
    ("success", "success_rate", "rate"),
    ("LoS", "los_rate", "rate"),
    ("NMAC", "nmac_rate", "rate"),
    ("timeout", "timeout_rate", "rate"),
    ("ended by LoS", "los_terminated_rate", "rate"),
    ("boundary", "boundary_rate", "rate"),
    ("steps (success)", "avg_steps_success", "mean"),
    ("clean success", "clean_success_rate", "rate"),
    ("R_G", "goal_reward", "mean"),
    ("R_S", "safety_reward", "mean"),
    ("invalid", "invalid_action_rate", "rate"),
)


def _fmt(m: dict[str, Any], kind: str, ci: bool) -> str:
    v = m.get("value")
    if v is None:
        return "-"
    lo, hi = m.get("ci95", [None, None])
    if kind == "rate":
        s = f"{100 * v:.1f}%"
        return f"{s} [{100 * lo:.1f}, {100 * hi:.1f}]" if ci and lo is not None else s
    s = f"{v:.2f}"
    return f"{s} [{lo:.2f}, {hi:.2f}]" if ci and lo is not None else s


def _rows(result: dict[str, Any], ci: bool) -> list[list[str]]:
    rows = []
    for sc in result["scenarios"]:
        lat = result.get("timing", {}).get("decision_latency", {}).get(sc["id"], {})
        per = lat.get("per_decision_ms", {})
        lat_s = f"{per['median']:.3g} / {per['p99']:.3g}" if per.get("median") is not None else "-"
        for role, m in sc["metrics"].items():
            row = [sc["id"], role, str(m["episodes"])]
            row += [_fmt(m[key], kind, ci) for _, key, kind in _COLUMNS]
            row.append(lat_s)
            rows.append(row)
    return rows


HEADER = ["scenario", "aircraft", "n"] + [c[0] for c in _COLUMNS] + ["latency ms med/p99"]


def summary_table(result: dict[str, Any]) -> str:
    """Plain-text table of every scenario and role (point values; intervals are in the JSON)."""
    rows = [HEADER] + _rows(result, ci=False)
    widths = [max(len(r[i]) for r in rows) for i in range(len(HEADER))]
    lines = [
        "  ".join(
            c.rjust(w) if i > 1 else c.ljust(w)
            for i, (c, w) in enumerate(zip(r, widths, strict=True))
        )
        for r in rows
    ]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return f"agent {result['agent']['name']} ({result['agent']['path']})\n" + "\n".join(lines)


def markdown_table(results: list[tuple[str, dict[str, Any]]], ci: bool = True) -> str:
    """One Markdown table over several results (``(path, result)`` pairs), one row per agent,
    scenario and role, with 95 % intervals."""
    head = ["agent"] + HEADER
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * 3 + "---:|" * (len(head) - 3)]
    for _path, res in results:
        for row in _rows(res, ci):
            lines.append("| " + " | ".join([res["agent"]["name"], *row]) + " |")
    return "\n".join(lines)


def results_readme(results: list[tuple[str, dict[str, Any]]], command: str) -> str:
    """The text of results/README.md."""
    r0 = results[0][1]
    files = "\n".join(
        f"- `{p}`: agent `{r['agent']['path']}` sha256 `{r['agent']['sha256'][:16]}`, "
        f"base seed {r['base_seed']}, {sum(s['episodes'] for s in r['scenarios'])} episodes"
        for p, r in results
    )
    intro = textwrap.fill(
        f"cdr-bench {r0['versions'].get('cdr-bench')}, numpy {r0['versions'].get('numpy')}, "
        f"python {r0['versions'].get('python')}. Rates are per episode with 95 % Wilson "
        "intervals; means (steps of successful episodes, episode sums of the goal and safety "
        "rewards R_G / R_S) with 95 % bootstrap intervals. LoS counts episodes with at least one "
        "loss of separation whatever the outcome (an NMAC is also a LoS); success, NMAC, "
        "timeout, ended by LoS (only where a LoS ends the episode) and boundary (only where "
        "leaving the sector ends it) partition the episodes. Latency is per decision (one "
        "batched call / decisions in it), in ms, machine-dependent.",
        width=96,
    )
    return f"""# Reference results

Generated from the result files below by `{command}`; do not edit by hand.

{intro}

{markdown_table(results)}

Result files:

{files}
"""


def compact_table(results: list[tuple[str, dict[str, Any]]]) -> str:
    """Point values of the paper's five metrics and clean success, one row per agent and
    scenario (ownship): the table of the top-level README."""
    keys = [
        ("success", "success_rate"),
        ("LoS", "los_rate"),
        ("NMAC", "nmac_rate"),
        ("timeout", "timeout_rate"),
        ("steps (success)", "avg_steps_success"),
        ("clean success", "clean_success_rate"),
    ]
    lines = [
        "| agent | scenario | episodes | " + " | ".join(k for k, _ in keys) + " |",
        "|---|---|" + "---:|" * (len(keys) + 1),
    ]
    for _path, res in results:
        for sc in res["scenarios"]:
            m = sc["metrics"]["ownship"]
            cells = [
                _fmt(m[key], "mean" if key.startswith("avg") else "rate", False) for _, key in keys
            ]
            lines.append(
                f"| {res['agent']['name']} | {sc['id']} | {sc['episodes']} | "
                + " | ".join(cells)
                + " |"
            )
    return "\n".join(lines)


MARKER = "reference-agents"


def update_marked_block(text: str, block: str, marker: str = MARKER) -> str:
    """Replace the text between ``<!-- marker:start -->`` and ``<!-- marker:end -->``."""
    pattern = re.compile(rf"(<!-- {marker}:start -->\n).*?(<!-- {marker}:end -->)", re.S)
    if not pattern.search(text):
        raise ValueError(f"no <!-- {marker}:start --> ... <!-- {marker}:end --> block")
    return pattern.sub(lambda m: m.group(1) + block + "\n" + m.group(2), text)
