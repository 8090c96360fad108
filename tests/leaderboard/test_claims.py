"""The rules that turn measurements into verdicts on the paper's claims (claims.py)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cdr_bench.leaderboard import claims as cl
from cdr_bench.leaderboard.published import load_published

ROOT = Path(__file__).resolve().parents[2]
PUB = load_published(ROOT / "leaderboard")


@dataclass
class Sub:
    name: str


@dataclass
class FakeEntry:
    name: str
    rates: dict[str, float]
    nmac_flags: list[int] = field(default_factory=list)

    @property
    def sub(self) -> Sub:
        return Sub(self.name)

    @property
    def episodes(self) -> list[dict[str, Any]]:
        return [
            {"scenario": "high", "aircraft": [{"id": "ownship_0", "outcome": "nmac" if f else "x"}]}
            for f in self.nmac_flags
        ]

    def scenario(self, sid: str) -> dict[str, Any]:
        m = {k: {"value": v, "ci95": [v - 0.01, v + 0.01]} for k, v in self.rates.items()}
        return {"metrics": {"ownship": m}}


class FakePaired:
    """b - a = difference of the point values, interval +- 0.005 (significant unless equal)."""

    def metric(self, a: FakeEntry, b: FakeEntry, sid: str, metric: str) -> dict[str, Any]:
        d = b.rates[metric] - a.rates[metric]
        return {"diff": d, "ci95": [d - 0.005, d + 0.005] if d else [-0.005, 0.005]}


def _verdicts(by_row: dict[str, FakeEntry]) -> dict[str, str]:
    out = cl.build_claims(by_row, FakePaired(), PUB, {}, {})
    return {c["id"]: c["verdict"] for c in out}


def _agents(dac: dict[str, float], nmac_dac: list[int], nmac_next: list[int]):
    base = {"success_rate": 0.9, "los_rate": 0.10, "nmac_rate": 0.05}
    rows = {r: FakeEntry(r.lower(), dict(base)) for r in cl.BASELINES}
    rows["Safe-DQN-X"] = FakeEntry("sdqn", {**base, "nmac_rate": 0.03}, nmac_next)
    rows["Diffusion-AC"] = FakeEntry("dac", dac, nmac_dac)
    return rows


def test_best_of_five_held_only_when_significantly_best() -> None:
    n = 1000
    nmac_dac = [1] * 12 + [0] * (n - 12)
    nmac_next = [1] * 30 + [0] * (n - 30)
    good = _verdicts(
        _agents({"success_rate": 0.95, "los_rate": 0.03, "nmac_rate": 0.012}, nmac_dac, nmac_next)
    )
    assert good["best-success_rate"] == good["best-los_rate"] == good["best-nmac_rate"] == "held"
    assert good["nmac-59"] == "held"  # 1 - 12/30 = 60 %, interval covers 59 %
    tied = _verdicts(
        _agents({"success_rate": 0.9, "los_rate": 0.2, "nmac_rate": 0.012}, nmac_dac, nmac_dac)
    )
    assert tied["best-success_rate"] == "not held"  # equal to the baselines: not separated
    assert tied["best-los_rate"] == "not held"  # worse
    assert tied["nmac-59"] == "not held"  # no reduction at all
    assert tied["dpsc-convergence"] == tied["fig7"] == "not measured"
    # 2 NMAC episodes each, in different episodes: an interval that covers everything
    few_dac, few_next = [1, 1] + [0] * (n - 2), [0, 0, 1, 1] + [0] * (n - 4)
    rare = _verdicts(
        _agents({"success_rate": 0.95, "los_rate": 0.03, "nmac_rate": 0.002}, few_dac, few_next)
    )
    assert rare["nmac-59"] == "not held"  # no reduction shown, though 59 % is inside


def test_missing_rows_are_not_measured() -> None:
    v = _verdicts({})
    assert v["best-success_rate"] == "not measured"
    assert all(v[f"ablation-{r}"] == "not measured" for r in cl.ABLATED)
