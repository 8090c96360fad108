"""The batched environment and its Gymnasium vector face: auto-reset, final observations, the
same episodes as the PettingZoo env, and a CleanRL-style masked PPO update on it."""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest

import cdr_bench
from cdr_bench.actions import HOLD
from cdr_bench.gym_env import OwnshipVectorEnv
from cdr_bench.vector_env import VectorEnv


def _feasible(rng: np.random.Generator, masks: np.ndarray) -> np.ndarray:
    """One random feasible action per row of (..., 27) masks."""
    flat = masks.reshape(-1, masks.shape[-1]).astype(bool)
    return np.array([rng.choice(np.flatnonzero(m)) for m in flat]).reshape(masks.shape[:-1])


def test_make_vec_vector_entry_point_gives_the_native_vector_env():
    envs = gymnasium.make_vec(
        "cdr_bench/Ownship-v0", num_envs=5, vectorization_mode="vector_entry_point", scenario="low"
    )
    assert isinstance(envs, OwnshipVectorEnv)
    obs, info = envs.reset(seed=3)
    assert obs.shape == (5, 42) and obs.dtype == np.float32
    assert info["action_mask"].shape == (5, 27) and envs.action_masks().dtype == bool
    assert envs.single_action_space == gymnasium.spaces.Discrete(27)
    assert envs.observation_space.shape == (5, 42)
    envs.close()


def test_same_step_autoreset_returns_the_new_episode_and_the_final_observation():
    envs = OwnshipVectorEnv(num_envs=4, scenario="tactical/head-on")  # LoS ends it quickly
    obs, info = envs.reset(seed=0)
    seeds = info["episode_seed"].copy()
    ended_any = False
    for _ in range(200):
        obs, reward, term, trunc, info = envs.step(np.full(4, HOLD))
        done = term | trunc
        if done.any():
            ended_any = True
            e = int(np.flatnonzero(done)[0])
            assert info["_final_obs"][e] and info["final_info"][e]["outcome"] == "los"
            assert info["final_info"][e]["episode_seed"] == seeds[e]
            assert info["final_obs"][e][11] > 0.0  # time elapsed at the end
            assert obs[e][11] == 0.0  # the new episode's first observation
            assert not np.isnan(reward).any()
            break
    assert ended_any


def test_an_episode_of_the_vector_env_is_the_pettingzoo_episode_of_its_seed():
    rng = np.random.default_rng(1)
    vec = VectorEnv("marl/low-2", num_envs=3)
    obs, masks = vec.reset(seeds=[7, 8, 9])
    par = cdr_bench.parallel_env("marl/low-2")
    pobs, _ = par.reset(options={"episode_seed": 8})
    for _ in range(150):
        if not par.agents:
            break
        act = _feasible(rng, masks)
        for m, agent in enumerate(vec.agent_ids):
            if agent in pobs:
                assert np.array_equal(pobs[agent]["observation"], obs[1, m])
                assert np.array_equal(pobs[agent]["action_mask"], masks[1, m])
        live = {a: int(act[1, m]) for m, a in enumerate(vec.agent_ids) if a in par.agents}
        out = vec.step(act)
        pobs, rew, *_ = par.step(live)
        for m, agent in enumerate(vec.agent_ids):
            if agent in rew:
                assert rew[agent] == out.reward[1, m]
        obs, masks = out.obs, out.action_mask


def test_vector_env_autoreset_keeps_the_final_observation_and_draws_new_seeds():
    vec = VectorEnv("tactical/crossing", num_envs=3, autoreset=True, seed=5)
    obs, _ = vec.reset()
    first = vec.episode_seeds.copy()
    for _ in range(200):
        out = vec.step(np.full((3, vec.n_agents), HOLD))
        if out.episode_done.any():
            e = int(np.flatnonzero(out.episode_done)[0])
            assert out.final_episode_seeds[e] == first[e] != vec.episode_seeds[e]
            assert out.final_obs[e, 0, 11] > 0.0 and out.obs[e, 0, 11] == 0.0
            assert vec.flying[e].all()
            return
    pytest.fail("no episode ended")


def test_autoreset_hooks_choose_the_episodes_that_end_and_their_seeds():
    """``autoreset_when`` decides which episodes end with the step (it may end some itself),
    ``autoreset_seeds`` gives the seeds of the restarted ones; what they ended with stays in
    the step's ``final_*`` arrays, the slots in ``restarted``."""
    asked: list[int] = []

    def seeds(n: int) -> list[int]:
        asked.append(n)
        return [1000 + len(asked)] * n

    def every_tenth_step(res) -> np.ndarray:
        due = np.flatnonzero(vec.episode_steps >= 10)
        if due.size:
            vec.end_episodes(due)
        return ~vec.flying.any(axis=1)

    vec = VectorEnv(
        "low", 4, autoreset=True, seed=2, autoreset_seeds=seeds, autoreset_when=every_tenth_step
    )
    vec.reset()
    started = vec.episode_seeds.copy()
    for step in range(1, 21):
        out = vec.step(np.full((4, 1), HOLD))
        assert np.array_equal(out.restarted, np.full(4, step % 10 == 0))
        if step == 10:
            assert np.array_equal(out.final_episode_seeds, started)
            assert (out.final_obs[:, 0, 11] > 0).all() and (out.obs[:, 0, 11] == 0).all()
            assert out.final_action_mask.shape == out.action_mask.shape == (4, 1, 27)
            assert (out.result.outcome[:, 0] == 0).all()  # cut, not finished by the simulator
    assert asked == [4, 4] and (vec.episode_seeds == 1002).all()
    plain = VectorEnv("low", 4, seed=2)
    plain.reset()
    assert not plain.step(np.full((4, 1), HOLD)).restarted.any()


