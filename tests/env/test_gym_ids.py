"""One Gymnasium id per shipped single-agent task, registered on import."""

from __future__ import annotations

import io
from contextlib import redirect_stdout

import gymnasium
import numpy as np
import pytest

import cdr_bench
from cdr_bench.scenarios import list_scenarios, load_scenario

TASKS = [(i, k, n) for i, k, n in cdr_bench.GYMNASIUM_TASKS if k]


def test_every_single_agent_scenario_has_an_id() -> None:
    named = {k["scenario"] for _, k, _ in TASKS}
    single = {s for s in list_scenarios() if load_scenario(s).n_controlled == 1}
    assert named == single


@pytest.mark.parametrize(("task_id", "kwargs", "steps"), TASKS)
def test_id_matches_its_scenario(task_id: str, kwargs: dict, steps: int) -> None:
    cfg = load_scenario(kwargs["scenario"])
    assert steps == cfg.time.max_steps
    spec = gymnasium.spec(task_id)
    assert spec.max_episode_steps == cfg.time.max_steps
    assert task_id.endswith(f"-v{cfg.version - 3}"), "an id's version follows its scenario's"


def test_make_and_make_vec_run_an_id() -> None:
    env = gymnasium.make("cdr_bench/HeadOn-v1")
    obs, _ = env.reset(seed=0)
    assert env.unwrapped.par_env.config.id == "tactical/head-on" and obs.shape == (42,)
    envs = gymnasium.make_vec(
        "cdr_bench/High-v0", num_envs=4, vectorization_mode="vector_entry_point"
    )
    obs, info = envs.reset(seed=0)
    assert obs.shape == (4, 42) and info["action_mask"].shape == (4, 27)
    obs, *_ = envs.step(np.full(4, 13))
    assert obs.shape == (4, 42)


def test_version_0_of_a_tactical_id_is_still_the_fixed_encounter() -> None:
    for name in ("HeadOn", "Crossing", "Overtaking"):
        fixed = gymnasium.spec(f"cdr_bench/{name}Fixed-v0").kwargs["scenario"]
        assert gymnasium.spec(f"cdr_bench/{name}-v0").kwargs["scenario"] == fixed
        assert fixed.endswith("-fixed") and load_scenario(fixed).version == 3


def test_pprint_registry_shows_the_ids() -> None:
    buf = io.StringIO()
    with redirect_stdout(buf):
        gymnasium.pprint_registry()
    text = buf.getvalue()
    assert all(i.split("/")[1] in text for i, _, _ in cdr_bench.GYMNASIUM_TASKS)
