"""``--device``: every trainer's networks, generators and updates on the requested device.

This machine has no GPU, so what runs on one is checked here in two ways: the tensor operations
every non-CPU device runs (``networks.COMPILED = False``) compute what the compiled CPU kernels
compute, and with each device that is available (the CPU; CUDA where there is one) every
parameter, buffer, optimiser state and generator of each learner is on it and an update touches
no tensor on another device. A ``cuda`` request without CUDA is a one-line user error.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from torch.utils._python_dispatch import TorchDispatchMode

from cdr_bench.errors import UserError
from cdr_bench.rl import networks
from cdr_bench.rl.device import resolve_device
from tests.rl.helpers import cdr_bench

DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


@pytest.fixture(autouse=True)
def one_thread():
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture
def tensor_path(monkeypatch):
    """The tensor operations of the non-CPU devices, on the CPU."""
    monkeypatch.setattr(networks, "COMPILED", False)


def _close(a: torch.Tensor, b: torch.Tensor, rtol: float = 1e-4) -> None:
    assert a.shape == b.shape
    err = float((a - b).abs().max())
    assert err <= rtol * float(b.abs().max()) + 1e-5, err


def _batch(n: int = 64, seed: int = 0, device: str = "cpu") -> dict[str, torch.Tensor]:
    """A replay batch with the keys of every learner (Rainbow's discount and weights, Safe-DQN-X's
    two rewards)."""
    g = torch.Generator().manual_seed(seed)
    mask = (torch.rand(n, 27, generator=g) > 0.3).to(torch.int8)
    mask[:, 13] = 1
    b = {
        "obs": torch.randn(n, 42, generator=g),
        "mask": mask,
        "action": torch.randint(0, 27, (n,), generator=g),
        "reward": torch.randn(n, generator=g),
        "goal_reward": torch.randn(n, generator=g),
        "safety_reward": torch.randn(n, generator=g),
        "next_obs": torch.randn(n, 42, generator=g),
        "next_mask": mask.flip(0),
        "done": (torch.rand(n, generator=g) < 0.1).float(),
        "discount": torch.full((n,), 0.99**3),
        "weight": torch.rand(n, generator=g) + 0.5,
    }
    b["action"] = torch.where(mask.gather(1, b["action"][:, None])[:, 0] > 0, b["action"], 13)
    return {k: v.to(device) for k, v in b.items()}


# --- the tensor path computes what the compiled kernels compute -----------------------------


def test_denoiser_tensor_path_equals_compiled_values_and_gradients(monkeypatch):
    torch.manual_seed(0)
    net = networks.Denoiser(42, width=64, n_blocks=1, n_heads=4)
    g = torch.Generator().manual_seed(1)
    obs, y = torch.randn(40, 42, generator=g), 3 * torch.randn(40, 27, generator=g)
    t = torch.randint(0, 11, (40,), generator=g)
    params = list(net.parameters())

    def run() -> tuple[torch.Tensor, list[torch.Tensor], torch.Tensor]:
        out = net(obs, y, t)
        grads = torch.autograd.grad((out * out).sum(), params)
        with torch.no_grad():  # acting: one int step for every row
            c = net.condition(net.encode(obs[:7]), 10)
            act = net.denoise(c, y[:14], 5)
        return out.detach(), list(grads), act

    ref = run()
    monkeypatch.setattr(networks, "COMPILED", False)
    got = run()
    _close(got[0], ref[0])
    _close(got[2], ref[2])
    for a, b in zip(got[1], ref[1], strict=True):
        _close(a, b, 1e-3)


def test_mish_tensor_path(tensor_path):
    x = torch.linspace(-30, 30, 2001)
    assert torch.equal(networks.Mish()(x), torch.nn.functional.mish(x))


def test_rainbow_tensor_path_equals_compiled(monkeypatch):
    from cdr_bench.rl.rainbow import RainbowConfig, RainbowNet, project_distribution

    torch.manual_seed(3)
    net = RainbowNet(RainbowConfig(obs_dim=42, width=32, n_atoms=11))
    net.reset_noise()
    b = _batch(50)
    params = list(net.parameters())

    def run() -> list[torch.Tensor]:
        lp = net.log_probs_of(b["obs"], b["action"])
        grads = torch.autograd.grad(lp.sum(), params)
        q = net.expected_q(b["obs"])
        p = project_distribution(lp.exp(), b["reward"] * 8, b["discount"], net.support)
        return [lp.detach(), q, p, *grads]

    ref = run()
    monkeypatch.setattr(networks, "COMPILED", False)
    got = run()
    assert len(got) == len(ref)
    for a, r in zip(got, ref, strict=True):
        _close(a, r, 1e-3)
    assert torch.allclose(got[2].sum(-1), torch.ones(50), atol=1e-5)


def _learner(name: str, device: str):
    """The learner of ``cdr-bench train NAME`` (small networks), built as the loop builds it."""
    import importlib

    from cdr_bench.rl.cli import TRAINERS

    module = importlib.import_module(TRAINERS[name])
    args = module.Args(width=32, **({"critic_width": 32} if name == "diffusion-ac" else {}))
    torch.manual_seed(5)
    return module.build(args, 42, np.random.default_rng(0), device=torch.device(device))


OFF_POLICY = ("diffusion-ac", "rainbow", "safe-dqn-x")


@pytest.mark.parametrize("name", OFF_POLICY)
def test_tensor_path_update_matches_compiled_update(name, monkeypatch):
    """Three updates and acting from the same start: the losses agree to float rounding (the
    path a GPU takes, against the tested CPU path)."""

    def run() -> list[float]:
        torch.manual_seed(9)
        learner = _learner(name, "cpu")
        learner.schedule(0, 1)
        out = []
        for i in range(3):
            out += [v for v in learner.update(_batch(seed=i)).values() if math.isfinite(v)]
        b = _batch(seed=7)
        learner.act(b["obs"].numpy(), b["mask"].numpy(), False)
        return out

    ref = run()
    monkeypatch.setattr(networks, "COMPILED", False)
    got = run()
    assert np.allclose(got, ref, rtol=2e-3, atol=1e-5), (got, ref)


# --- placement: everything on the requested device, updates on one device --------------------


class _Devices(TorchDispatchMode):
    """The devices of every tensor (of at least one dimension) an operation reads or writes."""

    def __init__(self) -> None:
        super().__init__()
        self.seen: set[str] = set()

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        out = func(*args, **(kwargs or {}))
        for x in torch.utils._pytree.tree_leaves((args, kwargs, out)):
            if isinstance(x, torch.Tensor) and x.dim() > 0:
                self.seen.add(x.device.type)
        return out


def _placement(learner) -> dict[str, set[str]]:
    """Where each kind of state of ``learner`` lives: modules' parameters and buffers, the
    optimisers' tensors, the torch generators."""
    where: dict[str, set[str]] = {"parameters": set(), "buffers": set(), "optim": set()}
    where["generators"] = set()
    for value in vars(learner).values():
        if isinstance(value, torch.nn.Module):
            where["parameters"] |= {p.device.type for p in value.parameters()}
            where["buffers"] |= {b.device.type for b in value.buffers()}
            if hasattr(value, "schedule"):  # the diffusion schedule's constants
                where["buffers"] |= {x.device.type for x in value.schedule.tensors()}
        elif isinstance(value, torch.optim.Optimizer):
            # (torch's unfused Adam keeps its step count, 0-dimensional, on the CPU)
            for st in value.state.values():
                where["optim"] |= {v.device.type for v in st.values() if v.dim() > 0}
        elif isinstance(value, (torch.Generator, _Generator)):
            where["generators"].add(value.device.type)
        elif isinstance(value, networks.FlatParameters):
            where["parameters"].add(value.flat.device.type)
    return where


