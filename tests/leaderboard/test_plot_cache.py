"""The leaderboard's plots are functions of their digests: a build keeps each committed PNG whose
input (the part of the data it draws, the plotting code, the matplotlib version) is unchanged,
with the bytes a redraw gives, and draws only the plots that show what changed; a plot this
machine has drawn is read from its plot cache (by digest), also by ``--check``."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest

from cdr_bench.evaluate.report import COLUMNS
from cdr_bench.leaderboard import plots
from cdr_bench.leaderboard.plots import (
    MANIFEST,
    PLOT_CACHE_ENV,
    plots_manifest,
    read_manifest,
    render_plots,
)


def _metrics(v: float) -> dict[str, Any]:
    return {c.key: {"value": v, "ci95": [0.9 * v, min(1.1 * v, 1.0)]} for c in COLUMNS}


def _data(scenarios: tuple[str, ...]) -> dict[str, Any]:
    """Leaderboard data of three entries on ``scenarios`` (the first is the headline), with a
    learning curve for each learned entry and one first-action map."""
    names = {"a": "learned", "b": "scripted", "c": "learned"}
    counts = [(7 * i) % 11 for i in range(27)]
    return {
        "entries": [{"name": n, "display_name": n.upper(), "group": g} for n, g in names.items()],
        "ranking": {"scenario": scenarios[0], "rows": [{"entry": n} for n in names]},
        "tables": [
            {
                "scenario": sc,
                "rows": [
                    {
                        "entry": n,
                        "metrics": _metrics(0.2 + 0.1 * i + 0.05 * j),
                        "latency_ms": {"median": 0.1 * (i + 1), "p99": 0.3 * (i + 1)},
                    }
                    for i, n in enumerate(names)
                ],
            }
            for j, sc in enumerate(scenarios)
        ],
        "tactical": [{"scenario": "tactical/head-on", "fixed": False}],
        "learning_curves": [
            {"entry": n, "series": [[[0, 0.1], [5000, 0.3 + k / 10], [10000, 0.6]]], "fixed": []}
            for k, n in enumerate(("a", "c"))
        ],
        "multimodality": [
            {
                "entry": "a",
                "scenario": "tactical/head-on",
                "all": counts,
                "success": [c // 2 for c in counts],
                "samples": sum(counts),
                "success_rate": 0.5,
                "modes": 2,
                "normalised_entropy": 0.7,
            }
        ],
        "sensitivity": None,
    }


def _commit(folder: Path, data: dict[str, Any], pngs: dict[str, bytes]) -> None:
    """What a build writes into the plots folder."""
    folder.mkdir(exist_ok=True)
    for name, png in pngs.items():
        (folder / name).write_bytes(png)
    (folder / MANIFEST).write_bytes(plots_manifest(data, pngs))


def test_a_kept_plot_has_the_bytes_of_a_redraw(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Real drawing (four plots): unchanged data draws nothing and gives the committed bytes;
    a changed learning curve redraws that plot only, and every PNG equals a full redraw."""
    monkeypatch.setenv(PLOT_CACHE_ENV, "")  # every render draws
    data = _data(("tactical/head-on",))
    full = render_plots(data)
    assert list(full) == [
        "pareto.png",
        "learning_curves.png",
        "tactical_success_rate.png",
        "multimodal-a-tactical_head-on.png",
    ]
    _commit(tmp_path, data, full)
    drawn: list[str] = []
    assert render_plots(data, reuse=tmp_path, drawn=drawn) == full
    assert drawn == []

    changed = copy.deepcopy(data)
    changed["learning_curves"][1]["series"][0][1][1] = 0.2
    drawn = []
    kept = render_plots(changed, reuse=tmp_path, drawn=drawn)
    assert drawn == ["learning_curves.png"]
    assert kept["learning_curves.png"] != full["learning_curves.png"]
    assert kept == render_plots(changed)  # byte for byte, in the same order


