"""PNG plots of the leaderboard, drawn from ``leaderboard.json`` data only.

Every entry has one colour of the Okabe-Ito palette (colour-blind safe) and one marker, the same
in every plot (:func:`entry_styles`); legends sit outside the data area; intervals are 95 %.

Byte-deterministic for a given matplotlib version: Agg backend, matplotlib's default style
(whatever the user's matplotlibrc says), no ``Software`` metadata, fixed size and dpi. The
matplotlib version is recorded in ``index.html`` so that ``--check`` can tell a rendering
difference from a data difference.

Each plot is a :class:`Plot`: its file name, the function that draws it and that function's
arguments, which are exactly the part of the leaderboard data it shows (the rows, metrics,
styles and titles it reads; :func:`plot_specs`). A plot is therefore a function of its
:meth:`Plot.digest` (those arguments as canonical JSON, this module's source and the matplotlib
and numpy versions), and ``cdr-bench leaderboard build`` reuses the committed PNG of a plot whose
digest is unchanged instead of drawing it again (:func:`render_plots` with ``reuse``): the
digests and the PNGs' SHA-256 are recorded in ``plots/manifest.json`` (:data:`MANIFEST`,
:func:`plots_manifest`). A reused PNG has the bytes a redraw gives; ``--check`` never reuses a
committed PNG: it redraws every plot.

For the same reason a PNG this machine has drawn is kept in the user's cache folder, named by its
digest (:func:`plot_cache_dir`: ``$XDG_CACHE_HOME/cdr-bench/plots``, else
``~/.cache/cdr-bench/plots``; another folder, or none, with :data:`PLOT_CACHE_ENV`), and a plot
of that digest is read from there instead of drawn: by builds and by ``--check`` alike. Unlike
the committed PNGs, whoever submits an entry cannot write there (its agent runs confined), so
what the check compares is still this machine's own drawing. The folder keeps the
:data:`PLOT_CACHE_SIZE` newest PNGs.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import os
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cdr_bench import render
from cdr_bench.evaluate.report import COLUMNS
from cdr_bench.leaderboard.page_tables import DENSITIES, MAIN_COLUMNS
from cdr_bench.render import figure_png

DPI = 80
MANIFEST = "manifest.json"
"""The plots folder's record of what each PNG was drawn from (:func:`plots_manifest`)."""
PLOT_CACHE_ENV = "CDR_BENCH_PLOT_CACHE"
"""Environment variable: the folder of this machine's drawn PNGs (empty: none, every plot is
drawn); unset: :func:`plot_cache_dir`'s default."""
PLOT_CACHE_SIZE = 512
"""PNGs kept in that folder (the oldest go first)."""


def _label(key: str) -> str:
    """The column header of metric ``key`` (read from the registry when a plot is drawn)."""
    return next(c.header for c in COLUMNS if c.key == key)


OKABE_ITO = ("#000000", "#E69F00", "#56B4E9", "#009E73", "#0072B2", "#D55E00", "#CC79A7")
"""The Okabe-Ito palette (distinguishable with every common colour-vision deficiency), without
its yellow, too pale on white."""
MARKERS = ("o", "s", "^", "v", "D", "P", "X", "*", "<", ">", "p", "h", "d", "8", "H")
"""One marker per entry (with more entries than colours, the marker tells them apart)."""


