"""The sensitivity study (paper Fig. 7): the trials of a one-factor-at-a-time sweep, read from
their result files, beside the numbers the paper states, and one claim per factor.

Inputs, both in the leaderboard folder:

* ``sensitivity.yaml``: ``trials:``, the folder of the study's finished trials relative to that
  file (one sub-folder per trial holding the sweep's ``trial.json`` and the result file it
  names: what ``cdr-bench sweep`` writes and ``sweeps/seeds/ship.py --stage`` lands). Without
  this file the leaderboard has no sensitivity section and the claim is "not measured".
* ``published/fig7.yaml``: per factor, the paper's grid values and numbers, the metric it
  reports, and the values it recommends.

Nothing is evaluated here (the leaderboard reads result files only). A trial's number is the
mean over its evaluated scenarios of the ownship's metric (:func:`trial_metrics`); a grid
value's is the mean over its seeds, with their standard deviation.

**The rule of each factor's claim** (written when 18 of the 45 trials had landed: seeds 1 and 2
of the T and temperature points): *held* when the grid value with the best mean over seeds lies
in the paper's recommended set **and** each of its seeds beats each seed of every grid value
outside that set (with three seeds a side, a one-sided Mann-Whitney test at p = 0.05: U = 0);
*not held* otherwise; *not measured* while a grid value has fewer than :data:`MIN_SEEDS` seeds.
The rule is applied to the **clean success** (:data:`JUDGED`: success without any loss of
separation), the paper's own metric (success, or the episode reward for the Polyak coefficient)
shown beside it: success is nearly saturated on these scenarios (flying straight to the goal
reaches it in most episodes), so it cannot separate the grid values. The trials are trained
for a fraction of the reference recipe's transitions (``budgets``), which the section and each
claim state: an early-training study.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from cdr_bench.errors import UserError
from cdr_bench.evaluate.results import read_result
from cdr_bench.leaderboard.page_tables import study_value

CONFIG = "sensitivity.yaml"
PUBLISHED = Path("published") / "fig7.yaml"
MIN_SEEDS = 3
"""Seeds every grid value needs before its factor's claim is judged (issue 16: three)."""

METRICS: tuple[tuple[str, str], ...] = (
    ("success", "success rate"),
    ("clean_success", "clean success rate"),
    ("nmac", "NMAC rate"),
    ("latency_ms", "decision latency (ms, median)"),
    ("reward", "episode reward"),
)
"""What :func:`trial_metrics` gives per trial (and ``cdr-bench sweep-plot`` draws)."""
JUDGED = "clean_success"
"""The metric every factor's claim is judged on (the paper's is shown beside it)."""
OF_PUBLISHED = {"success_rate": "success", "reward": "reward"}
"""The paper's metric of a factor (``published/fig7.yaml``) -> ours."""
TEST = (
    "best mean over seeds inside the paper's recommended values, and each of its seeds above "
    "each seed of every value outside them (3 seeds a side: one-sided Mann-Whitney, p = 0.05)"
)


def trial_metrics(result: dict[str, Any]) -> dict[str, float]:
    """The numbers of one result file, each the mean over its scenarios (ownship)."""
    rows: dict[str, list[float]] = {k: [] for k, _ in METRICS}
    for s in result["scenarios"]:
        own = s["metrics"]["ownship"]
        rows["success"].append(own["success_rate"]["value"])
        rows["clean_success"].append(own["clean_success_rate"]["value"])
        rows["nmac"].append(own["nmac_rate"]["value"])
        rows["reward"].append(own["goal_reward"]["value"] + own["safety_reward"]["value"])
        lat = result.get("timing", {}).get("decision_latency", {}).get(s["id"], {})
        rows["latency_ms"].append(lat.get("per_decision_ms", {}).get("median", math.nan))
    return {k: float(np.mean(v)) for k, v in rows.items()}


def _read_json(path: Path) -> Any:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise UserError(f"{path}: cannot read ({e})") from None


