"""The rules that turn measurements into verdicts on the paper's claims (claims.py)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

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


@dataclass
class SeededEntry:
    """An entry with one scored run per seed: ``success`` and ``clean`` counts of 1000."""

    name: str
    success: list[int]
    clean: list[int] = field(default_factory=list)

    @property
    def sub(self) -> Sub:
        return Sub(self.name)

    @property
    def runs(self) -> list[tuple[int, FakeEntry]]:
        out = []
        for i, k in enumerate(self.success):
            q = (self.clean or self.success)[i]
            run = FakeEntry(f"{self.name}.seed-{i + 1}", {"success_rate": k / 1000})
            run.counts = {"success_rate": k, "clean_success_rate": q}  # type: ignore[attr-defined]
            out.append((i + 1, run))
        return out

    def scenario(self, sid: str) -> dict[str, Any]:
        return self.runs[0][1].scenario(sid)


def _seeded_scenario(self: FakeEntry, sid: str) -> dict[str, Any]:
    counts = getattr(self, "counts", {})
    m = {k: {"value": v / 1000, "count": v, "n": 1000} for k, v in counts.items()}
    return {"metrics": {"ownship": m}} if m else FakeEntry.scenario(self, sid)


def _ablation_verdict(
    complete: list[int], ablated: list[int], monkeypatch, budgets: Any = None
) -> dict[str, Any]:
    monkeypatch.setattr(FakeEntry, "scenario", _seeded_scenario, raising=True)
    by_row = {
        cl.COMPLETE: SeededEntry("diffusion-ac", complete),
        "W/O DPSC": SeededEntry("no-dpsc", ablated),
    }
    out = cl.build_claims(by_row, FakePaired(), PUB, {}, {}, None, None, budgets)
    return next(c for c in out if c["id"] == "ablation-W/O DPSC")


def test_ablation_over_seeds_held_only_when_every_seed_pair_separates(monkeypatch) -> None:
    held = _ablation_verdict([990, 992, 995, 991, 993], [900, 910, 880], monkeypatch)
    assert held["verdict"] == "held"
    assert "= 1.00 [1.00, 1.00]" in held["measured"] and "(5 seeds) vs" in held["measured"]
    # one ablation seed as good as the complete method's seeds: the interval reaches 0.5
    mixed = _ablation_verdict([990, 992, 995, 991, 993], [900, 999, 880], monkeypatch)
    assert mixed["verdict"] == "not held"
    # success saturated (the same count everywhere): ties, P = 0.5
    tied = _ablation_verdict([999, 999, 999], [999, 999, 999], monkeypatch)
    assert tied["verdict"] == "not held" and "= 0.50 [" in tied["measured"]
    assert "= 0.50 [0.50, 0.50]" not in tied["measured"]  # episodes resampled too


def test_ablation_judged_on_clean_success_not_on_success(monkeypatch) -> None:
    """The complete method succeeds more often but loses separation more often: on clean
    success (the verdict's metric) the ablation is not worse."""
    monkeypatch.setattr(FakeEntry, "scenario", _seeded_scenario, raising=True)
    by_row = {
        cl.COMPLETE: SeededEntry("diffusion-ac", [999] * 5, [850, 852, 851, 849, 853]),
        "W/O DPSC": SeededEntry("no-dpsc", [950, 951, 949], [900, 905, 898]),
    }
    out = cl.build_claims(by_row, FakePaired(), PUB, {}, {}, None, None, None)
    row = next(c for c in out if c["id"] == "ablation-W/O DPSC")
    assert row["verdict"] == "not held" and row["test"].startswith("on clean success")
    assert row["measured"].startswith("clean success, mean over seeds: 85.1 % (5 seeds)")
    assert "success 99.9 % vs 95.0 %" in row["measured"]


def test_ablation_at_another_budget_is_not_measured(monkeypatch) -> None:
    good, bad = [990, 992, 995, 991, 993], [900, 910, 880]
    same = {"diffusion-ac": 1_374_560, "no-dpsc": 1_374_560}
    assert _ablation_verdict(good, bad, monkeypatch, same)["verdict"] == "held"
    mixed = _ablation_verdict(good, bad, monkeypatch, {**same, "no-dpsc": 100_000})
    assert mixed["verdict"] == "not measured"
    assert "1,374,560" in mixed["measured"] and "for 100,000" in mixed["measured"]
    # seeds of one entry at different budgets never equal a single budget
    spread = _ablation_verdict(good, bad, monkeypatch, {**same, "no-dpsc": [100_000, 1_374_560]})
    assert spread["verdict"] == "not measured" and "100,000-1,374,560" in spread["measured"]
    # unknown budgets (no training logs): judged as before
    assert _ablation_verdict(good, bad, monkeypatch, {"no-dpsc": 100_000})["verdict"] == "held"


def _curve(values: list[float], every: int = 50_000) -> list[list[float]]:
    return [[i * every, v] for i, v in enumerate(values)]


def test_convergence_step_is_where_the_running_mean_stays_above_the_target() -> None:
    c = _curve([0.1, 0.5, 0.8, 0.9, 0.6, 0.9, 0.9, 0.9, 0.9])
    # running means (3 points) end at points 2..8: .47 .73 .77 .80 .80 .90 .90
    assert cl.convergence_step(c, 0.75, 400_000) == 200_000  # from point 4 on, never below
    assert cl.convergence_step(c, 0.85, 400_000) == 350_000  # the dip keeps it below until 7
    assert cl.convergence_step(c, 0.95, 400_000) == 400_000  # never: the run's length
    assert cl.final_level(c) == pytest.approx(0.9)


def test_dpsc_convergence_measured_with_three_seeds_of_each() -> None:
    fast = [_curve([0.1, 0.6, 0.9, 0.9, 0.9, 0.9, 0.9, 0.9]) for _ in range(3)]
    slow = [_curve([0.1, 0.2, 0.3, 0.6, 0.9, 0.9, 0.9, 0.9, 0.9, 0.9]) for _ in range(3)]
    r = cl.dpsc_convergence([(c, 400_000) for c in fast], [(c, 500_000) for c in slow])
    assert r["target"] == pytest.approx(0.81)
    assert r["steps"] == [[200_000] * 3, [300_000] * 3]  # the mean of 3 points first >= .81
    assert r["reduction"] == pytest.approx(1 / 3) and r["ci95"] == pytest.approx([1 / 3, 1 / 3])

    def verdict(complete, ablated) -> dict[str, Any]:
        rates = {"success_rate": 0.9, "clean_success_rate": 0.8, "los_rate": 0.1, "nmac_rate": 0.01}
        by_row = {cl.COMPLETE: FakeEntry("dac", rates), "W/O DPSC": FakeEntry("nd", rates)}
        training = {"dac": complete, "nd": ablated}
        out = cl.build_claims(by_row, FakePaired(), PUB, {}, {}, None, training)
        return next(c for c in out if c["id"] == "dpsc-convergence")

    runs_f = [(c, 400_000) for c in fast]
    runs_s = [(c, 500_000) for c in slow]
    held = verdict(runs_f, runs_s)
    assert held["verdict"] == "held" and "reduction +33 % [+33, +33]" in held["measured"]
    assert "200k / 200k / 200k" in held["measured"]
    assert verdict(runs_s, runs_f)["verdict"] == "not held"  # DPSC slower
    few = verdict(runs_f[:2], runs_s)
    assert few["verdict"] == "not measured" and "Diffusion-AC (Complete) 2" in few["measured"]


def test_latency_claim_reads_the_controlled_run(tmp_path: Path) -> None:
    """The latency claim is judged on the single-decision medians of ``latency.json`` (one
    controlled run), not on the timing each result file recorded while it was scored; the
    committed pages state what the committed controlled run measured."""
    import json

    from cdr_bench.errors import UserError
    from cdr_bench.leaderboard.data import load_latency

    assert load_latency(tmp_path) == {}  # no controlled run: no latency claim
    rates = {"success_rate": 0.9, "los_rate": 0.1, "nmac_rate": 0.05, "clean_success_rate": 0.85}
    rows = {r: FakeEntry(r.lower(), dict(rates)) for r in (cl.DIFFUSION, *cl.BASELINES)}
    assert "latency" not in {c["id"] for c in cl.build_claims(rows, FakePaired(), PUB, {}, {})}
    slow = {e.name: 0.01 for e in rows.values()} | {rows[cl.DIFFUSION].name: 0.2}
    claim = {c["id"]: c for c in cl.build_claims(rows, FakePaired(), PUB, {}, slow)}["latency"]
    assert claim["verdict"] == "held" and "controlled run" in claim["measured"]
    fast = slow | {rows[cl.DIFFUSION].name: 0.001}
    claim = {c["id"]: c for c in cl.build_claims(rows, FakePaired(), PUB, {}, fast)}["latency"]
    assert claim["verdict"] == "not held"

    (tmp_path / "latency.json").write_text(json.dumps({"rows": [{"entry": "x"}]}))
    with pytest.raises(UserError, match=r"latency.json: rows\[0\]: expected"):
        load_latency(tmp_path)
    (tmp_path / "latency.json").write_text("[1, 2")
    with pytest.raises(UserError, match="latency.json: cannot read"):
        load_latency(tmp_path)

    committed = load_latency(ROOT / "leaderboard")
    page = json.loads((ROOT / "leaderboard" / "leaderboard.json").read_text())
    text = next(c for c in page["claims"] if c["id"] == "latency")["measured"]
    assert f"Diffusion-AC {committed['diffusion-ac']:.3g}," in text
