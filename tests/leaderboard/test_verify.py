"""Verification by replay: every committed episode is flown again from its recorded decisions
(exact), and each agent is asked again on a random sample of them (within a tolerance).

The miniature leaderboard of ``conftest.py`` (8 episodes per scenario) is forged in the ways a
hostile contributor would: an outcome edited and the hash recomputed, a decision edited, and a
whole batch of records replaced by another agent's (consistent with its own decisions, so the
replay passes and only the agent re-run can catch it)."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import pytest

from cdr_bench.evaluate.results import compress_log, log_text, sha256_text
from cdr_bench.leaderboard.verify import MIN_AGREEMENT, agreement_verdict, replay_result
from tests.leaderboard.conftest import EPISODES, NO_FRESH, cdr, submission_yaml

CHECK = ("leaderboard", "build", "--check", "--reference", "weave", "--workers", 1)


def _lines(path: Path) -> list[dict]:
    return [json.loads(x) for x in log_text(path).splitlines() if x]


def _rewrite(result: Path, records: list[dict]) -> None:
    """Write ``records`` as the result's per-episode log, with its hash updated in the JSON
    (what a forger does to pass the file's own consistency check)."""
    text = "".join(json.dumps(r, separators=(",", ":")) + "\n" for r in records)
    result.with_suffix(".jsonl.xz").write_bytes(compress_log(text))
    doc = json.loads(result.read_text())
    doc["episodes_sha256"] = sha256_text(text)
    result.write_text(json.dumps(doc, indent=1) + "\n")


def test_replay_reproduces_every_committed_episode(repo: Path) -> None:
    for name in ("direct", "weave", "weave.seed-2"):
        n, diffs = replay_result(repo / "leaderboard" / "results" / f"{name}.json")
        assert (n, diffs) == (4 * EPISODES, [])


def test_replay_catches_an_edited_outcome(repo: Path) -> None:
    res = repo / "leaderboard" / "results" / "direct.json"
    recs = _lines(res.with_suffix(".jsonl.xz"))
    last = max(i for i, r in enumerate(recs) if r["scenario"] == "high")  # the last episode
    recs[last]["aircraft"][0]["min_sep_km"] = 99.0
    recs[last]["aircraft"][0]["los"] = False
    _rewrite(res, recs)
    n, diffs = replay_result(res)
    assert n == 4 * EPISODES and len(diffs) == 1
    assert diffs[0].startswith(f"high episode {EPISODES - 1}: ")
    assert "ownship_0.min_sep_km committed 99.0, replayed " in diffs[0]


def test_replay_catches_an_edited_decision(repo: Path) -> None:
    res = repo / "leaderboard" / "results" / "direct.json"
    recs = _lines(res.with_suffix(".jsonl.xz"))
    first = min(i for i, r in enumerate(recs) if r["scenario"] == "low")
    code = recs[first]["aircraft"][0]["actions"]
    recs[first]["aircraft"][0]["actions"] = ("0" if code[0] != "0" else "1") + code[1:]
    _rewrite(res, recs)
    _, diffs = replay_result(res)
    assert diffs and diffs[0].startswith(("low episode 0", "low batch 0")), diffs


def test_check_fails_on_a_forged_log_and_names_it(repo: Path) -> None:
    res = repo / "leaderboard" / "results" / "weave.seed-2.json"
    recs = _lines(res.with_suffix(".jsonl.xz"))
    i = max(i for i, r in enumerate(recs) if r["scenario"] == "low")
    recs[i]["aircraft"][0]["goal_reward"] += 1.0
    _rewrite(res, recs)
    r = cdr(*CHECK, *NO_FRESH, cwd=repo)
    assert r.returncode == 1, r.stderr
    assert "results/weave.seed-2.json: the per-episode log is not what" in r.stderr
    assert f"low episode {EPISODES - 1}" in r.stderr


def test_agent_rerun_catches_records_that_are_not_the_agents(repo: Path) -> None:
    """Direct's high episodes replaced by Weave's on the same episodes: every record is what
    its decisions give (the replay passes), but they are not Direct's decisions."""
    res = repo / "leaderboard" / "results"
    direct, weave = _lines(res / "direct.jsonl.xz"), _lines(res / "weave.jsonl.xz")
    forged = [
        next(w for w in weave if (w["scenario"], w["episode"]) == (d["scenario"], d["episode"]))
        if d["scenario"] == "high"
        else d
        for d in direct
    ]
    assert forged != direct
    _rewrite(res / "direct.json", forged)
    assert replay_result(res / "direct.json") == (4 * EPISODES, [])
    r = cdr(*CHECK, *NO_FRESH, "--rerun-batches", 4, "--sample-seed", 1, cwd=repo)
    assert r.returncode == 1, r.stderr
    assert "results/direct.json: direct: agent re-run on" in r.stderr
    assert "tolerance 99 %" in r.stderr
    assert "--sample-seed 1" in r.stderr


NOISY_AGENT = textwrap.dedent(
    """
    import os
    import numpy as np

    FLIP = {flip}

    class Agent:
        def __init__(self, observation_space, action_space):
            self.rng = np.random.default_rng(int.from_bytes(os.urandom(8), "little"))

        def reset(self, seed):
            pass

        def act_batch(self, observations, masks):
            a = np.full(len(observations), 13)
            flip = self.rng.random(len(a)) < FLIP  # a near-tie that falls the other way
            return np.where(flip & (masks[:, 4] == 1), 4, a)

        def act(self, observation):
            return 13
    """
)


@pytest.mark.parametrize("flip, passes", [(0.0, True), (0.2, False)])
def test_rerun_tolerance(repo: Path, flip: float, passes: bool) -> None:
    """An agent whose decisions are not reproducible passes while few of them differ and fails
    when many do; the disagreements are listed."""
    (repo / "agents" / "noisy").mkdir()
    (repo / "agents" / "noisy" / "agent.py").write_text(NOISY_AGENT.format(flip=0.0))
    lb = repo / "leaderboard"
    (lb / "submissions" / "noisy.yaml").write_text(submission_yaml("agents/noisy"))
    r = cdr(
        "leaderboard",
        "build",
        "--evaluate",
        "noisy",
        "--reference",
        "weave",
        "--workers",
        1,
        cwd=repo,
    )
    assert r.returncode == 0, r.stderr
    (repo / "agents" / "noisy" / "agent.py").write_text(NOISY_AGENT.format(flip=flip))
    # the identity changed with the file: put the committed identity back so that only the
    # decisions differ (as they would on another CPU with the same files)
    doc = json.loads((lb / "results" / "noisy.json").read_text())
    from cdr_bench.evaluate.loader import agent_identity

    doc["agent"] = agent_identity(repo / "agents" / "noisy" / "agent.py", checkpoint=None)
    doc["agent"]["path"] = "agents/noisy/agent.py"
    (lb / "results" / "noisy.json").write_text(json.dumps(doc, indent=1) + "\n")
    r = cdr(*CHECK, *NO_FRESH, "--evaluate", "noisy", "--rerun-batches", 4, cwd=repo)
    assert "noisy: agent re-run on" in r.stderr, r.stderr
    if passes:
        assert "100.00 %" in r.stderr
    else:
        assert r.returncode == 1 and "disagreements" in r.stderr, r.stderr


def test_agreement_verdict_applies_the_stated_tolerance() -> None:
    def batch(asked: int, agree: int) -> dict:
        return {"scenario": "high", "batch": 0, "decisions": asked, "agree": agree}

    assert MIN_AGREEMENT == 0.99
    assert agreement_verdict("x", [batch(1000, 990)])[1]
    assert not agreement_verdict("x", [batch(1000, 989)])[1]
    assert agreement_verdict("x", [batch(0, 0)])[1]


CLAIRVOYANT_AGENT = textwrap.dedent(
    """
    import hashlib

    import numpy as np

    from cdr_bench.resolvers import mvp_actions

    # Fingerprints of the public test episodes' first observations (computed beforehand from
    # the public base seed and seed derivation).
    PUBLIC = {public!r}

    def fingerprint(row):
        return hashlib.sha256(np.round(row, 4).tobytes()).hexdigest()[:16]

    class Agent:
        def __init__(self, observation_space, action_space):
            self.known = None

        def reset(self, seed):
            self.known = None

        def act_batch(self, observations, masks):
            if self.known is None:  # the first step: which episodes are these?
                self.known = all(fingerprint(r) in PUBLIC for r in observations)
            if self.known:  # a plan for episodes it knows (here: the MVP resolver)
                return mvp_actions(observations, masks)
            a = np.full(len(observations), 22)  # ones it has not seen: circles, never arrives
            return np.where(masks[np.arange(len(a)), a] == 1, a, 13)

        def act(self, observation):
            return int(self.act_batch(observation["observation"][None],
                                      observation["action_mask"][None])[0])
    """
)


def _public_fingerprints() -> set[str]:
    import hashlib

    import numpy as np

    from cdr_bench.evaluate.seeds import episode_seeds
    from cdr_bench.leaderboard.build import BASE_SEED
    from cdr_bench.scenarios import load_scenario
    from cdr_bench.vector_env import VectorEnv
    from tests.leaderboard.conftest import SCENARIOS

    out = set()
    for s in SCENARIOS:
        config = load_scenario(s)
        env = VectorEnv(config, num_envs=EPISODES)
        seeds = episode_seeds(BASE_SEED, s, config.config_hash(), 0, EPISODES)
        obs, _ = env.reset(seeds=seeds)
        out |= {hashlib.sha256(np.round(r, 4).tobytes()).hexdigest()[:16] for r in obs[:, 0]}
    return out


@pytest.mark.slow
def test_fresh_episodes_catch_an_agent_that_knows_the_public_episodes(repo: Path) -> None:
    """An agent that recognises the public episodes (from their first observations) flies well
    on them only: its committed records replay and its re-run agrees, but its score on episodes
    drawn at check time is not consistent with the committed one."""
    (repo / "agents" / "seer").mkdir()
    (repo / "agents" / "seer" / "agent.py").write_text(
        CLAIRVOYANT_AGENT.format(public=_public_fingerprints())
    )
    lb = repo / "leaderboard"
    (lb / "submissions" / "seer.yaml").write_text(submission_yaml("agents/seer"))
    r = cdr(*CHECK[:2], "--evaluate", "seer", *CHECK[3:], cwd=repo)
    assert r.returncode == 0, r.stderr
    from cdr_bench.evaluate.results import read_result

    scored = read_result(lb / "results" / "seer.json")
    high = next(s for s in scored["scenarios"] if s["id"] == "high")["metrics"]["ownship"]
    assert high["episodes"] == EPISODES and high["clean_success_rate"]["count"] >= 4
    # without the fresh-episode test it passes every other check (its agent asked again only:
    # the other entries' agents are asked below)
    r = cdr(*CHECK, *NO_FRESH, "--evaluate", "seer", "--rerun-batches", 4, cwd=repo)
    assert r.returncode == 0, r.stderr
    assert "seer: agent re-run on" in r.stderr and "direct: agent re-run" not in r.stderr
    r = cdr(*CHECK, cwd=repo)
    assert r.returncode == 1, r.stderr
    assert "seer: 200 fresh high episodes (base seed " in r.stderr
    assert "the committed score does not generalise" in r.stderr
    assert "direct: 200 fresh high episodes" in r.stderr  # honest entries pass it
    assert "results/direct.json" not in r.stderr and "results/weave" not in r.stderr


@pytest.mark.slow
def test_scored_reset_seeds_are_not_the_public_ones(repo: Path) -> None:
    """The build scores with agent reset seeds derived with a secret key, recorded in the
    result afterwards (so the check can ask the agent again with the same seeds)."""
    (repo / "agents" / "seeds").mkdir()
    (repo / "agents" / "seeds" / "agent.py").write_text(
        textwrap.dedent(
            """
            import numpy as np

            class Agent:
                def __init__(self, observation_space, action_space):
                    self.rng = np.random.default_rng(0)

                def reset(self, seed):
                    self.rng = np.random.default_rng(seed)  # a stochastic agent

                def act_batch(self, observations, masks):
                    a = self.rng.integers(0, 27, len(observations))
                    return np.where(masks[np.arange(len(a)), a] == 1, a, 13)

                def act(self, observation):
                    return 13
            """
        )
    )
    lb = repo / "leaderboard"
    (lb / "submissions" / "seeds.yaml").write_text(submission_yaml("agents/seeds"))
    r = cdr(*CHECK[:2], "--evaluate", "seeds", *CHECK[3:], cwd=repo)
    assert r.returncode == 0, r.stderr
    doc = json.loads((lb / "results" / "seeds.json").read_text())
    assert len(doc["agent_seed_key"]) == 32
    only_seeds = (*NO_FRESH, "--evaluate", "seeds", "--rerun-batches", 4)
    r = cdr(*CHECK, *only_seeds, cwd=repo)
    assert r.returncode == 0, r.stderr
    assert "seeds: agent re-run on" in r.stderr and "(100.00 %" in r.stderr
    doc["agent_seed_key"] = "0" * 32  # another key: another agent's decisions
    (lb / "results" / "seeds.json").write_text(json.dumps(doc, indent=1) + "\n")
    r = cdr(*CHECK, *only_seeds, cwd=repo)
    assert r.returncode == 1 and "seeds: agent re-run on" in r.stderr, r.stderr


def test_fisher_exact_is_scipys_and_keeps_its_false_alarm_rate() -> None:
    import numpy as np
    from scipy.stats import fisher_exact as scipy_fisher

    from cdr_bench.leaderboard.verify import fisher_exact

    rng = np.random.default_rng(0)
    assert fisher_exact(517, 1000, 100, 200) == pytest.approx(
        scipy_fisher([[517, 483], [100, 100]])[1], rel=1e-9
    )  # binomial coefficients far beyond a float
    for _ in range(200):
        n1, n2 = int(rng.integers(1, 300)), int(rng.integers(1, 300))
        k1, k2 = int(rng.integers(0, n1 + 1)), int(rng.integers(0, n2 + 1))
        want = scipy_fisher([[k1, n1 - k1], [k2, n2 - k2]])[1]
        assert fisher_exact(k1, n1, k2, n2) == pytest.approx(want, rel=1e-9, abs=1e-300)
    # two samples of one rate: rejected at 5 % no more often than 5 % (exact, conservative)
    draws = [
        fisher_exact(int(rng.binomial(1000, 0.94)), 1000, int(rng.binomial(200, 0.94)), 200)
        for _ in range(1000)
    ]
    assert np.mean(np.array(draws) < 0.05) <= 0.05 + 3 * (0.05 * 0.95 / 1000) ** 0.5
    with pytest.raises(ValueError):
        fisher_exact(5, 4, 0, 1)