def _trial(tj: Path) -> tuple[dict[str, Any], dict[str, float], list[list[Any]]]:
    rec = _read_json(tj)
    need = {"factor": str, "label": str, "seed": int, "result": str, "train_flags": dict}
    if not isinstance(rec, dict):
        raise UserError(f"{tj}: expected the trial record of `cdr-bench sweep`")
    for k, t in need.items():
        if not isinstance(rec.get(k), t) or isinstance(rec.get(k), bool):
            raise UserError(f"{tj}: field {k!r}: expected {t.__name__}, got {rec.get(k)!r}")
    rp = (tj.parent / rec["result"]).resolve()
    if tj.parent.resolve() not in rp.parents:
        raise UserError(f"{tj}: field 'result': {rec['result']!r} is outside the trial's folder")
    res = _read_json(rp)
    stored = isinstance(res, dict) and all(  # archived (schema 3) results carry metrics
        isinstance(sc, dict) and "metrics" in sc for sc in res.get("scenarios") or [{}]
    )
    if not stored:
        try:
            res = read_result(rp)  # metrics computed from the per-episode log
        except ValueError as e:
            why = str(e).removeprefix(f"{rp}: ")
            raise UserError(f"{rp}: not a cdr-bench result file ({why})") from None
    try:
        scen = [[s["id"], int(s["episodes"])] for s in res["scenarios"]]
        return rec, trial_metrics(res), scen
    except (KeyError, TypeError, ValueError) as e:
        raise UserError(f"{rp}: not a cdr-bench result file (missing {e})") from None


def sort_key(label: str) -> tuple[int, float, str]:
    try:
        return (1, float(label), label)
    except ValueError:
        return (0, 0.0, label)


def collect(sweep_dir: Path, factors: list[str] | None = None) -> dict[str, Any]:
    """``{"factors": {factor: {label: {metric: [per trial], "seed": [...]}}}, "defaults",
    "trials", "scenarios"}``; the centre ("default") trial counts in every factor at its value,
    the factors of the trials and those named in ``factors`` (a grid whose other points have
    not landed yet)."""
    trials = [_trial(tj) for tj in sorted(Path(sweep_dir).glob("*/trial.json"))]
    if not trials:
        raise UserError(f"{sweep_dir}: no finished trials (*/trial.json)")
    fixed: dict[str, Any] = next(
        (r["train_flags"] for r, _, _ in trials if r["factor"] == "default"), {}
    )
    names = {r["factor"] for r, _, _ in trials if r["factor"] != "default"} | set(factors or [])
    factors = sorted(names) or ["default"]
    data: dict[str, dict[str, dict[str, list[Any]]]] = {f: {} for f in factors}
    defaults = {f: str(fixed[f]) if f in fixed else "default" for f in factors}
    for rec, m, _ in sorted(trials, key=lambda t: (t[0]["seed"], t[0]["factor"], t[0]["label"])):
        targets = factors if rec["factor"] == "default" else [rec["factor"]]
        for f in targets:
            label = defaults[f] if rec["factor"] == "default" else rec["label"]
            cell = data[f].setdefault(label, {**{k: [] for k, _ in METRICS}, "seed": []})
            for k, _ in METRICS:
                cell[k].append(m[k])
            cell["seed"].append(rec["seed"])
    budgets = sorted({r["train_flags"].get("total-steps") for r, _, _ in trials}, key=str)
    return {
        "factors": data,
        "defaults": defaults,
        "trials": len(trials),
        "scenarios": trials[0][2],
        "budgets": budgets,
    }


def _num(x: Any, where: str) -> float:
    if isinstance(x, bool) or not isinstance(x, int | float) or not math.isfinite(x):
        raise UserError(f"{where}: expected a number, got {x!r}")
    return float(x)