@pytest.mark.parametrize("path", ["compiled", "tensors"])
@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("name", OFF_POLICY)
def test_learner_lives_and_updates_on_the_requested_device(name, device, path, monkeypatch):
    if path == "tensors":
        monkeypatch.setattr(networks, "COMPILED", False)
    elif device != "cpu":
        pytest.skip("the compiled kernels are the CPU's")
    learner = _learner(name, device)
    learner.schedule(0, 1)
    with _Devices() as mode:
        losses = learner.update(_batch(device=device))
    assert mode.seen == {device}, mode.seen
    assert losses and all(isinstance(v, float) for v in losses.values())
    where = _placement(learner)
    assert where["parameters"] == where["optim"] == {device}, where
    if name != "safe-dqn-x":  # Rainbow's support and noise, the diffusion schedule
        assert where["buffers"] == {device}, where
    if name == "diffusion-ac":  # the exploring and the evaluation generator
        assert where["generators"] == {device}, where
    b = _batch(8)
    actions = learner.act(b["obs"].numpy(), b["mask"].numpy(), True)  # host in, host out
    assert isinstance(actions, np.ndarray) and actions.shape == (8,)
    assert (b["mask"].numpy()[np.arange(8), actions] > 0).all()


class _Generator:
    """A stand-in for ``torch.Generator`` on a device that has none (meta)."""

    def __init__(self, device: str | torch.device = "cpu") -> None:
        self.device = torch.device(device)

    def manual_seed(self, seed: int) -> _Generator:
        return self


