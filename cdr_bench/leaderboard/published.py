"""The paper's published numbers (``leaderboard/published/table2.yaml``, ``table3.yaml``),
read as they were transcribed. They are claims from the paper's own simulator: shown in their own
section and beside our measurements, never ranked with them.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from cdr_bench.errors import UserError

# published column -> our metric key (None: no counterpart)
METRIC_OF_COLUMN: dict[str, str] = {
    "success_rate": "success_rate",
    "los_rate": "los_rate",
    "nmac_rate": "nmac_rate",
    "timeout_rate": "timeout_rate",
    "average_steps": "avg_steps_success",
    "average_goal_reward": "goal_reward",
    "average_safety_reward": "safety_reward",
}


@dataclass(frozen=True)
class PublishedRow:
    table: str
    """``Table 2`` or ``Table 3``."""
    row: str
    """Agent (Table 2) or variant (Table 3) as printed."""
    density: str
    values: dict[str, float]
    """Published column -> value (rates in %)."""
    episodes: int | None = None
    """Episodes behind the row in the paper (the table's ``episodes``; None if not stated)."""


@dataclass(frozen=True)
class Published:
    citation2: str
    citation3: str
    columns2: tuple[str, ...]
    columns3: tuple[str, ...]
    rows: tuple[PublishedRow, ...]

    def names(self) -> set[str]:
        return {r.row for r in self.rows}

    def table(self, table: str) -> list[PublishedRow]:
        return [r for r in self.rows if r.table == table]

    def lookup(self, row: str, density: str) -> PublishedRow | None:
        for r in self.rows:
            if r.row == row and r.density == density:
                return r
        return None


def _load(path: Path) -> dict[str, Any]:
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as e:
        raise UserError(f"{path}: cannot read published numbers ({e})") from None
    if not isinstance(data, dict) or not {"citation", "columns", "rows"} <= set(data):
        raise UserError(f"{path}: expected citation, columns and rows")
    for col in data["columns"]:
        if col not in METRIC_OF_COLUMN:
            raise UserError(f"{path}: unknown column {col!r}")
    if not isinstance(data.get("episodes", 0), int):
        raise UserError(f"{path}: episodes: expected an integer")
    for i, r in enumerate(data["rows"]):
        if len(r.get("values", [])) != len(data["columns"]):
            raise UserError(f"{path}: rows[{i}]: expected {len(data['columns'])} values")
    return data


def _rows(table: str, data: dict[str, Any], name: str, row_density: bool) -> list[PublishedRow]:
    """The rows of one loaded table, named by their field ``name`` (``agent``, ``variant``), at
    their own ``density`` (``row_density``) or at the table's."""
    return [
        PublishedRow(
            table,
            r[name],
            r["density"] if row_density else data["density"],
            dict(zip(data["columns"], r["values"], strict=True)),
            data.get("episodes"),
        )
        for r in data["rows"]
    ]


def load_published(leaderboard_dir: str | os.PathLike[str]) -> Published:
    d = Path(leaderboard_dir) / "published"
    t2, t3 = _load(d / "table2.yaml"), _load(d / "table3.yaml")
    rows = _rows("Table 2", t2, "agent", row_density=True)
    rows += _rows("Table 3", t3, "variant", row_density=False)
    return Published(
        citation2=t2["citation"],
        citation3=t3["citation"],
        columns2=tuple(t2["columns"]),
        columns3=tuple(t3["columns"]),
        rows=tuple(rows),
    )
