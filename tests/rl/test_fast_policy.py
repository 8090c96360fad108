"""The fixed numeric path (:mod:`cdr_bench.inference`) computes what the PyTorch modules compute.

Up to float rounding: the kernels sum in another order than MKL/oneDNN and use their own exp and
tanh, so outputs agree to ~1e-5 relative and actions agree except on near ties. And the path
itself is bit-stable: a row's result does not depend on the batch it is computed in, and fixed
weights and inputs give fixed digests (the same on every x86-64 CPU:
``tests/leaderboard/test_cpu_independence.py`` runs them under two kernel settings).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

import cdr_bench.inference as inf  # noqa: E402
from cdr_bench.rl.diffusion import Schedule  # noqa: E402
from cdr_bench.rl.diffusion_ac import Policy, PolicyConfig, load_policy  # noqa: E402
from cdr_bench.rl.networks import sinusoidal_embedding  # noqa: E402
from cdr_bench.rl.rainbow import RainbowConfig, RainbowNet  # noqa: E402
from cdr_bench.rl.safe_dqn import SafeDQNConfig, SafeDQNNet  # noqa: E402
from cdr_bench.rl.sb3_policies import ppo_actor, td3_actor  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
DIFFUSION_CHECKPOINTS = [ROOT / "agents" / "diffusion_ac" / "checkpoint.pt"] + sorted(
    (ROOT / "agents" / "diffusion_ac" / "ablations").glob("*/checkpoint.pt")
)


def _sd(module: torch.nn.Module) -> dict[str, np.ndarray]:
    return {k: v.detach().numpy().copy() for k, v in module.state_dict().items()}


def _random_policy(**kw) -> Policy:
    torch.manual_seed(0)
    pol = Policy(PolicyConfig(**kw))
    with torch.no_grad():  # non-trivial LayerNorm affines, so folding them is exercised
        for m in pol.modules():
            if isinstance(m, torch.nn.LayerNorm):
                m.weight.uniform_(0.5, 1.5)
                m.bias.uniform_(-0.3, 0.3)
    return pol.eval()


def _actor(pol: Policy) -> inf.DiffusionActor:
    return inf.DiffusionActor(_sd(pol), asdict(pol.cfg))


@torch.no_grad()
def _torch_clean_logits(pol: Policy, obs: np.ndarray, noise: np.ndarray) -> np.ndarray:
    """:meth:`Policy.clean_logits` with the noise given (y_T = noise[0], then the z of steps
    t = T..2) instead of drawn from a torch generator."""
    if pol.cfg.actor == "categorical":
        return pol.clean_logits(torch.as_tensor(obs)).numpy()
    sch, n = pol.schedule, len(obs)
    h = pol.net.encode(torch.as_tensor(obs))
    y = torch.as_tensor(noise[0])
    for t in range(sch.T, 0, -1):
        y0 = pol.net.forward_h(h, y, torch.full((n,), t, dtype=torch.long))
        if t == 1:
            return y0.numpy()
        y = sch.posterior_mean(y0, y, t) + sch.beta_tilde[t].sqrt() * torch.as_tensor(
            noise[sch.T - t + 1]
        )
    raise AssertionError("unreachable")


def _near_ties_only(ref: np.ndarray, got_a: np.ndarray, ref_a: np.ndarray, tol: float) -> None:
    """Actions may differ only where the reference values of the two actions are within
    ``tol`` (a near tie), and in at most 2 % of the rows."""
    diff = np.nonzero(got_a != ref_a)[0]
    assert len(diff) <= max(1, 0.02 * len(ref_a)), f"{len(diff)} of {len(ref_a)} actions differ"
    for i in diff:
        gap = abs(float(ref[i, got_a[i]]) - float(ref[i, ref_a[i]]))
        assert gap <= tol, f"row {i}: actions {got_a[i]} vs {ref_a[i]}, gap {gap}"


def simulator_states(n: int = 256, steps: int = 4):
    from cdr_bench.scenarios import load_scenario
    from cdr_bench.sim import Simulator, observe

    sim = Simulator(load_scenario("high"), n_episodes=n)
    sim.reset(np.arange(n))
    for _ in range(steps):
        sim.step(np.full((n, sim.M), 13))
    return observe(sim)[:, 0].astype(np.float32), sim.action_masks()[:, 0]


# ----------------------------------------------------------------------------------------------
# Elementwise functions and load-time constants


def test_elementwise_functions_match_libm():
    rng = np.random.default_rng(0)
    xs = np.concatenate([rng.uniform(-40, 40, 3000), rng.normal(0, 1e-3, 1000), [0.0, -0.0]])
    for x in xs:
        # a few units in the last place of float64 (float32 results need 6e-8)
        assert abs(inf.exp_(x) - math.exp(x)) <= 8e-16 * math.exp(x)
        assert abs(inf.expm1_(x) - math.expm1(x)) <= 8e-16 * abs(math.expm1(x))
        assert abs(inf.tanh_(x) - math.tanh(x)) <= 8e-16 * abs(math.tanh(x))
        mish = x * math.tanh(math.log1p(math.exp(x)))
        assert abs(inf.mish_(x) - mish) <= 1e-15 * abs(mish) + 1e-300
        s, c = inf.sincos_(x)
        assert abs(s - math.sin(x)) <= 8e-16 and abs(c - math.cos(x)) <= 8e-16
    assert math.copysign(1.0, inf.tanh_(-0.0)) == -1.0 and inf.exp_(0.0) == 1.0
    assert inf.exp_(-800.0) < 1e-307 and inf.tanh_(50.0) == 1.0 and math.isnan(inf.exp_(math.nan))


@pytest.mark.parametrize("kind", ["cosine", "linear"])
@pytest.mark.parametrize("T", [1, 3, 10, 20])
def test_schedule_matches_torch(kind, T):
    ref = Schedule(kind, T)
    got = inf.diffusion_schedule(kind, T)
    ulp = np.finfo(np.float32).eps
    for name, r in (
        ("coef_y0", ref.coef_y0),
        ("coef_yt", ref.coef_yt),
        ("sigma", ref.beta_tilde.sqrt()),
    ):
        np.testing.assert_allclose(got[name], r.numpy(), rtol=2 * ulp, atol=0, err_msg=name)


def test_step_embedding_matches_torch():
    t = np.arange(21)
    ref = sinusoidal_embedding(torch.as_tensor(t), 128).numpy()
    np.testing.assert_allclose(inf.sinusoidal_embedding(t, 128), ref, rtol=0, atol=2e-6)


# ----------------------------------------------------------------------------------------------
# Diffusion-AC actor


@pytest.mark.parametrize(
    "kw",
    [{}, {"schedule": "linear"}, {"T": 3, "width": 64, "n_blocks": 1}, {"T": 20, "n_heads": 4}],
)
def test_clean_logits_match_torch(kw):
    pol = _random_policy(**kw)
    actor = _actor(pol)
    rng = np.random.default_rng(1)
    obs = rng.normal(size=(33, pol.cfg.obs_dim)).astype(np.float32)
    noise = rng.standard_normal((pol.cfg.T, 33, 27), dtype=np.float32)
    ref = _torch_clean_logits(pol, obs, noise)
    got = actor.clean_logits(obs, noise)
    assert got.shape == (33, 27) and got.dtype == np.float32
    np.testing.assert_allclose(got, ref, rtol=1e-4, atol=1e-4 * np.abs(ref).max())


def test_categorical_actor_matches_torch():
    pol = _random_policy(actor="categorical")
    obs = np.random.default_rng(1).normal(size=(50, 42)).astype(np.float32)
    ref = _torch_clean_logits(pol, obs, np.zeros(0))
    got = _actor(pol).clean_logits(obs)
    np.testing.assert_allclose(got, ref, rtol=1e-4, atol=1e-4 * np.abs(ref).max())


def test_different_noise_gives_different_logits():
    """Guard against a path that ignores the noise (the diffusion actor is stochastic)."""
    actor = _actor(_random_policy())
    obs = np.zeros((4, 42), np.float32)
    a = actor.logits(obs, inf.new_generator(1))
    b = actor.logits(obs, inf.new_generator(2))
    assert np.abs(a - b).max() > 1e-3
    np.testing.assert_array_equal(a, actor.logits(obs, inf.new_generator(1)))


def test_masked_classes_are_never_chosen():
    actor = _actor(_random_policy())
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(200, 42)).astype(np.float32)
    mask = (rng.random((200, 27)) < 0.3).astype(np.int8)
    mask[np.arange(200), rng.integers(0, 27, 200)] = 1
    a = actor.act(obs, mask, inf.new_generator(0))
    assert a.dtype == np.int64 and mask[np.arange(200), a].all()


@pytest.mark.artefacts
@pytest.mark.parametrize("path", DIFFUSION_CHECKPOINTS, ids=lambda p: p.parent.name)
def test_shipped_diffusion_checkpoints_same_actions_on_simulator_states(path):
    pol = load_policy(str(path))
    ck = torch.load(path, map_location="cpu", weights_only=True)
    actor = inf.DiffusionActor({k: v.numpy() for k, v in ck["state_dict"].items()}, ck["config"])
    obs, mask = simulator_states()
    noise = np.random.default_rng(4).standard_normal((pol.cfg.T, len(obs), 27), np.float32)
    ref = np.where(mask != 0, _torch_clean_logits(pol, obs, noise), -np.inf)
    got = actor.clean_logits(obs, noise)
    finite = np.isfinite(ref)
    np.testing.assert_allclose(got[finite], ref[finite], rtol=1e-4, atol=1e-4 * 10)
    _near_ties_only(ref, inf.masked_argmax(got, mask), ref.argmax(1), 1e-3)


# ----------------------------------------------------------------------------------------------
# Baselines: PPO / MaskablePPO / TD3 (MLPs), Rainbow-DQN, Safe-DQN-X


@pytest.mark.parametrize("kind", ["ppo", "td3"])
def test_mlp_matches_torch(kind):
    torch.manual_seed(1)
    net = (ppo_actor if kind == "ppo" else td3_actor)(42).eval()
    mlp = inf.MLP.from_state_dict(_sd(net), "", *(("tanh",) if kind == "ppo" else ("relu", "tanh")))
    obs = np.random.default_rng(2).normal(size=(77, 42)).astype(np.float32)
    with torch.no_grad():
        ref = net(torch.as_tensor(obs)).numpy()
    got = mlp(obs)
    assert got.shape == ref.shape and got.dtype == np.float32
    np.testing.assert_allclose(got, ref, rtol=1e-5, atol=1e-5 * np.abs(ref).max())


def _random_rainbow() -> RainbowNet:
    torch.manual_seed(2)
    net = RainbowNet(RainbowConfig(obs_dim=42)).eval()
    with torch.no_grad():  # spread the atoms: a freshly initialised net is nearly uniform
        net.advantage[2].weight_mu.mul_(8.0)
        net.value[2].weight_mu.mul_(8.0)
    return net


def test_rainbow_matches_torch():
    net = _random_rainbow()
    q = inf.RainbowQ(_sd(net), asdict(net.cfg))
    np.testing.assert_allclose(q.support, net.support.numpy(), rtol=0, atol=0)
    obs = np.random.default_rng(3).normal(size=(64, 42)).astype(np.float32)
    mask = (np.random.default_rng(4).random((64, 27)) < 0.5).astype(np.int8)
    mask[:, 13] = 1
    with torch.no_grad():
        ref = net.q_values(torch.as_tensor(obs)).numpy()
        ref_a = net.act(torch.as_tensor(obs), torch.as_tensor(mask)).numpy()
    got = q.q_values(obs)
    np.testing.assert_allclose(got, ref, rtol=1e-5, atol=1e-5 * np.abs(ref).max())
    _near_ties_only(np.where(mask != 0, ref, -np.inf), q.act(obs, mask), ref_a, 1e-4)


@pytest.mark.parametrize("rule", ["sum", "lexicographic"])
def test_safe_dqn_matches_torch(rule):
    torch.manual_seed(3)
    net = SafeDQNNet(SafeDQNConfig(obs_dim=42, rule=rule, slack=0.05)).eval()
    q = inf.SafeDQNQ(_sd(net), asdict(net.cfg))
    obs = np.random.default_rng(5).normal(size=(300, 42)).astype(np.float32)
    mask = (np.random.default_rng(6).random((300, 27)) < 0.5).astype(np.int8)
    mask[:, 13] = 1
    with torch.no_grad():
        qs, qg = net(torch.as_tensor(obs))
        ref_a = net.act(torch.as_tensor(obs), torch.as_tensor(mask)).numpy()
    np.testing.assert_allclose(q.safety(obs), qs.numpy(), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(q.goal(obs), qg.numpy(), rtol=1e-5, atol=1e-6)
    got_a = q.act(obs, mask)
    assert mask[np.arange(300), got_a].all()
    assert (got_a != ref_a).mean() <= 0.02


def _load(path: Path):
    ck = torch.load(path, map_location="cpu", weights_only=True)
    return ck["config"], {k: v.numpy() for k, v in ck["state_dict"].items()}


@pytest.mark.artefacts
@pytest.mark.parametrize(
    "name", ["ppo", "maskable_ppo", "td3", "rainbow", "safe_dqn_x", "ippo", "mappo"]
)
def test_shipped_baselines_same_actions_on_simulator_states(name):
    from cdr_bench.rl import rainbow, safe_dqn
    from cdr_bench.rl.baselines import continuous_to_index
    from cdr_bench.rl.sb3_policies import load_actor

    path = ROOT / "agents" / name / "checkpoint.pt"
    cfg, sd = _load(path)
    obs, mask = simulator_states()
    o, m = torch.as_tensor(obs), torch.as_tensor(mask)
    with torch.no_grad():
        if name == "rainbow":
            net = rainbow.load_net(str(path))
            ref, ref_a = net.q_values(o).numpy(), net.act(o, m).numpy()
            q = inf.RainbowQ(sd, cfg)
            got, got_a = q.q_values(obs), q.act(obs, mask)
        elif name == "safe_dqn_x":
            snet = safe_dqn.load_net(str(path))
            qs, qg = snet(o)
            ref, ref_a = (qs + qg).numpy(), snet.act(o, m).numpy()
            sq = inf.SafeDQNQ(sd, cfg)
            got, got_a = sq.safety(obs) + sq.goal(obs), sq.act(obs, mask)
        else:
            actor, _ = load_actor(str(path))
            ref = actor(o).numpy()
            mlp = inf.MLP.from_state_dict(
                sd, "", *(("relu", "tanh") if name == "td3" else ("tanh",))
            )
            got = mlp(obs)
            if name == "td3":
                ref_a, got_a = continuous_to_index(ref), continuous_to_index(got)
            else:
                use = mask if name != "ppo" else None
                ref_a = (
                    np.where(mask != 0, ref, -np.inf).argmax(1)
                    if use is not None
                    else ref.argmax(1)
                )
                got_a = inf.masked_argmax(got, use)
    np.testing.assert_allclose(got, ref, rtol=1e-4, atol=1e-5 * np.abs(ref).max())
    if name == "td3":
        assert (got_a != ref_a).mean() <= 0.02
    else:
        masked = np.where(mask != 0, ref, -np.inf) if name != "ppo" else ref
        _near_ties_only(masked, got_a, ref_a, 1e-3 * max(1.0, np.abs(ref).max()))


# ----------------------------------------------------------------------------------------------
# Bit stability of the fixed path


def _digest(*arrays) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def _numpy_models():
    """Models with weights drawn by numpy's PCG64 (the same on every machine) in the shipped
    checkpoints' state-dict layouts."""
    rng = np.random.default_rng(2026)

    def lin(prefix, i, o, w="weight", b="bias"):
        s = 1 / math.sqrt(i)
        return {
            f"{prefix}.{w}": rng.uniform(-s, s, (o, i)).astype(np.float32),
            f"{prefix}.{b}": rng.uniform(-s, s, o).astype(np.float32),
        }

    def ln(prefix, n):
        return {
            f"{prefix}.weight": rng.uniform(0.5, 1.5, n).astype(np.float32),
            f"{prefix}.bias": rng.uniform(-0.3, 0.3, n).astype(np.float32),
        }

    W = 64
    dsd = {
        **lin("net.enc.net.0", 42, W), **ln("net.enc.net.1", W),
        **lin("net.enc.net.3", W, W), **ln("net.enc.net.4", W),
        **lin("net.t_mlp.0", W, W), **lin("net.t_mlp.2", W, W),
        **lin("net.y_mlp.0", 27, W), **lin("net.y_mlp.2", W, W),
        **ln("net.attn_norm", W), **lin("net.attn.out_proj", W, W),
        **ln("net.blocks.0.net.0", W), **lin("net.blocks.0.net.1", W, W),
        **lin("net.blocks.0.net.3", W, W), **ln("net.head.0", W), **lin("net.head.1", W, 27),
    }  # fmt: skip
    qkv = lin("net.attn", W, 3 * W)
    dsd["net.attn.in_proj_weight"] = qkv["net.attn.weight"]
    dsd["net.attn.in_proj_bias"] = qkv["net.attn.bias"]
    diffusion = inf.DiffusionActor(dsd, {"T": 5, "n_heads": 4, "schedule": "cosine"})
    categorical = inf.DiffusionActor(dsd, {"actor": "categorical"})
    ppo = inf.MLP.from_state_dict(
        {**lin("0", 42, W), **lin("2", W, W), **lin("4", W, 27)}, "", "tanh"
    )
    rsd = {
        **lin("torso.0", 42, W), **lin("torso.2", W, W),
        **lin("value.0", W, W, "weight_mu", "bias_mu"),
        **lin("value.2", W, 11, "weight_mu", "bias_mu"),
        **lin("advantage.0", W, W, "weight_mu", "bias_mu"),
        **lin("advantage.2", W, 27 * 11, "weight_mu", "bias_mu"),
    }  # fmt: skip
    rainbow = inf.RainbowQ(rsd, {"n_atoms": 11, "v_min": -3.0, "v_max": 2.0})
    obs = rng.normal(size=(41, 42)).astype(np.float32)
    noise = rng.standard_normal((5, 41, 27), dtype=np.float32)
    return diffusion, categorical, ppo, rainbow, obs, noise


