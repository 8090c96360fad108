"""PNG plots of the leaderboard, drawn from ``leaderboard.json`` data only.

Byte-deterministic for a given matplotlib version: Agg backend, matplotlib's default style
(whatever the user's matplotlibrc says), no ``Software`` metadata, fixed size and dpi. The
matplotlib version is recorded in ``index.html`` so that ``--check`` can tell a rendering
difference from a data difference.
"""

from __future__ import annotations

import io
import math
from typing import Any

import numpy as np

from cdr_bench.evaluate.report import DENSITIES, MAIN_COLUMNS

DPI = 80
LABEL = {c.key: c.header for c in MAIN_COLUMNS}


def matplotlib_version() -> str:
    import matplotlib

    return str(matplotlib.__version__)


def _png(fig: Any) -> bytes:
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, metadata={"Software": None})
    plt.close(fig)
    return buf.getvalue()


def _density_tables(data: dict[str, Any]) -> list[dict[str, Any]]:
    return [t for t in data["tables"] if t["scenario"] in DENSITIES]


def _names(data: dict[str, Any]) -> dict[str, str]:
    return {e["name"]: e["display_name"] for e in data["entries"]}


def _grouped_bars(
    data: dict[str, Any], tables: list[dict[str, Any]], key: str, kind: str, title: str
) -> bytes:
    import matplotlib.pyplot as plt

    names = _names(data)
    entries = [e["name"] for e in data["entries"]]
    fig, ax = plt.subplots(figsize=(8, 4))
    width = 0.8 / max(len(entries), 1)
    scale = 100.0 if kind == "rate" else 1.0
    values_seen = []
    for j, name in enumerate(entries):
        xs, ys, lo, hi = [], [], [], []
        for i, t in enumerate(tables):
            row = next((r for r in t["rows"] if r["entry"] == name), None)
            if row is None or row["metrics"][key]["value"] is None:
                continue
            m = row["metrics"][key]
            v = scale * m["value"]
            a, b = (scale * x if x is not None else v for x in m["ci95"])
            xs.append(i - 0.4 + width * (j + 0.5))
            ys.append(v)
            lo.append(max(v - a, 0.0))
            hi.append(max(b - v, 0.0))
            values_seen.append(v)
        if xs:
            ax.bar(xs, ys, width, yerr=[lo, hi], capsize=3, label=names[name], color=f"C{j}")
    ax.set_xticks(range(len(tables)), [t["scenario"] for t in tables])
    ax.set_ylabel(f"{LABEL[key]}" + (" (%)" if kind == "rate" else ""))
    ax.set_title(title)
    finite = [abs(v) for v in values_seen if math.isfinite(v) and v != 0]
    if finite and max(finite) / max(min(finite), 1e-9) > 100 and kind == "mean":
        ax.set_yscale("symlog")
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    return _png(fig)


def _success_vs_density(data: dict[str, Any], tables: list[dict[str, Any]]) -> bytes:
    import matplotlib.pyplot as plt

    names = _names(data)
    fig, ax = plt.subplots(figsize=(6, 4))
    for j, e in enumerate(data["entries"]):
        xs, ys, lo, hi = [], [], [], []
        for i, t in enumerate(tables):
            row = next((r for r in t["rows"] if r["entry"] == e["name"]), None)
            if row is None:
                continue
            m = row["metrics"]["success_rate"]
            xs.append(i)
            ys.append(100 * m["value"])
            lo.append(100 * m["ci95"][0])
            hi.append(100 * m["ci95"][1])
        if xs:
            ax.plot(xs, ys, marker="o", label=names[e["name"]], color=f"C{j}")
            ax.fill_between(xs, lo, hi, alpha=0.2, color=f"C{j}")
    ax.set_xticks(range(len(tables)), [t["scenario"] for t in tables])
    ax.set_xlabel("traffic density")
    ax.set_ylabel("success rate (%), 95 % interval")
    ax.set_title("Success against density")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    return _png(fig)


