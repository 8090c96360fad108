"""A plain PyTorch agent is a first-class leaderboard entry: scored on one machine, it passes
``leaderboard build --check`` on another.

Two kernel settings stand in for two CPUs (tests/leaderboard/test_cpu_independence.py): the
entries are scored with this machine's own kernels, and checked with torch, numpy, OpenBLAS,
MKL, oneDNN, glibc and numba forced down to their baseline (SSE) kernels, which the scorer
passes on to the confined agent (:data:`cdr_bench.evaluate.sandbox.CPU_KNOBS`). Two agents: one
written from ``agents/template`` with an ordinary ``torch.nn`` network and a state dict beside
it, and the shipped PPO entry's checkpoint run by ``torch.nn`` instead of the fixed numeric
path of ``cdr_bench.inference``. The replay of the committed episodes is exact whatever the
kernels; the agent re-run must agree on at least 99 % of the decisions (here it agrees on all
of them, or the disagreements are listed).
"""

from __future__ import annotations

import os
import shutil
import textwrap
from pathlib import Path

import pytest

from tests.leaderboard.conftest import ROOT, cdr, submission_yaml
from tests.leaderboard.test_cpu_independence import baseline_kernel_env

torch = pytest.importorskip("torch")

TEMPLATE_TORCH = textwrap.dedent(
    '''
    """agents/template/agent.py with a PyTorch policy (a state dict beside this file)."""
    from pathlib import Path

    import numpy as np
    import torch
    from torch import nn

    HERE = Path(__file__).parent


    def network(obs_size: int, n_actions: int) -> nn.Module:
        return nn.Sequential(
            nn.Linear(obs_size, 64), nn.Tanh(), nn.Linear(64, 64), nn.Tanh(),
            nn.Linear(64, n_actions),
        )


    class Agent:
        def __init__(self, observation_space, action_space):
            self.policy = network(observation_space["observation"].shape[0], action_space.n)
            self.policy.load_state_dict(
                torch.load(HERE / "policy.pt", map_location="cpu", weights_only=True)
            )
            self.policy.eval()

        def reset(self, seed):
            pass

        @torch.no_grad()
        def act_batch(self, observations, masks):
            logits = self.policy(torch.as_tensor(observations)).numpy()
            return np.where(masks == 1, logits, -np.inf).argmax(axis=1)

        def act(self, observation):
            return int(self.act_batch(observation["observation"][None],
                                      observation["action_mask"][None])[0])
    '''
)

PPO_TORCH = textwrap.dedent(
    '''
    """The shipped PPO checkpoint, run by torch.nn (Linear + Tanh x 3, Linear -> 27 logits;
    argmax, unmasked like agents/ppo)."""
    import os

    import numpy as np
    import torch
    from torch import nn


    class Agent:
        def __init__(self, observation_space, action_space):
            ck = torch.load(os.environ["CDR_BENCH_CHECKPOINT"], map_location="cpu",
                            weights_only=True)
            sd = ck["state_dict"]
            layers = []
            names = sorted({k.rsplit(".", 1)[0] for k in sd}, key=lambda n: [
                int(p) if p.isdigit() else p for p in n.split(".")])
            for i, n in enumerate(names):
                lin = nn.Linear(sd[n + ".weight"].shape[1], sd[n + ".weight"].shape[0])
                lin.weight.data, lin.bias.data = sd[n + ".weight"], sd[n + ".bias"]
                layers += [lin] + ([nn.Tanh()] if i < len(names) - 1 else [])
            self.net = nn.Sequential(*layers).eval()

        def reset(self, seed):
            pass

        @torch.no_grad()
        def act_batch(self, observations, masks):
            return self.net(torch.as_tensor(observations)).numpy().argmax(axis=1)

        def act(self, observation):
            return int(self.act_batch(observation["observation"][None],
                                      observation["action_mask"][None])[0])
    '''
)


@pytest.mark.slow
def test_pytorch_agents_pass_the_check_under_other_kernels(repo: Path) -> None:
    agents = repo / "agents"
    (agents / "torch_mlp").mkdir()
    (agents / "torch_mlp" / "agent.py").write_text(TEMPLATE_TORCH)
    torch.manual_seed(0)
    net = torch.nn.Sequential(
        torch.nn.Linear(42, 64),
        torch.nn.Tanh(),
        torch.nn.Linear(64, 64),
        torch.nn.Tanh(),
        torch.nn.Linear(64, 27),
    )
    torch.save(net.state_dict(), agents / "torch_mlp" / "policy.pt")
    (agents / "ppo_torch").mkdir()
    (agents / "ppo_torch" / "agent.py").write_text(PPO_TORCH)
    shutil.copy(ROOT / "agents" / "ppo" / "checkpoint.pt", agents / "ppo_torch" / "checkpoint.pt")
    subs = repo / "leaderboard" / "submissions"
    (subs / "torch-mlp.yaml").write_text(submission_yaml("agents/torch_mlp"))
    (subs / "ppo-torch.yaml").write_text(
        submission_yaml(
            "agents/ppo_torch",
            training="python train.py",
            checkpoint="agents/ppo_torch/checkpoint.pt",
        )
    )
    host = {k: v for k, v in os.environ.items() if k not in baseline_kernel_env()}
    names = ("torch-mlp", "ppo-torch")
    r = cdr(
        "leaderboard", "build", "--evaluate", *names, "--reference", "weave", "--workers", 1,
        cwd=repo, env=host, timeout=900,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    other_cpu = {**host, **baseline_kernel_env()}
    r = cdr(
        "leaderboard", "build", "--check", "--evaluate", *names, "--reference", "weave",
        "--workers", 1, "--rerun-batches", 4, cwd=repo, env=other_cpu, timeout=900,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    for name in names:
        assert f"{name}: agent re-run on " in r.stderr
    assert "check passed" in r.stderr