def test_rows_do_not_depend_on_the_batch():
    """Each output has its own fixed-order sum: computing a row alone, or in a batch of any
    size (the kernels block four rows at a time), gives the same bits."""
    diffusion, categorical, ppo, rainbow, obs, noise = _numpy_models()
    full = [
        diffusion.clean_logits(obs, noise),
        categorical.clean_logits(obs),
        ppo(obs),
        rainbow.q_values(obs),
    ]
    for lo, hi in ((0, 1), (3, 5), (5, 12), (12, 41)):
        part = [
            diffusion.clean_logits(obs[lo:hi], noise[:, lo:hi]),
            categorical.clean_logits(obs[lo:hi]),
            ppo(obs[lo:hi]),
            rainbow.q_values(obs[lo:hi]),
        ]
        for f, p in zip(full, part, strict=True):
            assert f[lo:hi].tobytes() == p.tobytes()


GOLDEN = {
    "diffusion": "ba53a7d9b493382f",
    "categorical": "c8b630ec24b667d2",
    "ppo": "7b5f658da6a961f4",
    "rainbow": "91572fab8f1c22fc",
    "noise": "9205ad83a192a5ac",
}


def test_fixed_path_golden_digests():
    """Fixed weights and inputs -> fixed bits. A failure means the arithmetic changed (a kernel
    edit, or a numba/LLVM that vectorises differently -- which it must not): results computed
    before and after are then not comparable, and the leaderboard must be re-evaluated."""
    diffusion, categorical, ppo, rainbow, obs, noise = _numpy_models()
    got = {
        "diffusion": _digest(diffusion.clean_logits(obs, noise)),
        "categorical": _digest(categorical.clean_logits(obs)),
        "ppo": _digest(ppo(obs)),
        "rainbow": _digest(rainbow.q_values(obs)),
        "noise": _digest(inf.new_generator(123).standard_normal((3, 5, 27), dtype=np.float32)),
    }
    assert got == GOLDEN