@pytest.mark.parametrize(
    "kwargs, when, expect",
    [
        (dict(autoreset_seeds=3), None, "autoreset_seeds must be None or a callable"),
        (dict(autoreset_when="x"), None, "autoreset_when must be None or a callable"),
        (dict(autoreset_seeds=lambda n: [-1] * n), "all", "autoreset_seeds(n)[0] = -1"),
        (dict(autoreset_seeds=lambda n: [1]), "all", "autoreset_seeds(n) expects 3 seed(s)"),
        ({}, "ints", "autoreset_when must return a (3,) bool array"),
    ],
)
def test_bad_autoreset_hooks_raise_argument_errors(kwargs, when, expect):
    from cdr_bench.errors import ArgumentError

    rules = {"all": lambda res: np.ones(3, bool), "ints": lambda res: np.ones(3, int)}
    with pytest.raises(ArgumentError) as err:
        vec = VectorEnv("low", 3, autoreset=True, **{"autoreset_when": rules.get(when), **kwargs})
        vec.reset(seed=0)
        vec.step(np.full((3, 1), HOLD))
    assert expect in str(err.value)


def test_cleanrl_style_masked_ppo_update_runs_on_the_native_vector_env():
    torch = pytest.importorskip("torch")
    envs = gymnasium.make_vec(
        "cdr_bench/Ownship-v0", num_envs=8, vectorization_mode="vector_entry_point", scenario="low"
    )
    torch.manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Linear(42, 32), torch.nn.Tanh(), torch.nn.Linear(32, 28))
    opt = torch.optim.Adam(net.parameters(), lr=3e-4)
    obs, info = envs.reset(seed=0)
    mask = info["action_mask"]
    for _update in range(2):
        buf = []
        for _ in range(32):
            x = torch.as_tensor(obs)
            out = net(x)
            logits = out[:, :27].masked_fill(torch.as_tensor(mask) == 0, -1e9)
            dist = torch.distributions.Categorical(logits=logits)
            a = dist.sample()
            obs, r, term, trunc, info = envs.step(a.numpy())
            mask = info["action_mask"]
            buf.append((x, a, dist.log_prob(a).detach(), torch.as_tensor(r), out[:, 27]))
        ret = torch.stack([b[3] for b in buf]).float()
        logp_old = torch.stack([b[2] for b in buf])
        value = torch.stack([b[4] for b in buf])
        adv = (ret - value).detach()
        x = torch.stack([b[0] for b in buf]).reshape(-1, 42)
        logits = net(x)[:, :27]
        logp = torch.distributions.Categorical(logits=logits).log_prob(
            torch.stack([b[1] for b in buf]).reshape(-1)
        )
        ratio = (logp - logp_old.reshape(-1)).exp()
        loss = -(ratio * adv.reshape(-1)).mean() + ((ret - value) ** 2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        assert torch.isfinite(loss)


def test_random_feasible_actions_are_feasible_and_uniform():
    from cdr_bench.actions import action_mask
    from cdr_bench.vector_env import random_feasible_actions

    rng = np.random.default_rng(0)
    for level in range(3):
        masks = np.repeat(action_mask(level)[None], 54_000, axis=0)
        counts = np.bincount(random_feasible_actions(masks, rng), minlength=27)
        feasible = masks[0] == 1
        assert (counts[~feasible] == 0).all()
        expected = 54_000 / feasible.sum()
        assert np.abs(counts[feasible] - expected).max() < 5 * np.sqrt(expected)


@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
def test_a_copied_env_continues_exactly_like_the_original(how):
    import copy
    import pickle

    env = cdr_bench.parallel_env("high")
    env.reset(seed=4)
    for _ in range(3):
        env.step({a: HOLD for a in env.agents})
    twin = copy.deepcopy(env) if how == "deepcopy" else pickle.loads(pickle.dumps(env))
    for _ in range(30):
        if not env.agents:
            break
        a = env.step({x: 22 for x in env.agents})
        b = twin.step({x: 22 for x in twin.agents})
        assert (
            a[1] == b[1]
            and a[4]["ownship_0"]["min_separation_km"] == (b[4]["ownship_0"]["min_separation_km"])
        )
        assert np.array_equal(a[0]["ownship_0"]["observation"], b[0]["ownship_0"]["observation"])
    assert twin.vector.sim.state.pos is twin.vector.sim.pos_km  # the tuple still holds the arrays


@pytest.mark.parametrize(
    ("actions", "words"),
    [
        (np.zeros((5,), np.int64), "actions: expected an integer array of shape (2, 3), got (5,)"),
        (np.full((2, 3), 0.5), "actions: expected integers in 0..26, got an array of float64"),
        (np.ones((2, 3), bool), "actions: expected integers in 0..26, got an array of bool"),
        ([[4, 4, 4], [4, 4, 27]], "actions[1, 2] = 27: expected an integer in 0..26"),
        ([[-1, 4, 4], [4, 4, 4]], "actions[0, 0] = -1: expected an integer in 0..26"),
        (np.full((2, 3), 2**63, np.uint64), "actions[0, 0] = 9223372036854775808: expected"),
    ],
)
def test_bad_batched_actions_are_action_errors_and_change_nothing(actions, words):
    """The batched face validates like the PettingZoo one (an out-of-range index used to turn
    by two heading steps, a float was truncated); a refused step leaves the state as it was."""
    from cdr_bench.errors import ActionError

    env = VectorEnv("marl/low-2", num_envs=2, seed=0)
    env.reset(seed=0)
    before = env.sim.ac_pos_km.copy()
    with pytest.raises(ActionError) as e:
        env.step(actions)
    assert words in str(e.value)
    assert np.array_equal(env.sim.ac_pos_km, before)
    env.step(np.full((2, 3), HOLD, np.int8))  # a flat or narrow integer array is fine
    env.step(np.full(6, HOLD))


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"seeds": [1, 2, 3]}, "reset(seeds=...) expects 2 seed(s), got [1, 2, 3]"),
        ({"seeds": [-1, 2]}, "reset(seeds=...)[0] = -1: expected an integer in 0..2**64-1"),
        ({"seeds": [1, 2**64]}, "reset(seeds=...)[1] = 18446744073709551616: expected"),
        ({"seeds": [1.5, 2]}, "reset(seeds=...)[0] = 1.5: expected an integer"),  # was int(1.5)
        ({"seed": "x"}, "reset(seed=...) expects None or an integer >= 0, got 'x'"),
        ({"episodes": [2]}, "reset(episodes=...) expects distinct slot indices in 0..1"),
        ({"episodes": [1, 1]}, "reset(episodes=...) expects distinct slot indices in 0..1"),
    ],
)
def test_bad_reset_arguments_are_argument_errors(kwargs, words):
    from cdr_bench.errors import ArgumentError

    env = VectorEnv("low", num_envs=2, seed=0)
    env.reset(seeds=[7, 8])
    with pytest.raises(ArgumentError) as e:
        env.reset(**kwargs)
    assert words in str(e.value)
    assert env.episode_seeds.tolist() == [7, 8]  # nothing restarted
    env.reset(seeds=np.array([2**64 - 1, 0], np.uint64))  # the whole range is accepted


