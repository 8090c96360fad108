"""Regenerate the result tables of README.md from files in the repo (never typed by hand).

Sources: ``cdr-bench evaluate`` result JSONs under ``eval/`` (written by ``evaluate_all.sh``), the
``{"final": ...}`` line of each training log (the trainer's quick evaluation), the analysis JSONs
under ``analysis/`` and the paper's Tables 2 and 3 as transcribed in ``leaderboard/published/``
(shown as *published*, never mixed with ours).

Run: python agents/diffusion_ac/report.py            (print the tables)
     python agents/diffusion_ac/report.py --update   (rewrite them inside README.md)
"""

from __future__ import annotations

import contextlib
import io
import json
import re
import sys
from pathlib import Path

import yaml

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
PUBLISHED = ROOT / "leaderboard" / "published"
METRICS = ("success_rate", "los_rate", "nmac_rate", "timeout_rate")
ABLATIONS = {  # checkpoint stem -> row of the paper's Table 3
    "full-100k": "Diffusion-AC (Complete)",
    "no-diffusion-100k": "W/O Diffusion",
    "no-double-q-100k": "W/O Double Q",
    "no-dpsc-100k": "W/O DPSC",
    "no-value-guidance-100k": "W/O Value Guidance",
}
DESIGN_RUNS = ("default-26k", "default-40k", "linear", "ce-none", "ce-noise")


def published(table: str) -> dict:
    return yaml.safe_load((PUBLISHED / f"{table}.yaml").read_text())


def final_of(log: Path) -> dict | None:
    if not log.exists():
        return None
    finals = [json.loads(x)["final"] for x in log.read_text().splitlines() if '"final"' in x]
    return finals[-1] if finals else None


def scenario_metrics(result: Path) -> dict[str, dict]:
    """scenario id -> ownship metrics of a cdr-bench evaluate result file."""
    data = json.loads(result.read_text())
    return {sc["id"]: sc["metrics"]["ownship"] for sc in data["scenarios"]}


def pct(m: dict, key: str) -> str:
    v = m[key]
    lo, hi = v["ci95"]
    return f"{100 * v['value']:.1f} [{100 * lo:.1f}, {100 * hi:.1f}]"


def steps(m: dict) -> str:
    v = m.get("avg_steps_success")
    if not isinstance(v, dict) or v.get("value") is None:
        return "—"
    return f"{v['value']:.1f}"


def measured_row(label: str, m: dict) -> str:
    cells = " | ".join(pct(m, k) for k in METRICS)
    return f"| {label} | {m['episodes']} | {cells} | {steps(m)} |"


def published_row(label: str, values: list) -> str:
    return f"| {label} | 1000 | " + " | ".join(str(v) for v in values[:5]) + " |"


HEADER = (
    "| {} | n | success % | LoS % | NMAC % | timeout % | steps (successful) |\n"
    "|---|---:|---:|---:|---:|---:|---:|"
)


def main() -> None:
    t2 = {(r["agent"], r["density"]): r["values"] for r in published("table2")["rows"]}
    t3 = {r["variant"]: r["values"] for r in published("table3")["rows"]}

    print("### Reference checkpoint on the paper suite (`cdr-bench evaluate`, 95 % intervals)\n")
    paper = HERE / "eval" / "paper.json"
    if paper.exists():
        print(HEADER.format("scenario"))
        for sid, m in scenario_metrics(paper).items():
            print(measured_row(f"{sid} — measured here", m))
            if ("Diffusion-AC", sid) in t2:
                print(published_row(f"{sid} — paper Table 2 (published)", t2["Diffusion-AC", sid]))
    ref = final_of(HERE / "training_log.jsonl")
    if ref:
        print(
            f"\nTraining: {ref['step']:,} transitions, {ref['updates']:,} updates, "
            f"{ref['wall_s'] / 60:.0f} min wall, final DPSC stage {ref['stage']} of 12."
        )

    print("\n### Table 3 ablations at 100k transitions, high density (`cdr-bench evaluate`)\n")
    print(HEADER.format("variant"))
    for stem, variant in ABLATIONS.items():
        f = HERE / "eval" / f"ablation-{stem}.json"
        if f.exists():
            print(measured_row(f"{stem} — measured here", scenario_metrics(f)["high"]))
        else:
            print(f"| {stem} — not evaluated | | | | | | |")
        print(published_row(f"{variant} — paper Table 3 (published)", t3[variant]))

    print("\n### Design decisions: short runs, same seed (trainer's quick evaluation, high)\n")
    print("| run | transitions | success % | LoS % | NMAC % | timeout % | episodes |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for name in DESIGN_RUNS:
        ev = final_of(HERE / "ablations" / f"{name}.log.jsonl")
        if not ev or "eval/high" not in ev:
            continue
        e = ev["eval/high"]
        print(
            f"| {name} | {ev['step']:,} | {100 * e['success']:.0f} | {100 * e['los']:.0f} "
            f"| {100 * e['nmac']:.0f} | {100 * e['timeout']:.0f} | {e['episodes']} |"
        )

    mm = sorted((HERE / "analysis").glob("multimodal-*.json"))
    if mm:
        print("\n### Multimodality of the first action (`cdr-bench multimodal`, Fig. 9)\n")
        print(
            "| scenario | samples | follow-on success % | modes ≥ 5 % (successful) "
            "| normalised entropy | most sampled first actions (share of all samples) |"
        )
        print("|---|---:|---:|---:|---:|---|")
        for f in mm:
            d = json.loads(f.read_text())
            allc = d["all"]
            top = sorted(range(27), key=lambda a: -allc[a])[:3]
            tops = ", ".join(f"{a} ({100 * allc[a] / d['samples']:.0f} %)" for a in top if allc[a])
            print(
                f"| {d['scenario']} | {d['samples']} | {100 * d['success_rate']:.1f} "
                f"| {d['modes']} | {d['normalised_entropy']:.3f} | {tops} |"
            )

    lat = HERE / "analysis" / "latency.json"
    if lat.exists():
        print("\n### Decision latency (`cdr-bench latency`, one thread)\n")
        print("| batch | calls | median ms/call | p99 ms/call | median ms/decision |")
        print("|---:|---:|---:|---:|---:|")
        for r in json.loads(lat.read_text())["rows"]:
            print(
                f"| {r['batch']} | {r.get('calls', '—')} | {r['median_ms']:.3f} "
                f"| {r['p99_ms']:.3f} | {r['median_ms_per_decision']:.4f} |"
            )


def update_readme() -> None:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        main()
    readme = HERE / "README.md"
    pattern = re.compile(r"(<!-- report:start -->\n).*?(<!-- report:end -->)", re.S)
    text = readme.read_text()
    if not pattern.search(text):
        raise SystemExit(f"{readme}: no <!-- report:start --> ... <!-- report:end --> block")
    readme.write_text(pattern.sub(lambda m: m[1] + buf.getvalue() + "\n" + m[2], text))


if __name__ == "__main__":
    update_readme() if "--update" in sys.argv[1:] else main()