def _latency(data: dict[str, Any], tables: list[dict[str, Any]]) -> bytes:
    import matplotlib.pyplot as plt

    names = _names(data)
    entries = [e["name"] for e in data["entries"]]
    fig, ax = plt.subplots(figsize=(8, 4))
    width = 0.8 / max(len(entries), 1)
    for j, name in enumerate(entries):
        xs, med, p99 = [], [], []
        for i, t in enumerate(tables):
            row = next((r for r in t["rows"] if r["entry"] == name), None)
            if row is None or row["latency_ms"]["median"] is None:
                continue
            xs.append(i - 0.4 + width * (j + 0.5))
            med.append(max(row["latency_ms"]["median"], 1e-5))
            p99.append(max(row["latency_ms"]["p99"], 1e-5))
        if xs:
            ax.bar(xs, med, width, label=names[name], color=f"C{j}")
            ax.scatter(xs, p99, marker="_", s=120, color="k", zorder=3)
    ax.set_yscale("log")
    ax.set_xticks(range(len(tables)), [t["scenario"] for t in tables])
    ax.set_ylabel("ms per decision (bar: median, dash: p99)")
    ax.set_title("Decision latency (machine-dependent; batched calls)")
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    return _png(fig)


def _heatmap(mm: dict[str, Any], title: str) -> bytes:
    """Fig. 9 style, two rows of three 3x3 panels (descend / level / climb; heading change
    across, speed change up): every sampled first action, then those whose follow-on episode
    succeeded, as shares of all samples (each row on its own colour scale, so that rare
    successes stay visible)."""
    import matplotlib.pyplot as plt

    n = max(float(sum(mm["all"])), 1.0)
    fig, axes = plt.subplots(2, 3, figsize=(11, 6.8), squeeze=False)
    for i, (label, counts) in enumerate(
        (("all sampled", mm["all"]), ("successful", mm["success"]))
    ):
        c = np.asarray(counts, float).reshape(3, 3, 3) / n  # (psi, v, h) as in cdr_bench.actions
        vmax = max(float(c.max()), 1e-9)
        im = None
        for j, panel in enumerate(("descend", "level", "climb")):
            ax = axes[i, j]
            share = c[:, :, j].T
            im = ax.imshow(share, vmin=0, vmax=vmax, cmap="viridis", origin="lower")
            ax.set_xticks(range(3), ["left 5°", "hold", "right 5°"])
            ax.set_yticks(range(3), ["-50 kt", "keep", "+50 kt"] if j == 0 else ["", "", ""])
            if j == 0:
                ax.set_ylabel(f"{label} first actions")
            ax.set_title(f"{panel}: {100 * share.sum():.1f}% of samples", fontsize=10)
            for (r, k), v in np.ndenumerate(share):
                ax.text(
                    k, r, f"{v:.2f}", ha="center", va="center", color="w" if v < vmax / 2 else "k"
                )
        assert im is not None
        fig.colorbar(im, ax=list(axes[i]), shrink=0.8, label="share of all samples")
    ent = mm.get("normalised_entropy")
    fig.suptitle(
        f"{title}: {mm['samples']} samples, follow-on success {100 * mm['success_rate']:.1f}%, "
        f"{mm['modes']} mode(s)" + (f", normalised entropy {ent:.2f}" if ent is not None else "")
    )
    return _png(fig)


def render_plots(data: dict[str, Any]) -> dict[str, bytes]:
    """``file name -> PNG bytes`` of every plot (names are stable: they are linked)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.style

    out: dict[str, bytes] = {}
    with matplotlib.style.context("default"), matplotlib.rc_context({"svg.hashsalt": "cdr"}):
        dens = _density_tables(data)
        if dens:
            for c in MAIN_COLUMNS:
                out[f"{c.key}.png"] = _grouped_bars(
                    data, dens, c.key, c.kind, f"{LABEL[c.key]} per density (95 % intervals)"
                )
            out["success_vs_density.png"] = _success_vs_density(data, dens)
            out["latency.png"] = _latency(data, dens)
        tact = [t for t in data["tables"] if t["scenario"].startswith("tactical/")]
        if tact:
            out["tactical_success_rate.png"] = _grouped_bars(
                data, tact, "success_rate", "rate", "Success on the tactical scenarios"
            )
        names = _names(data)
        for mm in data["multimodality"]:
            fname = f"multimodal-{mm['entry']}-{mm['scenario'].replace('/', '_')}.png"
            out[fname] = _heatmap(mm, f"{names[mm['entry']]} on {mm['scenario']}")
    return out