def load_fig7(lb_dir: Path) -> dict[str, Any]:
    """``published/fig7.yaml``, checked: :class:`UserError` naming the file and field."""
    path = Path(lb_dir) / PUBLISHED
    try:
        d = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as e:
        raise UserError(f"{path}: cannot read the paper's Fig. 7 numbers ({e})") from None
    if not isinstance(d, dict) or not isinstance(d.get("factors"), dict) or not d["factors"]:
        raise UserError(f"{path}: expected `citation` and a mapping `factors`")
    if not isinstance(d.get("citation"), str):
        raise UserError(f"{path}: citation: expected a string")
    for f, spec in d["factors"].items():
        w = f"{path}: factors.{f}"
        if not isinstance(spec, dict):
            raise UserError(f"{w}: expected a mapping")
        for k in ("name", "statement"):
            if not isinstance(spec.get(k), str):
                raise UserError(f"{w}.{k}: expected a string")
        if spec.get("metric") not in OF_PUBLISHED:
            raise UserError(f"{w}.metric: expected one of {', '.join(OF_PUBLISHED)}")
        if not isinstance(spec.get("values"), dict) or not spec["values"]:
            raise UserError(f"{w}.values: expected a mapping grid value -> number")
        for k, v in spec["values"].items():
            _num(k, f"{w}.values")
            _num(v, f"{w}.values.{k}")
        rec = spec.get("recommended")
        if not isinstance(rec, list) or not rec:
            raise UserError(f"{w}.recommended: expected a list of grid values")
        for v in rec:
            _num(v, f"{w}.recommended")
    return d


def _same(a: str, b: float) -> bool:
    try:
        return float(a) == float(b)
    except ValueError:
        return False


def _r(x: float) -> float | None:
    return None if not math.isfinite(x) else round(float(x), 6)


def study_data(collected: dict[str, Any], fig7: dict[str, Any], source: str) -> dict[str, Any]:
    """The leaderboard's ``sensitivity`` section: per factor of the paper's Fig. 7, every grid
    value (ours or the paper's) with our per-seed values, mean and standard deviation, and the
    paper's number; non-numeric labels (the temperature column's annealed "default") are left
    out: they are no point of the paper's grid. The trials' decision latencies are not shown:
    each was measured while other trials shared the CPU, so they do not compare."""
    factors = []
    for f, spec in fig7["factors"].items():
        ours = collected["factors"].get(f, {})
        key = OF_PUBLISHED[spec["metric"]]
        labels = {lb for lb in ours if sort_key(lb)[0] == 1}
        for v in spec["values"]:
            if not any(_same(lb, v) for lb in labels):
                labels.add(f"{v:g}" if isinstance(v, float) else str(v))
        points = []
        for lb in sorted(labels, key=sort_key):
            cell = ours.get(lb, {})
            vals = [float(x) for x in cell.get(key, [])]
            clean = [float(x) for x in cell.get(JUDGED, [])]
            paper = next((float(pv) for pk, pv in spec["values"].items() if _same(lb, pk)), None)
            points.append(
                {
                    "value": lb,
                    "seeds": list(cell.get("seed", [])),
                    "values": [_r(x) for x in vals],
                    "mean": _r(float(np.mean(vals))) if vals else None,
                    "sd": _r(float(np.std(vals))) if vals else None,
                    "clean": [_r(x) for x in clean],
                    "clean_mean": _r(float(np.mean(clean))) if clean else None,
                    "clean_sd": _r(float(np.std(clean))) if clean else None,
                    "recommended": any(_same(lb, v) for v in spec["recommended"]),
                    "paper": paper,
                }
            )
        factors.append(
            {
                "factor": f,
                "name": spec["name"],
                "metric": spec["metric"],
                "statement": spec["statement"],
                "recommended": [f"{float(v):g}" for v in spec["recommended"]],
                "points": points,
            }
        )
    return {
        "source": source,
        "citation": fig7["citation"],
        "trials": collected["trials"],
        "scenarios": collected["scenarios"],
        "budgets": collected.get("budgets", []),
        "min_seeds": MIN_SEEDS,
        "factors": factors,
    }


