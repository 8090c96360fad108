"""The tactical scenarios of Fig. 8 are real dilemmas (docs/model.md §8), certified by search.

For each scenario: (a) holding course, speed and level fails; (b) at least three distinct first
actions lead to success, spanning at least two of climb / level / descend. Every witness found
by the batched search is replayed independently through a fresh single-episode rollout.
"""

from __future__ import annotations

import pytest

from cdr_bench.actions import decode
from cdr_bench.evaluate.search import rollout, successful_first_actions
from cdr_bench.scenarios import load_scenario

TACTICAL = ("tactical/head-on", "tactical/crossing", "tactical/overtaking")


@pytest.mark.slow
@pytest.mark.parametrize("name", TACTICAL)
def test_tactical_scenario_is_a_dilemma(name: str) -> None:
    config = load_scenario(name)
    assert config.separation.los_terminates, "a tactical LoS must end the episode as a failure"

    assert rollout(config, []) in ("los", "nmac"), "holding must fail"

    witnesses = {a: w for a, w in successful_first_actions(config).items() if w is not None}
    assert len(witnesses) >= 3, f"only {sorted(witnesses)} succeed"
    vertical = {decode(a)[2] for a in witnesses}
    assert len(vertical) >= 2, f"successful first actions use only vertical choice {vertical}"

    for a, w in witnesses.items():
        assert w[0] == a
        assert rollout(config, w) == "success", f"witness of first action {a} does not replay"


def test_search_finds_nothing_when_every_first_action_fails() -> None:
    """A negative control: with a horizon of one step no first action can reach the goal."""
    config = load_scenario("tactical/head-on", time={"max_steps": 1})
    assert all(w is None for w in successful_first_actions(config).values())