@pytest.mark.parametrize("name", OFF_POLICY)
def test_learner_built_for_another_device_keeps_nothing_on_the_cpu(name, monkeypatch):
    """Built for the meta device (no memory, no kernels: the placement alone), no parameter,
    buffer, schedule constant or generator of the learner stays on the CPU."""
    import cdr_bench.rl.diffusion_ac as dac

    monkeypatch.setattr(dac.torch, "Generator", _Generator)
    learner = _learner(name, "meta")
    where = _placement(learner)
    assert where["parameters"] == {"meta"}, where
    assert where["buffers"] == ({"meta"} if name != "safe-dqn-x" else set()), where
    if name == "diffusion-ac":
        assert where["generators"] == {"meta"}, where


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("algorithm", ["ppo", "td3"])
def test_sb3_model_on_the_requested_device(algorithm, device):
    from cdr_bench.rl.common import training_env
    from cdr_bench.rl.train_sb3 import Args, _new_model
    from cdr_bench.wrappers import vector_env_to_sb3

    args = Args(n_envs=2, width=16, device=device)
    env = vector_env_to_sb3(training_env(args), include_mask=False)
    if algorithm == "td3":
        from cdr_bench.rl.baselines import continuous_to_index

        env = vector_env_to_sb3(
            training_env(args), include_mask=False, continuous_actions=continuous_to_index
        )
    model = _new_model(algorithm, args, env, resolve_device(device))
    assert {p.device.type for p in model.policy.parameters()} == {device}


# --- what is asked against what is available ---------------------------------------------


def test_cuda_without_cuda_is_a_user_error(monkeypatch, tmp_path):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    with pytest.raises(UserError) as e:
        resolve_device("cuda")
    assert "--device cuda" in str(e.value) and "available: cpu" in str(e.value)
    assert resolve_device("auto") == torch.device("cpu")
    assert resolve_device("cpu") == torch.device("cpu")
    with pytest.raises(UserError, match="must be one of auto, cpu, cuda"):
        resolve_device("tpu")
    for algorithm in ("diffusion-ac", "rainbow", "safe-dqn-x", "ppo", "td3"):
        r = cdr_bench(
            "train", algorithm, "--device", "cuda", "--run-dir", str(tmp_path / algorithm),
            "--total-steps", "10", "--no-progress", "--eval-episodes", "0",
        )  # fmt: skip
        assert r.returncode == 2, (algorithm, r.stderr)
        assert "--device cuda: no CUDA device is available" in r.stderr
        assert "available: cpu" in r.stderr and "Traceback" not in r.stderr


def test_auto_picks_cuda_when_there_is_one(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    assert resolve_device("auto") == torch.device("cuda")
