"""The training environment: DPSC promotion, the training-only penalty and cut, the split
reward, restarts, and its saved state."""

import pickle

import numpy as np

from cdr_bench.rl.curriculum import N_STAGES, Curriculum, CurriculumEnv
from cdr_bench.sim.core import LOS, NMAC, TIMEOUT


def test_curriculum_promotes_on_the_rolling_success_of_the_stage():
    c = Curriculum(window=4, threshold=0.75)
    assert not any(c.record(s) for s in (True, False, True))  # window not full yet
    assert c.record(True) and c.stage == 2 and c.success_rate() == 0.0  # 3/4: promoted, cleared
    assert not any(c.record(s) for s in (True, False, False, True))  # 2/4 < 0.75
    last = Curriculum(window=1, threshold=0.0, start=N_STAGES)
    assert not last.record(True) and last.stage == N_STAGES  # training stays on stage 12


def test_penalty_cut_split_reward_and_restarts():
    env = CurriculumEnv(8, seed=0, scenario="high", failure_penalty=5.0, max_episode_steps=30)
    rng = np.random.default_rng(0)
    outcomes, cut_seen = [], False
    for _ in range(80):
        acting = env.flying
        assert acting.all()  # single ownship, restarted in the step its episode ended
        st = env.step(rng.integers(0, 27, acting.shape))
        res = st.result
        failed = np.isin(res.outcome, (LOS, NMAC))
        assert np.array_equal(st.reward, res.reward - 5.0 * failed)
        assert np.allclose(st.goal_reward + st.safety_reward, st.reward)
        assert np.array_equal(st.goal_reward, res.goal_reward)
        # A flight that ends ends its (single-aircraft) episode; a terminal step always ends it.
        assert np.array_equal(st.flight_ended[:, 0], st.episode_done)
        assert not (st.terminated & ~st.flight_ended).any()
        cut = st.truncated & ~res.truncated  # the 30-step training cut
        cut_seen |= bool(cut.any())
        assert np.array_equal(st.final_action_mask, res.action_mask)
        steps = env.env.sim.steps
        assert (steps[st.episode_done] == 0).all() and (steps[~st.episode_done] > 0).all()
        outcomes += env.take_outcomes()
    assert cut_seen and TIMEOUT in outcomes and len(outcomes) == env.episodes >= 16
    assert env.success_rate() == np.mean(np.array(outcomes[-100:]) == 1)


def test_promotion_rebuilds_the_env_for_the_next_stage():
    env = CurriculumEnv(4, seed=1, curriculum=Curriculum(window=2, threshold=0.0))
    assert env.config.id == "curriculum/stage-01" and env.stage == 1
    for _ in range(500):
        acting = env.flying
        st = env.step(np.full(acting.shape, 13))
        if st.promoted:
            break
    assert st.promoted and env.stage == 2 and env.config.id == "curriculum/stage-02"
    # Every episode restarted on the new stage; those in flight were discarded, not counted.
    assert st.episode_done.all() and np.array_equal(st.flight_ended, st.result.acting)
    assert env.take_promotions() == [2] and env.take_promotions() == []
    assert env.flying.all() and (env.env.sim.steps == 0).all()
    assert env.episodes == len(env.take_outcomes()) >= 2
    assert np.array_equal(st.obs, env.observe()[0])


def test_saved_state_continues_exactly():
    a = CurriculumEnv(6, seed=2, curriculum=Curriculum(window=3, threshold=0.0))
    a.curriculum.stage = 4  # type: ignore[union-attr]
    a.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(20):
        a.step(rng.integers(0, 27, (6, 1)))
    b = CurriculumEnv(6, seed=99, curriculum=Curriculum(window=3, threshold=0.0))
    b.load_state_dict(pickle.loads(pickle.dumps(a.state_dict())))
    assert b.stage == a.stage and b.episodes == a.episodes
    for _ in range(200):
        actions = rng.integers(0, 27, (6, 1))
        sa, sb = a.step(actions), b.step(actions)
        assert np.array_equal(sa.obs, sb.obs) and np.array_equal(sa.reward, sb.reward)
        assert sa.promoted == sb.promoted
    assert a.stage == b.stage > 4 and a.take_outcomes() == b.take_outcomes()


def test_los_penalty_counts_the_aircraft_in_conflict():
    """The extra training penalty is los_penalty x (aircraft in LoS or NMAC with the ownship this
    step), recovered from the step's own los and nmac terms; the same episodes otherwise."""
    from cdr_bench.sim.core import REWARD_TERMS

    kw = dict(seed=3, scenario="high", max_episode_steps=40)
    a, b = CurriculumEnv(8, **kw), CurriculumEnv(8, los_penalty=2.0, **kw)
    rng = np.random.default_rng(5)
    hit = 0
    for _ in range(60):
        act = rng.integers(0, 27, a.flying.shape)
        sa, sb = a.step(act), b.step(act)
        ra = sa.result
        assert np.array_equal(ra.outcome, sb.result.outcome)  # the penalty changes no dynamics
        n = np.rint(-ra.terms[..., REWARD_TERMS.index("los")] / 0.5) + np.rint(
            -ra.terms[..., REWARD_TERMS.index("nmac")] / 1.0
        )
        assert np.array_equal(sb.reward, sa.reward - 2.0 * n)
        hit += int((n > 0).sum())
    assert hit > 0  # random flight at high density meets conflicts: the test saw some


def test_soft_boundary_is_the_reference_runs_reward_on_every_stage():
    """--soft-boundary trains with sector.boundary_margin_km null on every stage the curriculum
    builds (random flights then never end as boundary); the default keeps the margin."""
    from cdr_bench.rl.common import TrainArgs, training_env
    from cdr_bench.sim.core import BOUNDARY

    soft = training_env(TrainArgs(n_envs=16, seed=2, soft_boundary=True))
    hard = training_env(TrainArgs(n_envs=16, seed=2))
    assert soft.config.sector.boundary_margin_km is None
    assert hard.config.sector.boundary_margin_km == 50
    rng = np.random.default_rng(0)
    ends = {}
    for name, env in (("soft", soft), ("hard", hard)):
        out = []
        for _ in range(150):
            env.step(rng.integers(0, 27, env.flying.shape))
            out += env.take_outcomes()
        ends[name] = out
    assert BOUNDARY in ends["hard"] and BOUNDARY not in ends["soft"]
    soft.curriculum.stage = 12
    soft._build()  # what a promotion does
    assert soft.scenario == "curriculum/stage-12" and soft.config.sector.boundary_margin_km is None