def load_study(lb_dir: Path) -> dict[str, Any] | None:
    """The ``sensitivity`` section from ``<lb_dir>/sensitivity.yaml`` (None without it)."""
    cfg = Path(lb_dir) / CONFIG
    if not cfg.exists():
        return None
    try:
        d = yaml.safe_load(cfg.read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as e:
        raise UserError(f"{cfg}: cannot read ({e})") from None
    if not isinstance(d, dict) or not isinstance(d.get("trials"), str) or set(d) != {"trials"}:
        raise UserError(f"{cfg}: expected exactly one field, trials: <folder of landed trials>")
    folder = (cfg.parent / d["trials"]).resolve()
    if not folder.is_dir():
        raise UserError(f"{cfg}: trials: {d['trials']!r} is not a folder (from {cfg.parent})")
    fig7 = load_fig7(lb_dir)
    return study_data(collect(folder, list(fig7["factors"])), fig7, d["trials"])


def claim_rows(
    section: dict[str, Any] | None, reference_budget: int | None = None
) -> list[dict[str, str]]:
    """One claim per factor (see the module's rule), in the shape of the claims table;
    ``reference_budget``: the training transitions of the reference Diffusion-AC entry, beside
    which the trials' budget is stated."""
    src = "§5.3.2, Fig. 7"
    if section is None:
        return [
            {
                "id": "fig7",
                "claim": "Fig. 7 trends (T, temperature, Polyak tau, critic size)",
                "source": src,
                "published": "e.g. success 84.6 % at T = 8, 94.2 % at T = 10",
                "measured": "no sensitivity study (leaderboard/sensitivity.yaml)",
                "verdict": "not measured",
                "test": "-",
            }
        ]
    out = []
    scen = ", ".join(s for s, _ in section["scenarios"])
    budgets = [b for b in section.get("budgets", []) if isinstance(b, int)]
    early = ""
    if len(budgets) == 1:
        early = f"early training: {budgets[0]:,} transitions per trial"
        if reference_budget:
            early += (
                f" ({100 * budgets[0] / reference_budget:.0f} % of the reference Diffusion-AC's "
                f"{reference_budget:,})"
            )
        early += "; "
    for fac in section["factors"]:
        m, pts = fac["metric"], fac["points"]
        word = "success" if m == "success_rate" else "episode reward"
        rec = ", ".join(fac["recommended"])
        row = {
            "id": f"fig7-{fac['factor']}",
            "claim": f"Fig. 7: {fac['name']}: best {word} at {rec}",
            "source": src,
            "published": fac["statement"],
            "test": f"on clean success: {TEST}",
        }
        short = [p for p in pts if len(p["clean"]) < section["min_seeds"]]
        cells = "; ".join(
            f"{p['value']}: {study_value('success_rate', p['clean_mean'], p['clean_sd'])} "
            f"({len(p['clean'])}; {word} {study_value(m, p['mean'])})"
            for p in pts
        )
        head = (
            f"{early}clean success mean ± sd over seeds (n; the paper's metric beside it) on "
            f"{scen}: {cells}"
        )
        if short:
            row |= {
                "measured": f"{head}; waiting for {section['min_seeds']} seeds at "
                + ", ".join(p["value"] for p in short),
                "verdict": "not measured",
            }
        else:
            best = max(pts, key=lambda p: p["clean_mean"])
            outside = [p for p in pts if not p["recommended"]]
            overlap = [p["value"] for p in outside if min(best["clean"]) <= max(p["clean"])]
            if not best["recommended"]:
                why, verdict = f"best at {best['value']}, outside the paper's values", "not held"
            elif overlap:
                why = f"best at {best['value']}, not separated from {', '.join(overlap)}"
                verdict = "not held"
            else:
                why, verdict = f"best at {best['value']}, above every seed outside", "held"
            row |= {"measured": f"{head}; {why}", "verdict": verdict}
        out.append(row)
    return out