def test_the_state_properties_are_live_read_only_views_of_the_simulator():
    env = VectorEnv("marl/medium-4", num_envs=3)
    env.reset(seeds=[1, 2, 3])
    sim = env.sim  # the test may look behind the env: the properties must show the same state
    B, N, M = env.n_background, env.n_aircraft, env.n_agents
    assert (B, N) == (sim.B, sim.N) and N == B + M
    views = {
        "positions_km": (env.positions_km, sim.ac_pos_km, (3, M, 2)),
        "goals_km": (env.goals_km, sim.ac_goal_km, (3, M, 2)),
        "heading_vectors": (env.heading_vectors, sim.ac_dir, (3, M, 2)),
        "speeds_kt": (env.speeds_kt, sim.ac_speed_kt, (3, M)),
        "levels": (env.levels, sim.ac_level, (3, M)),
        "outcomes": (env.outcomes, sim.ac_outcome, (3, M)),
        "episode_steps": (env.episode_steps, sim.steps, (3,)),
        "aircraft_positions_km": (env.aircraft_positions_km, sim.pos_km, (3, N, 2)),
        "aircraft_levels": (env.aircraft_levels, sim.level, (3, N)),
        "aircraft_in_sky": (env.aircraft_in_sky, sim.active, (3, N)),
    }
    for name, (view, behind, shape) in views.items():
        assert view.shape == shape and view.dtype == behind.dtype, name
        assert np.shares_memory(view, behind) and not view.flags.writeable, name
        with pytest.raises(ValueError):
            view[...] = 0
    assert sim.pos_km.flags.writeable  # only the views are read-only
    positions, steps = env.positions_km, env.episode_steps
    before = positions.copy()
    env.step(np.full((3, M), HOLD))
    assert (steps == 1).all() and not np.array_equal(positions, before)  # live
    np.testing.assert_array_equal(env.aircraft_positions_km[:, B:], env.positions_km)
    np.testing.assert_array_equal(env.aircraft_in_sky[:, B:], env.flying)
    np.testing.assert_allclose(
        np.hypot(env.heading_vectors[..., 0], env.heading_vectors[..., 1]), 1.0, rtol=1e-12
    )
