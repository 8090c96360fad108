"""``cdr-bench sweep-plot``: the sensitivity figure (paper Fig. 7) from a sweep's result files.

Four panels, one per metric (rows): success rate, NMAC rate, median decision latency (ms) and
episode reward (goal + safety terms), of the ownship, averaged over the evaluated scenarios;
one column per varied factor. Each point is the mean over the trial's seeds, the error bar
one standard deviation across seeds, the dots the single runs. The "default" trial (the centre
of the one-factor-at-a-time design) is drawn in every column at the default value.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from cdr_bench.leaderboard.sensitivity import METRICS, collect, sort_key
from cdr_bench.render import figure_png


def plot_sweep(sweep_dir: Path, out: Path, json_out: Path | None = None) -> dict[str, Any]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cdr_bench.evaluate.results import atomic_write_text

    data = collect(sweep_dir)
    factors = list(data["factors"])
    fig, axes = plt.subplots(
        len(METRICS), len(factors), figsize=(3.2 * len(factors), 2.4 * len(METRICS)), squeeze=False
    )
    for j, f in enumerate(factors):
        cells = data["factors"][f]
        labels = sorted(cells, key=sort_key)
        x = np.arange(len(labels))
        for i, (k, title) in enumerate(METRICS):
            ax = axes[i][j]
            vals = [np.asarray(cells[lb][k], dtype=float) for lb in labels]
            mean = [float(np.nanmean(v)) for v in vals]
            std = [float(np.nanstd(v)) for v in vals]
            ax.errorbar(x, mean, yerr=std, marker="o", capsize=3, color="C0")
            for xi, v in zip(x, vals, strict=True):
                ax.plot([xi] * len(v), v, ".", color="C0", alpha=0.35)
            if data["defaults"][f] in labels:
                ax.axvline(labels.index(data["defaults"][f]), color="0.7", ls=":", zorder=0)
            ax.set_xticks(x, labels)
            if i == len(METRICS) - 1:
                ax.set_xlabel(f)
            if j == 0:
                ax.set_ylabel(title)
    fig.suptitle(f"{sweep_dir.name}: mean ± std over seeds ({data['trials']} trials)", fontsize=10)
    fig.tight_layout()
    atomic_write_text(out, figure_png(fig, 110))  # never replaces anything but a regular file
    if json_out is not None:
        atomic_write_text(json_out, json.dumps(data, indent=1) + "\n")
    return data
