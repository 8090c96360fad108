"""The off-policy loop collects from ``--n-envs`` episodes at once: one simulator step of all of
them and one ``act`` call for all their flying aircraft per iteration, and one update per
``update_every`` transitions whatever the number of episodes."""

import pytest


@pytest.mark.parametrize("n_envs", [1, 8])
def test_one_act_call_per_step_of_every_episode_and_the_update_ratio(n_envs, tmp_path, monkeypatch):
    from cdr_bench.rl import train_safe_dqn
    from cdr_bench.rl.curriculum import CurriculumEnv
    from cdr_bench.rl.offpolicy import train
    from cdr_bench.rl.safe_dqn import SafeDQN

    rows: list[int] = []
    flying: list[int] = []
    act, step = SafeDQN.act, CurriculumEnv.step

    def recording_act(self, obs, mask, explore):
        if explore:
            rows.append(len(obs))
        return act(self, obs, mask, explore)

    def recording_step(self, actions):
        flying.append(int(self.flying.sum()))
        return step(self, actions)

    monkeypatch.setattr(SafeDQN, "act", recording_act)
    monkeypatch.setattr(CurriculumEnv, "step", recording_step)
    args = train_safe_dqn.Args(
        run_dir=str(tmp_path), total_steps=400, learning_starts=100, update_every=4,
        batch_size=16, width=16, n_envs=n_envs, progress=False, eval_episodes=0,
        curve_every=0, checkpoint_every=10**6,
    )  # fmt: skip
    summary = train(train_safe_dqn.ALGORITHM, args)
    # every environment step acted for every flying aircraft of the N episodes in one call
    assert rows == [f for f in flying if f], (rows[:10], flying[:10])
    assert max(rows) <= n_envs
    if n_envs > 1:
        assert max(rows) > 1
    assert sum(flying) == summary["step"]
    # one update per 4 transitions from learning_starts on (up to the last step's rounding)
    expected = (summary["step"] - args.learning_starts) / args.update_every
    assert abs(summary["updates"] - expected) <= n_envs / args.update_every + 1