@pytest.fixture
def counted(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The plots drawn (drawing replaced by the digest, so that no matplotlib runs; no plot
    cache, which would keep these stand-ins)."""
    names: list[str] = []
    monkeypatch.setenv(PLOT_CACHE_ENV, "")

    def draw(p: plots.Plot) -> bytes:
        names.append(p.name)
        return f"png of {p.digest()}".encode()

    monkeypatch.setattr(plots, "_draw", draw)
    return names


def _redrawn(folder: Path, data: dict[str, Any], counted: list[str]) -> list[str]:
    counted.clear()
    out = render_plots(data, reuse=folder)
    assert out == render_plots(data)  # a full redraw
    redrawn = counted[: len(counted) - len(out)]
    _commit(folder, data, out)
    return sorted(redrawn)


def test_only_the_plots_that_show_a_change_are_drawn(tmp_path: Path, counted: list[str]) -> None:
    data = _data(("high", "low", "tactical/head-on"))
    every = sorted(render_plots(data))
    assert len(every) == 4 + len([c for c in COLUMNS if not c.detail]) + 2
    assert _redrawn(tmp_path, data, counted) == every  # no manifest yet
    assert read_manifest(tmp_path).keys() == set(every)
    assert _redrawn(tmp_path, data, counted) == []

    row_b = {sc: i for i, sc in enumerate(("high", "low", "tactical/head-on"))}
    data["tables"][row_b["low"]]["rows"][1]["latency_ms"]["median"] = 0.15  # b's latency
    assert _redrawn(tmp_path, data, counted) == ["latency.png"]

    data["tables"][row_b["high"]]["rows"][1]["metrics"]["los_rate"]["value"] = 0.35
    assert _redrawn(tmp_path, data, counted) == ["los_rate.png", "pareto.png"]

    data["tables"][row_b["tactical/head-on"]]["rows"][2]["metrics"]["success_rate"]["ci95"] = [
        0.1,
        0.9,
    ]
    assert _redrawn(tmp_path, data, counted) == ["tactical_success_rate.png"]

    data["multimodality"][0]["modes"] = 3
    assert _redrawn(tmp_path, data, counted) == ["multimodal-a-tactical_head-on.png"]

    data["entries"][1]["display_name"] = "Bee"  # a legend label: every plot that shows b
    shown_b = [p for p in every if not p.startswith(("learning_curves", "multimodal"))]
    assert _redrawn(tmp_path, data, counted) == shown_b

    data["entries"][0]["display_name"] = "Ay"  # a also titles its map
    assert _redrawn(tmp_path, data, counted) == every


def test_a_changed_png_code_or_matplotlib_is_redrawn(
    tmp_path: Path, counted: list[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    data = _data(("high", "low", "tactical/head-on"))
    every = sorted(render_plots(data))
    _redrawn(tmp_path, data, counted)
    (tmp_path / "latency.png").write_bytes(b"edited")
    (tmp_path / "pareto.png").unlink()
    assert _redrawn(tmp_path, data, counted) == ["latency.png", "pareto.png"]
    code = dict(plots._code(), matplotlib="0.0")
    monkeypatch.setattr(plots, "_code", lambda: code)
    assert _redrawn(tmp_path, data, counted) == every
    (tmp_path / MANIFEST).write_text("{not json")
    assert read_manifest(tmp_path) == {}
    assert _redrawn(tmp_path, data, counted) == every


def test_a_plot_is_drawn_once_per_machine(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Real drawing: the plot cache holds each PNG drawn under its digest, and a render (with or
    without a committed folder to reuse, as ``--check``) reads it from there with the bytes a
    drawing gives; a PNG of another input is drawn; an unwritable cache is no error."""
    data = _data(("tactical/head-on",))
    monkeypatch.setenv(PLOT_CACHE_ENV, "")
    full = render_plots(data)
    cache = tmp_path / "cache"
    monkeypatch.setenv(PLOT_CACHE_ENV, str(cache))
    assert render_plots(data) == full
    specs = {p.name: p for p in plots.plot_specs(data)}
    assert sorted(x.name for x in cache.iterdir()) == sorted(
        f"{p.digest()}.png" for p in specs.values()
    )
    names: list[str] = []

    def draw(p: plots.Plot) -> bytes:
        names.append(p.name)
        raise AssertionError("drawn although this machine has drawn it")

    monkeypatch.setattr(plots, "_draw", draw)
    drawn: list[str] = []
    assert render_plots(data, drawn=drawn) == full and names == []
    assert drawn == list(full)  # not reused from a committed folder: as drawn
    changed = copy.deepcopy(data)
    changed["learning_curves"][1]["series"][0][1][1] = 0.2
    with pytest.raises(AssertionError, match="drawn although"):
        render_plots(changed)
    assert names == ["learning_curves.png"]

    monkeypatch.undo()
    (tmp_path / "file").write_text("")
    monkeypatch.setenv(PLOT_CACHE_ENV, str(tmp_path / "file" / "cache"))  # cannot be made
    assert render_plots(data) == full