def entry_styles(data: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """``entry -> {color, marker, label}``: one Okabe-Ito colour and one marker per entry, by
    its rank (the same entry looks the same in every plot; the leaders get the first colours);
    markers are hollow for the second round of colours."""
    out = {}
    names = {e["name"]: e["display_name"] for e in data["entries"]}
    for i, name in enumerate(_ranked(data)):
        out[name] = {
            "color": OKABE_ITO[i % len(OKABE_ITO)],
            "marker": MARKERS[i % len(MARKERS)],
            "mfc": OKABE_ITO[i % len(OKABE_ITO)] if (i // len(OKABE_ITO)) % 2 == 0 else "white",
            "label": names[name],
        }
    return out


def matplotlib_version() -> str:
    import matplotlib

    return str(matplotlib.__version__)


def _png(fig: Any) -> bytes:
    return figure_png(fig, DPI)


def _figure(width: float, height: float) -> tuple[Any, Any]:
    import matplotlib.pyplot as plt

    return plt.subplots(figsize=(width, height), layout="constrained")


def _legend(fig: Any) -> None:
    """The legend outside the data area, right of the axes."""
    fig.legend(loc="outside right upper", fontsize=8, frameon=False)


def _density_tables(data: dict[str, Any]) -> list[dict[str, Any]]:
    return [t for t in data["tables"] if t["scenario"] in DENSITIES]


def _ranked(data: dict[str, Any]) -> list[str]:
    """Entries in ranking order (legends follow the leaderboard)."""
    return [r["entry"] for r in data["ranking"]["rows"]]


def _err(v: float, ci: list[float | None], scale: float) -> tuple[float, float]:
    lo, hi = ci
    a = v if lo is None else scale * lo
    b = v if hi is None else scale * hi
    return max(v - a, 0.0), max(b - v, 0.0)


def _row(table: dict[str, Any], name: str) -> dict[str, Any] | None:
    """The entry's row of a table (None when the entry has none)."""
    return next((r for r in table["rows"] if r["entry"] == name), None)


def _entry_errorbars(
    ax: Any,
    style: dict[str, Any],
    tables: list[dict[str, Any]],
    name: str,
    key: str,
    scale: float,
    x: list[float],
    **kw: Any,
) -> list[float]:
    """One entry's metric ``key`` (times ``scale``) with its 95 % interval, at ``x[i]`` for
    table i, on the tables that have a value for it; ``kw``: the marker's own style. Returns
    the values drawn."""
    xs, ys, lo, hi = [], [], [], []
    for i, t in enumerate(tables):
        row = _row(t, name)
        if row is None or row["metrics"][key]["value"] is None:
            continue
        m = row["metrics"][key]
        v = scale * m["value"]
        a, b = _err(v, m["ci95"], scale)
        xs.append(x[i])
        ys.append(v)
        lo.append(a)
        hi.append(b)
    if xs:
        ax.errorbar(
            xs,
            ys,
            yerr=[lo, hi],
            color=style["color"],
            mfc=style["mfc"],
            capsize=2,
            lw=1,
            label=style["label"],
            **kw,
        )
    return ys


# ----------------------------------------------------------------------------------------------
# The plots. Each draws from its own arguments only: the part of the data it shows


def _points(
    styles: dict[str, dict[str, Any]],
    entries: list[str],
    tables: list[dict[str, Any]],
    key: str,
    kind: str,
    label: str,
    title: str,
) -> bytes:
    """One marker per entry and scenario with its 95 % interval, entries side by side."""
    fig, ax = _figure(10, 4.2)
    width = 0.8 / max(len(entries), 1)
    scale = 100.0 if kind == "rate" else 1.0
    seen = []
    for j, name in enumerate(entries):
        st = styles[name]
        x = [i - 0.4 + width * (j + 0.5) for i in range(len(tables))]
        seen += _entry_errorbars(ax, st, tables, name, key, scale, x, fmt=st["marker"], ms=6)
    ax.set_xticks(range(len(tables)), [t["scenario"] for t in tables])
    for i in range(1, len(tables)):
        ax.axvline(i - 0.5, color="0.85", lw=0.8)
    ax.set_ylabel(f"{label}" + (" (%)" if kind == "rate" else ""))
    ax.set_title(title)
    finite = [abs(v) for v in seen if math.isfinite(v) and v != 0]
    if finite and max(finite) / max(min(finite), 1e-9) > 100 and kind == "mean":
        ax.set_yscale("symlog")
    ax.grid(axis="y", alpha=0.3)
    _legend(fig)
    return _png(fig)


def _success_vs_density(
    styles: dict[str, dict[str, Any]],
    entries: list[str],
    n_entries: int,
    tables: list[dict[str, Any]],
) -> bytes:
    fig, ax = _figure(9, 4.2)
    n = max(n_entries, 1)
    for j, name in enumerate(entries):
        st = styles[name]
        x = [i + 0.3 * (j / n - 0.5) for i in range(len(tables))]
        _entry_errorbars(ax, st, tables, name, "success_rate", 100.0, x, marker=st["marker"])
    ax.set_xticks(range(len(tables)), [t["scenario"] for t in tables])
    ax.set_xlabel("traffic density")
    ax.set_ylabel("success rate (%), 95 % interval")
    ax.set_title("Success against density")
    ax.grid(alpha=0.3)
    _legend(fig)
    return _png(fig)


def _latency(
    styles: dict[str, dict[str, Any]], entries: list[str], tables: list[dict[str, Any]]
) -> bytes:
    fig, ax = _figure(10, 4.2)
    width = 0.8 / max(len(entries), 1)
    for j, name in enumerate(entries):
        xs, med, p99 = [], [], []
        for i, t in enumerate(tables):
            row = _row(t, name)
            if row is None or row["latency_ms"]["median"] is None:
                continue
            xs.append(i - 0.4 + width * (j + 0.5))
            med.append(max(row["latency_ms"]["median"], 1e-5))
            p99.append(max(row["latency_ms"]["p99"], 1e-5))
        if xs:
            st = styles[name]
            ax.scatter(xs, med, marker=st["marker"], color=st["color"], label=st["label"], zorder=3)
            ax.scatter(xs, p99, marker="_", s=80, color=st["color"], zorder=3)
    ax.set_yscale("log")
    ax.set_xticks(range(len(tables)), [t["scenario"] for t in tables])
    ax.set_ylabel("ms per decision (marker: median, dash: p99)")
    ax.set_title("Decision latency (machine-dependent; batched calls)")
    ax.grid(axis="y", alpha=0.3)
    _legend(fig)
    return _png(fig)


def pareto_front(points: list[tuple[str, float, float]]) -> list[str]:
    """Names of the non-dominated points when both coordinates are to be minimised (a point is
    dominated when another is no worse in both and better in one), in increasing x."""
    front = []
    for n, x, y in points:
        if not any(
            (x2 <= x and y2 <= y) and (x2 < x or y2 < y) for n2, x2, y2 in points if n2 != n
        ):
            front.append((x, y, n))
    return [n for _, _, n in sorted(front)]


def _pareto(styles: dict[str, dict[str, Any]], entries: list[str], table: dict[str, Any]) -> bytes:
    """Safety (LoS rate) against efficiency (extra path of successful flights) on the headline
    scenario, each with its 95 % interval, and the non-dominated front."""
    fig, ax = _figure(9, 5)
    pts = []
    for name in entries:
        row = _row(table, name)
        if row is None:
            continue
        x_m, y_m = row["metrics"]["extra_path_km"], row["metrics"]["los_rate"]
        if x_m["value"] is None or y_m["value"] is None:
            continue
        x, y = x_m["value"], 100 * y_m["value"]
        pts.append((name, x, y))
        st = styles[name]
        ax.errorbar(
            [x],
            [y],
            xerr=[[a] for a in _err(x, x_m["ci95"], 1.0)],
            yerr=[[a] for a in _err(y, y_m["ci95"], 100.0)],
            fmt=st["marker"],
            color=st["color"],
            mfc=st["mfc"],
            ms=7,
            capsize=2,
            lw=1,
            label=st["label"],
        )
    front = pareto_front(pts)
    if front:
        xy = {n: (x, y) for n, x, y in pts}
        fx = [xy[n][0] for n in front]
        fy = [xy[n][1] for n in front]
        ax.step(fx, fy, where="post", color="0.4", ls="--", lw=1, label="non-dominated front")
    xs = [x for _, x, _ in pts]
    if xs and max(xs) > 50:
        ax.set_xscale("symlog", linthresh=1.0)  # a few entries detour by hundreds of km
    ax.set_xlabel("extra path of successful flights, km (95 % interval)")
    ax.set_ylabel("LoS rate, % of episodes (95 % interval)")
    ax.set_title(f"Safety against efficiency on {table['scenario']} (lower left is better)")
    ax.grid(alpha=0.3)
    _legend(fig)
    return _png(fig)


def _curves(
    styles: dict[str, dict[str, Any]],
    names: list[str],
    series_of: dict[str, list[Any]],
    title: str,
    key: str = "series",
) -> bytes:
    """A learning curve against transitions, one line per entry (the mean over its logs, with
    the min-max band when it has several seeds): ``series``, the rolling success of training
    episodes, or ``fixed``, the clean success of the greedy policy on the fixed evaluation
    set; ``series_of``: entry -> its curves of that kind."""
    fig, ax = _figure(9, 4.5)
    for name in names:
        series = [np.asarray(s, float) for s in series_of[name] if s]
        if not series:
            continue
        st = styles[name]
        x = series[0][:, 0]
        ys = np.stack([np.interp(x, s[:, 0], s[:, 1]) for s in series])
        x = x / 1e6
        mean = 100 * ys.mean(axis=0)
        label = st["label"] + (f" ({len(series)} seeds)" if len(series) > 1 else "")
        ax.plot(
            x,
            mean,
            color=st["color"],
            marker=st["marker"],
            mfc=st["mfc"],
            markevery=max(len(x) // 8, 1),
            lw=1.2,
            label=label,
        )
        if len(series) > 1:
            ax.fill_between(
                x, 100 * ys.min(axis=0), 100 * ys.max(axis=0), color=st["color"], alpha=0.2
            )
    ax.set_xlabel("transitions (millions)")
    if key == "fixed":
        ax.set_ylabel("clean success on the fixed evaluation set (%)")
        note = "the greedy policy on the same episodes of high at every point"
    else:
        ax.set_ylabel("rolling training success (%)")
        note = (
            "the last training episodes on the scenario being trained; with a curriculum "
            "its current stage, so it drops at each promotion; not an evaluation"
        )
    ax.set_title(f"{title}\n({note})", fontsize=9)
    ax.set_ylim(-2, 102)
    ax.grid(alpha=0.3)
    _legend(fig)
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


def _sensitivity(factors: list[dict[str, Any]]) -> bytes:
    """Paper Fig. 7 beside ours: one panel per factor, our mean ± sd over seeds with the single
    seeds as dots (left axis), the paper's stated numbers on the right axis (its scale differs:
    another simulator), the values the paper recommends shaded."""
    import matplotlib.pyplot as plt

    facs = factors
    fig, axes = plt.subplots(
        1, len(facs), figsize=(3.3 * len(facs), 3.2), layout="constrained", squeeze=False
    )
    for ax, fac in zip(axes[0], facs, strict=True):
        pts = fac["points"]
        x = np.arange(len(pts))
        scale = 100.0 if fac["metric"] == "success_rate" else 1.0
        for xi, p in zip(x, pts, strict=True):
            if p["recommended"]:
                ax.axvspan(xi - 0.4, xi + 0.4, color="0.92", zorder=0)
            if p["values"]:
                ax.plot([xi] * len(p["values"]), [scale * v for v in p["values"]], ".",
                        color=OKABE_ITO[4], alpha=0.45)  # fmt: skip
        have = [(xi, p) for xi, p in zip(x, pts, strict=True) if p["mean"] is not None]
        if have:
            ax.errorbar([xi for xi, _ in have], [scale * p["mean"] for _, p in have],
                        yerr=[scale * p["sd"] for _, p in have], marker="o", capsize=3,
                        color=OKABE_ITO[4], label="measured (mean ± sd over seeds)")  # fmt: skip
        twin = ax.twinx()
        pub = [(xi, p["paper"]) for xi, p in zip(x, pts, strict=True) if p["paper"] is not None]
        twin.plot([a for a, _ in pub], [b for _, b in pub], "s--", color=OKABE_ITO[5],
                  label="paper (right axis)")  # fmt: skip
        ax.set_xticks(x, [p["value"] for p in pts])
        ax.set_xlabel(fac["name"], fontsize=8)
        word = "success rate (%)" if fac["metric"] == "success_rate" else "episode reward"
        ax.set_ylabel(f"measured {word}", fontsize=8)
        twin.set_ylabel(f"paper {word}", fontsize=8, color=OKABE_ITO[5])
        ax.tick_params(labelsize=7)
        twin.tick_params(labelsize=7, colors=OKABE_ITO[5])
    h1, l1 = axes[0][0].get_legend_handles_labels()
    h2, l2 = axes[0][0].figure.axes[-1].get_legend_handles_labels()
    fig.legend(h1 + h2, l1 + l2, loc="outside lower center", ncols=2, fontsize=8, frameon=False)
    fig.suptitle("Sensitivity (paper Fig. 7); shaded: the paper's recommended values", fontsize=9)
    return _png(fig)


# ----------------------------------------------------------------------------------------------
# What each plot draws, its digest, and rendering with reuse


@dataclass(frozen=True)
class Plot:
    """One plot: its file name, the function that draws it and that function's keyword
    arguments (JSON data: exactly the part of the leaderboard data the plot shows)."""

    name: str
    draw: Callable[..., bytes]
    args: dict[str, Any]

    def digest(self) -> str:
        """SHA-256 of everything the PNG's bytes depend on: the draw function, its arguments
        (canonical JSON: sorted keys, exact float repr), this module's source and the
        matplotlib and numpy versions."""
        return _sha256(_canonical({"draw": self.draw.__name__, "args": self.args, "code": _code()}))


def _canonical(obj: Any) -> bytes:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), ensure_ascii=False).encode()


def _sha256(b: bytes) -> str:
    return hashlib.sha256(b).hexdigest()


@functools.cache
def _code() -> dict[str, str]:
    """What the drawing code is: this module's source and the versions it draws with."""
    import PIL

    return {
        "plots.py": _sha256(Path(__file__).read_bytes()),
        "render.py": _sha256(Path(render.__file__).read_bytes()),
        "matplotlib": matplotlib_version(),
        "numpy": str(np.__version__),
        "pillow": str(PIL.__version__),
    }


def _metric_tables(
    tables: list[dict[str, Any]], entries: list[str], keys: tuple[str, ...]
) -> list[dict[str, Any]]:
    """The tables with only the rows of ``entries`` and, of each, only metrics ``keys`` (value
    and interval)."""
    return [
        {
            "scenario": t["scenario"],
            "rows": [
                {
                    "entry": r["entry"],
                    "metrics": {
                        k: {"value": r["metrics"][k]["value"], "ci95": r["metrics"][k]["ci95"]}
                        for k in keys
                    },
                }
                for r in t["rows"]
                if r["entry"] in entries
            ],
        }
        for t in tables
    ]


def _styled(data: dict[str, Any], names: list[str]) -> dict[str, dict[str, Any]]:
    """The styles of ``names`` (each entry's style depends on its rank among all)."""
    styles = entry_styles(data)
    return {n: styles[n] for n in names}


def _points_plot(
    data: dict[str, Any], name: str, tables: list[dict[str, Any]], key: str, kind: str, title: str
) -> Plot:
    entries = _ranked(data)
    return Plot(
        name,
        _points,
        {
            "styles": _styled(data, entries),
            "entries": entries,
            "tables": _metric_tables(tables, entries, (key,)),
            "key": key,
            "kind": kind,
            "label": _label(key),
            "title": title,
        },
    )


def _curve_plots(data: dict[str, Any], ranked: list[str]) -> list[Plot]:
    """The learning curves of the learned entries, of the ablations, and on the fixed
    evaluation set (each plot only when some entry has such curves)."""
    groups = {e["name"]: e["group"] for e in data["entries"]}
    curves = {c["entry"]: c for c in data["learning_curves"]}
    learned = [n for n in ranked if n in curves and groups[n] == "learned"]
    ablations = [n for n in ranked if n in curves and groups[n] == "ablation"]
    fixed = [
        n
        for n in ranked
        if n in curves and any(c["entry"] == n and c["fixed"] for c in data["learning_curves"])
    ]
    out = []
    for fname, names, title, key in (
        (
            "learning_curves.png",
            learned,
            "Learning curves: rolling success of training episodes",
            "series",
        ),
        ("learning_curves_ablations.png", ablations, "Learning curves of the ablations", "series"),
        (
            "learning_curves_fixed.png",
            fixed,
            "Learning curves on the fixed evaluation set",
            "fixed",
        ),
    ):
        if names:
            args = {
                "styles": _styled(data, names),
                "names": names,
                "series_of": {n: curves[n][key] for n in names},
                "title": title,
                "key": key,
            }
            out.append(Plot(fname, _curves, args))
    return out


def _density_plots(
    data: dict[str, Any], ranked: list[str], dens: list[dict[str, Any]]
) -> list[Plot]:
    """One plot per main metric over the density tables, success against density, latency."""
    out = []
    for c in MAIN_COLUMNS:
        title = f"{_label(c.key)} per density (95 % intervals)"
        out.append(_points_plot(data, f"{c.key}.png", dens, c.key, c.kind, title))
    styles = _styled(data, ranked)
    success = {
        "styles": styles,
        "entries": ranked,
        "n_entries": len(data["entries"]),
        "tables": _metric_tables(dens, ranked, ("success_rate",)),
    }
    out.append(Plot("success_vs_density.png", _success_vs_density, success))
    lat = [
        {
            "scenario": t["scenario"],
            "rows": [
                {
                    "entry": r["entry"],
                    "latency_ms": {
                        "median": r["latency_ms"]["median"],
                        "p99": r["latency_ms"]["p99"],
                    },
                }
                for r in t["rows"]
                if r["entry"] in ranked
            ],
        }
        for t in dens
    ]
    latency = {"styles": styles, "entries": ranked, "tables": lat}
    out.append(Plot("latency.png", _latency, latency))
    return out


def _heatmap_plot(data: dict[str, Any], mm: dict[str, Any]) -> Plot:
    """The first-action map of one ``cdr-bench multimodal`` result."""
    display = next(e["display_name"] for e in data["entries"] if e["name"] == mm["entry"])
    shown = {
        "all": mm["all"],
        "success": mm["success"],
        "samples": mm["samples"],
        "success_rate": mm["success_rate"],
        "modes": mm["modes"],
        "normalised_entropy": mm.get("normalised_entropy"),
    }
    return Plot(
        f"multimodal-{mm['entry']}-{mm['scenario'].replace('/', '_')}.png",
        _heatmap,
        {"mm": shown, "title": f"{display} on {mm['scenario']}"},
    )


def plot_specs(data: dict[str, Any]) -> list[Plot]:
    """Every plot of the leaderboard data, the headline plots first (file names are stable:
    they are linked)."""
    out: list[Plot] = []
    ranked = _ranked(data)
    head = next((t for t in data["tables"] if t["scenario"] == data["ranking"]["scenario"]), None)
    if head is not None:
        table = _metric_tables([head], ranked, ("extra_path_km", "los_rate"))[0]
        args = {"styles": _styled(data, ranked), "entries": ranked, "table": table}
        out.append(Plot("pareto.png", _pareto, args))
    out += _curve_plots(data, ranked)
    fams = [t for t in data["tactical"] if not t["fixed"]]
    if fams:  # fixed encounters are single outcomes, in the table only
        tables = [next(x for x in data["tables"] if x["scenario"] == t["scenario"]) for t in fams]
        title = "Success per tactical family (95 % intervals)"
        out.append(
            _points_plot(data, "tactical_success_rate.png", tables, "success_rate", "rate", title)
        )
    dens = _density_tables(data)
    if dens:
        out += _density_plots(data, ranked, dens)
    factors = (data.get("sensitivity") or {}).get("factors")
    if factors:
        out.append(Plot("sensitivity.png", _sensitivity, {"factors": factors}))
    out += [_heatmap_plot(data, mm) for mm in data["multimodality"]]
    return out


def _draw(plot: Plot) -> bytes:
    """The PNG of one plot (inside :func:`render_plots`' matplotlib settings)."""
    return plot.draw(**plot.args)


def plot_cache_dir() -> Path | None:
    """The folder of the PNGs this machine has drawn, by digest (module docstring), or None."""
    folder = os.environ.get(PLOT_CACHE_ENV)
    if folder is not None:
        return Path(folder) if folder else None
    from cdr_bench.evaluate.results import user_cache_dir

    return user_cache_dir("plots")


def _cached(folder: Path, digest: str) -> bytes | None:
    try:
        return (folder / f"{digest}.png").read_bytes()
    except OSError:
        return None


def _keep(folder: Path, digest: str, png: bytes) -> None:
    """Store ``png`` as ``<digest>.png`` (whole or not at all: a temporary file renamed); the
    oldest PNGs beyond :data:`PLOT_CACHE_SIZE` are removed. A folder that cannot be written is
    no error: the plot is drawn again next time."""
    try:
        folder.mkdir(parents=True, exist_ok=True, mode=0o700)
        fd, tmp = tempfile.mkstemp(prefix=".", suffix=".tmp", dir=folder)
    except OSError:
        return
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(png)
        os.replace(tmp, folder / f"{digest}.png")
    except OSError:
        Path(tmp).unlink(missing_ok=True)  # a full disk: no partial file is left behind
        return
    try:
        kept = sorted(folder.glob("*.png"), key=lambda p: p.stat().st_mtime_ns)
        for old in kept[: max(0, len(kept) - PLOT_CACHE_SIZE)]:
            old.unlink(missing_ok=True)
    except OSError:
        pass


def read_manifest(folder: Path) -> dict[str, dict[str, str]]:
    """``file name -> {"input": digest, "png": sha256}`` of the plots folder's manifest; empty
    when it is missing or unreadable (every plot is then drawn)."""
    try:
        got = json.loads((folder / MANIFEST).read_text(encoding="utf-8"))
        plots = got["plots"]
    except (OSError, ValueError, TypeError, KeyError):
        return {}
    if not isinstance(plots, dict):
        return {}
    return {
        k: v
        for k, v in plots.items()
        if isinstance(v, dict) and isinstance(v.get("input"), str) and isinstance(v.get("png"), str)
    }


def _reused(plot: Plot, folder: Path, manifest: dict[str, dict[str, str]]) -> bytes | None:
    """The committed PNG of ``plot`` when the manifest records its current digest and the file
    still has the recorded hash; None otherwise."""
    rec = manifest.get(plot.name)
    if rec is None or rec["input"] != plot.digest():
        return None
    try:
        png = (folder / plot.name).read_bytes()
    except OSError:
        return None
    return png if _sha256(png) == rec["png"] else None


def render_plots(
    data: dict[str, Any], reuse: Path | None = None, drawn: list[str] | None = None
) -> dict[str, bytes]:
    """``file name -> PNG bytes`` of every plot (names are stable: they are linked), the
    headline plots first. With ``reuse`` (a plots folder with its :data:`MANIFEST`), a plot
    whose digest the manifest records, with the PNG there unchanged, is read instead of drawn:
    the same bytes, since a plot is a function of its digest. ``drawn``: appended the names of
    the plots drawn (or read from this machine's plot cache, :func:`plot_cache_dir`: the same
    bytes again)."""
    specs = plot_specs(data)
    manifest = read_manifest(reuse) if reuse is not None else {}
    out: dict[str, bytes | None] = {
        p.name: None if reuse is None else _reused(p, reuse, manifest) for p in specs
    }
    fresh = [p for p in specs if out[p.name] is None]
    cache = plot_cache_dir()
    digests = {p.name: p.digest() for p in fresh} if cache is not None else {}
    todo = []
    for p in fresh:
        out[p.name] = _cached(cache, digests[p.name]) if cache is not None else None
        if out[p.name] is None:
            todo.append(p)
    if todo:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.style

        with matplotlib.style.context("default"), matplotlib.rc_context({"svg.hashsalt": "cdr"}):
            for p in todo:
                png = out[p.name] = _draw(p)
                if cache is not None:
                    _keep(cache, digests[p.name], png)
    if drawn is not None:
        drawn += [p.name for p in fresh]
    return {k: v for k, v in out.items() if v is not None}


def plots_manifest(data: dict[str, Any], plots: dict[str, bytes]) -> bytes:
    """``plots/manifest.json``: for each plot of ``plots``, the digest of what it was drawn
    from and the SHA-256 of its PNG (what :func:`render_plots` checks before reusing it)."""
    code = _code()
    rec = {
        p.name: {"input": p.digest(), "png": _sha256(plots[p.name])}
        for p in plot_specs(data)
        if p.name in plots
    }
    doc = {
        "about": "what each PNG of this folder was drawn from (written by `cdr-bench "
        "leaderboard build`; a plot whose input digest is unchanged is not redrawn)",
        "matplotlib": code["matplotlib"],
        "numpy": code["numpy"],
        "plots": rec,
    }
    return (json.dumps(doc, indent=1, sort_keys=True, ensure_ascii=False) + "\n").encode()
