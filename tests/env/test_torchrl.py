"""TorchRL's PettingZoo wrapper (with action masks) on every shipped scenario, with
``flat_infos=True`` (the form its collectors need: the same numeric keys every step)."""

from __future__ import annotations

import pytest

import cdr_bench
from cdr_bench.env import FLAT_INFO_KEYS

pytest.importorskip("torchrl")
from torchrl.envs.libs.pettingzoo import PettingZooWrapper  # noqa: E402
from torchrl.envs.utils import check_env_specs  # noqa: E402


@pytest.mark.parametrize("scenario", cdr_bench.list_scenarios())
def test_check_env_specs_passes(scenario: str) -> None:
    env = PettingZooWrapper(
        env=cdr_bench.parallel_env(scenario, flat_infos=True), use_mask=True, return_state=False
    )
    check_env_specs(env, seed=0)


def test_a_rollout_to_the_end_keeps_every_info() -> None:
    env = PettingZooWrapper(
        env=cdr_bench.parallel_env("tactical/head-on", flat_infos=True), use_mask=True
    )
    td = env.rollout(100)  # the head-on encounter ends within its 60-step horizon
    info = td["next", "ownship", "info"]  # TorchRL groups agents by name: ownship_0
    assert set(FLAT_INFO_KEYS) <= set(info.keys())
    assert bool(td["next", "done"][-1].all())
    assert int(info["outcome"][-1].max()) > 0  # the ownship's outcome code at the end


def test_flat_infos_have_the_same_numeric_keys_every_step() -> None:
    env = cdr_bench.parallel_env("marl/low-2", flat_infos=True)
    _, infos = env.reset(seed=0)
    seen = [infos]
    while env.agents:
        _, _, _, _, infos = env.step({a: 13 for a in env.agents})
        seen.append(infos)
    for infos in seen:
        for info in infos.values():
            assert tuple(info) == FLAT_INFO_KEYS
            assert all(isinstance(v, (int, float)) for v in info.values())
