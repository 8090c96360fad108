"""Imitation, then RL (cdr_bench/rl/imitation.py, ``--teacher``): the demonstrations are the
teacher's actions with the returns of the training reward, and fitting them makes the PPO
policy act as the teacher."""

from __future__ import annotations

import dataclasses
import importlib.util
import json

import numpy as np
import pytest

pytest.importorskip("torch")

from cdr_bench.rl.common import TrainArgs, training_env  # noqa: E402
from cdr_bench.rl.imitation import TEACHER_SEED_OFFSET, demonstrations  # noqa: E402

from .helpers import ROOT, cdr_bench  # noqa: E402

ARGS = TrainArgs(n_envs=3, curriculum=False, scenario="high", seed=4, gamma=0.9)


def _direct():
    spec = importlib.util.spec_from_file_location("direct", ROOT / "agents/direct/agent.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.Agent(None, None)


def test_demonstrations_are_the_teachers_actions_and_returns() -> None:
    teacher = _direct()
    data = demonstrations(teacher.act_batch, ARGS, 400)
    n = len(data["action"])
    assert n >= 400 and all(len(v) == n for v in data.values())
    assert (data["action"] == teacher.act_batch(data["obs"], data["mask"])).all()
    assert data["has_ret"].mean() > 0.5

    # Slot 0 flown again by hand in the teacher's own episode stream: row 0 is its first step,
    # and its return is the discounted sum of the training reward to the end of its flight.
    env = training_env(dataclasses.replace(ARGS, seed=ARGS.seed + TEACHER_SEED_OFFSET))
    obs, mask = env.observe()
    rewards = []
    while True:
        acting = env.flying
        actions = np.full(acting.shape, 13, dtype=np.int64)
        actions[acting] = teacher.act_batch(obs[acting], mask[acting])
        st = env.step(actions)
        rewards.append(float(st.reward[0, 0]))
        if st.flight_ended[0, 0]:
            break
        obs, mask = st.obs, st.action_mask
    assert not st.truncated[0, 0]
    want = sum(ARGS.gamma**k * r for k, r in enumerate(rewards))
    assert data["has_ret"][0] and data["ret"][0] == pytest.approx(want, rel=1e-5)
    assert data["action"][0] == teacher.act_batch(data["obs"][:1], data["mask"][:1])[0]


def test_maskable_ppo_imitates_its_teacher(tmp_path) -> None:
    d = tmp_path / "run"
    r = cdr_bench(
        "train", "maskable-ppo", "--run-dir", str(d), "--total-steps", "1", "--n-envs", "4",
        "--no-curriculum", "--scenario", "high", "--eval-episodes", "0", "--curve-every", "0",
        "--no-progress", "--n-steps", "8", "--n-epochs", "1",
        "--teacher", "agents/direct", "--teacher-transitions", "4000", "--teacher-epochs", "4",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    rows = [json.loads(x) for x in (d / "log.jsonl").read_text().splitlines()]
    t = next(x for x in rows if "teacher/agreement_after" in x)
    assert t["teacher/transitions"] >= 4000
    assert t["teacher/agreement_before"] < 0.5 < 0.95 < t["teacher/agreement_after"]
    assert json.loads((d / "args.json").read_text())["teacher"] == "agents/direct"


@pytest.mark.parametrize(
    ("algo", "teacher", "message"),
    [
        ("td3", "agents/direct", "PPO and MaskablePPO only"),
        ("ppo", "agents/no-such-agent", "no-such-agent"),
    ],
)
def test_bad_teacher_is_a_clear_error(tmp_path, algo, teacher, message) -> None:
    r = cdr_bench(
        "train", algo, "--run-dir", str(tmp_path / "r"), "--total-steps", "1", "--n-envs", "2",
        "--no-progress", "--eval-episodes", "0", "--teacher", teacher,
    )  # fmt: skip
    assert r.returncode != 0
    assert message in r.stderr and "Traceback" not in r.stderr


@pytest.mark.parametrize(
    "bad",
    [
        lambda o, m: np.full(len(o), 27),  # out of range
        lambda o, m: np.zeros(len(o) + 1, np.int64),  # wrong length
        lambda o, m: np.zeros(len(o)) + 0.5,  # not integers
        lambda o, m: 1 / 0,  # raises
    ],
)
def test_a_bad_teacher_is_a_user_error(bad) -> None:
    from cdr_bench.errors import UserError

    with pytest.raises(UserError, match="--teacher: act_batch"):
        demonstrations(bad, ARGS, 10)
