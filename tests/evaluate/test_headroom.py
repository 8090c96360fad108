"""The headroom planner (:mod:`cdr_bench.evaluate.headroom`): its plans are flown by the
evaluator's runner, its result replays like any entry's, and it does better than holding."""

from __future__ import annotations

import json
import lzma
from pathlib import Path

import pytest

from cdr_bench.errors import UserError
from cdr_bench.evaluate.headroom import headroom_result, plan
from cdr_bench.evaluate.results import read_episodes, read_result
from cdr_bench.evaluate.seeds import episode_seeds
from cdr_bench.leaderboard.verify import replay_result
from cdr_bench.scenarios import load_scenario


@pytest.fixture(scope="module")
def planned(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("headroom") / "high.json"
    headroom_result(load_scenario("high"), 1, 24, out, batch_size=12)
    return out


def test_plans_are_clean_where_holding_is_not(planned: Path) -> None:
    result = read_result(planned)
    own = result["scenarios"][0]["metrics"]["ownship"]
    records = read_episodes(planned, result)
    # holding all the way (Direct) has a LoS in about half of the episodes of high
    held = [
        r["aircraft"][0]["manoeuvres"] == 0 and r["aircraft"][0]["los_events"] > 0 for r in records
    ]
    assert not any(held)
    assert own["clean_success_rate"]["count"] >= 22  # 99 % on the leaderboard's episodes
    assert result["agent"]["name"] == "headroom" and result["split"] == "validation"
    seeds = episode_seeds(1, "high", load_scenario("high").config_hash(), 0, 24)
    assert [r["seed"] for r in records] == seeds


def test_result_replays_and_a_changed_decision_is_found(planned: Path, tmp_path: Path) -> None:
    assert replay_result(planned) == (24, [])
    # one decision of one episode changed (hold -> left turn) in the stored log
    result = json.loads(planned.read_text())
    log = planned.with_name(result["episodes_file"])
    lines = lzma.decompress(log.read_bytes()).decode().splitlines(keepends=True)
    k = next(i for i, line in enumerate(lines) if '"actions":"' in line and i > 0)
    start = lines[k].index('"actions":"') + len('"actions":"')
    lines[k] = lines[k][:start] + ("a" if lines[k][start] != "a" else "b") + lines[k][start + 1 :]
    text = "".join(lines)
    import hashlib

    result["episodes_sha256"] = hashlib.sha256(text.encode()).hexdigest()
    forged = tmp_path / "high.json"
    forged.write_text(json.dumps(result, indent=1) + "\n")
    forged.with_name(result["episodes_file"]).write_bytes(lzma.compress(text.encode()))
    n, diffs = replay_result(forged)
    assert diffs and "high" in diffs[0]


def test_plan_is_deterministic_and_refuses_several_controlled_aircraft() -> None:
    config = load_scenario("high")
    seeds = [int(s) for s in episode_seeds(7, "high", config.config_hash(), 0, 3)]
    a, b = plan(config, seeds), plan(config, seeds)
    assert all((x == y).all() for x, y in zip(a, b, strict=True))
    with pytest.raises(UserError, match="controlled aircraft"):
        plan(load_scenario("marl/low-2"), seeds)
