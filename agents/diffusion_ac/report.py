"""Regenerate the result tables of README.md from files in the repo (never typed by hand).

Reads the ``{"final": ...}`` line of each shipped training log (quick evaluation on the batched
simulator, seeds 10000.., argmax inference) and, when present, ``cdr-bench evaluate`` result
JSONs under ``agents/diffusion_ac/eval/``. Published numbers are the paper's Tables 2 and 3,
marked as published.

Run: python agents/diffusion_ac/report.py
"""

from __future__ import annotations

import json
from pathlib import Path

HERE = Path(__file__).resolve().parent

# Published (paper Table 2, Diffusion-AC row; Table 3, high density). Percent.
PAPER_TABLE2 = {
    "low": {"success": 100, "los": 0.2, "nmac": 0, "timeout": 0, "steps": 258},
    "medium": {"success": 96.9, "los": 0.7, "nmac": 0.3, "timeout": 2.8, "steps": 279},
    "high": {"success": 94.1, "los": 2.8, "nmac": 1.2, "timeout": 4.7, "steps": 302},
}
PAPER_TABLE3 = {
    "complete": (94.1, 2.8, 1.2, 4.7, 302),
    "no-diffusion": (89.2, 12.3, 6.4, 4.4, 342),
    "no-double-q": (91.3, 4.5, 2.1, 6.6, 323),
    "no-dpsc": (87.6, 6.4, 2.9, 9.5, 350),
    "no-value-guidance": (4.1, 26.2, 11.2, 84.7, 953),
}


def final_of(log: Path) -> dict | None:
    if not log.exists():
        return None
    finals = [json.loads(x)["final"] for x in log.read_text().splitlines() if '"final"' in x]
    return finals[-1] if finals else None


def row(name: str, ev: dict, extra: str = "") -> str:
    return (
        f"| {name} | {100 * ev['success']:.1f} | {100 * ev['los']:.1f} | {100 * ev['nmac']:.1f} "
        f"| {100 * ev['timeout']:.1f} | {ev['steps_success']:.0f} | {ev['episodes']} |{extra}"
    )


def main() -> None:
    hdr = "| {} | success % | LoS % | NMAC % | timeout % | steps (successful) | episodes |"
    sep = "|---|---:|---:|---:|---:|---:|---:|"
    ref = final_of(HERE / "training_log.jsonl")
    print("### Reference checkpoint, quick evaluation (argmax, seeds 10000..)\n")
    print(hdr.format("density"))
    print(sep)
    for d in ("low", "medium", "high"):
        if ref and f"eval/{d}" in ref:
            print(row(f"{d} (cdr-bench, measured)", ref[f"eval/{d}"]))
        p = PAPER_TABLE2[d]
        print(
            f"| {d} (paper Table 2, published) | {p['success']} | {p['los']} | {p['nmac']} "
            f"| {p['timeout']} | {p['steps']} | 1000 |"
        )
    if ref:
        print(
            f"\nTraining: {ref['step']} transitions, {ref['updates']} updates, "
            f"{ref['wall_s'] / 60:.1f} min wall, final DPSC stage {ref['stage']}."
        )
    evals = sorted((HERE / "eval").glob("*.json")) if (HERE / "eval").exists() else []
    if evals:
        print("\n### `cdr-bench evaluate` (official scorer, 95 % Wilson intervals)\n")
        print("| file | scenario | n | success % | LoS % | NMAC % | timeout % | clean success % |")
        print("|---|---|---:|---:|---:|---:|---:|---:|")
    for f in evals:
        for sc in json.loads(f.read_text())["scenarios"]:
            m = sc["metrics"]["ownship"]

            def pct(k, m=m):
                v = m[k]
                lo, hi = v["ci95"]
                return f"{100 * v['value']:.1f} [{100 * lo:.1f}, {100 * hi:.1f}]"

            print(
                f"| eval/{f.name} | {sc['id']} | {m['episodes']} | {pct('success_rate')} "
                f"| {pct('los_rate')} | {pct('nmac_rate')} | {pct('timeout_rate')} "
                f"| {pct('clean_success_rate')} |"
            )
    print("\n### Short runs (same seed and budget), high density quick evaluation\n")
    print(hdr.format("variant") + " transitions | published (Table 3: succ/LoS/NMAC/timeout) |")
    print(sep + "---:|---|")
    for log in sorted((HERE / "ablations").glob("*.log.jsonl")):
        name = log.name.removesuffix(".log.jsonl")
        ev = final_of(log)
        if not ev or "eval/high" not in ev:
            print(f"| {name} | not finished | | | | | | | |")
            continue
        pub = PAPER_TABLE3.get("complete" if name.startswith("default") else name)
        pub_s = "/".join(str(x) for x in pub[:4]) if pub else "—"
        print(row(name, ev["eval/high"], f" {ev['step']} | {pub_s} |"))
    print("\n### Short runs, all densities (success % / LoS % / NMAC %)\n")
    print("| variant | low | medium | high |")
    print("|---|---|---|---|")
    for log in sorted((HERE / "ablations").glob("*.log.jsonl")):
        ev = final_of(log)
        if not ev:
            continue
        cells = []
        for d in ("low", "medium", "high"):
            e = ev.get(f"eval/{d}")
            cells.append(
                f"{100 * e['success']:.0f} / {100 * e['los']:.0f} / {100 * e['nmac']:.0f}"
                if e
                else "—"
            )
        print(f"| {log.name.removesuffix('.log.jsonl')} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
