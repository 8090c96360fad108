"""Inference networks of the SB3 baselines, rebuilt from plain weight files (no SB3, no pickle).

SB3 saves a zip whose ``load`` unpickles Python objects, so cdr-bench never ships one: the
trainers export the few tensors an agent needs to a ``.pt`` file that agents read with
``torch.load(weights_only=True)`` and load into the same layers built here.

* PPO / MaskablePPO (``MlpPolicy``, ``net_arch = dict(pi=[128] * 3, vf=[128] * 3)``, Tanh): the
  actor is ``mlp_extractor.policy_net`` followed by ``action_net`` -> 27 logits; the agent takes
  the argmax (SB3's ``deterministic=True``), over the feasible actions for MaskablePPO.
* TD3 (``net_arch = [128] * 3``, ReLU): the actor ``actor.mu`` -> tanh -> (a_psi, a_v, a_h) in
  [-1, 1]^3, rounded by :func:`cdr_bench.rl.baselines.continuous_to_index`.
"""

from __future__ import annotations

from typing import Any

import torch
from torch import nn


def ppo_actor(
    obs_dim: int, width: int = 128, layers: int = 3, n_actions: int = 27
) -> nn.Sequential:
    """Linear+Tanh x ``layers``, then Linear -> logits (the layout of SB3's PPO actor)."""
    mods: list[nn.Module] = []
    d = obs_dim
    for _ in range(layers):
        mods += [nn.Linear(d, width), nn.Tanh()]
        d = width
    mods.append(nn.Linear(d, n_actions))
    return nn.Sequential(*mods)


def td3_actor(obs_dim: int, width: int = 128, layers: int = 3, act_dim: int = 3) -> nn.Sequential:
    """Linear+ReLU x ``layers``, Linear, Tanh (SB3's ``TD3`` ``actor.mu``)."""
    mods: list[nn.Module] = []
    d = obs_dim
    for _ in range(layers):
        mods += [nn.Linear(d, width), nn.ReLU()]
        d = width
    mods += [nn.Linear(d, act_dim), nn.Tanh()]
    return nn.Sequential(*mods)


def export_actor(model: Any, kind: str, path: str, meta: dict, **config_extra: Any) -> None:
    """Write the actor of a trained SB3 ``model`` (kind "ppo" or "td3") to ``path``;
    ``config_extra`` goes into its config (``mvp_input=True``: the observation has
    :func:`cdr_bench.resolvers.mvp_onehot` appended)."""
    config, sd = actor_state(model, kind)
    config.update(config_extra)
    torch.save({"config": config, "state_dict": sd, "meta": meta}, path)


def actor_of(model: Any, kind: str) -> nn.Sequential:
    """The actor of an SB3 ``model`` as the network :func:`load_actor` gives (a copy, in eval
    mode): what the exported checkpoint would hold now."""
    config, sd = actor_state(model, kind)
    return _build(config, sd)


def actor_state(model: Any, kind: str) -> tuple[dict, dict[str, torch.Tensor]]:
    """``(config, state_dict)`` of the actor of an SB3 ``model`` (kind "ppo" or "td3")."""
    obs_dim = int(model.observation_space.shape[0])
    if kind == "ppo":
        pol = model.policy
        sd: dict[str, torch.Tensor] = {}
        linears = [m for m in pol.mlp_extractor.policy_net if isinstance(m, nn.Linear)]
        linears.append(pol.action_net)
        for i, lin in enumerate(linears):
            sd[f"{2 * i}.weight"] = lin.weight.detach().cpu().clone()
            sd[f"{2 * i}.bias"] = lin.bias.detach().cpu().clone()
        layers = len(linears) - 1
        width = int(linears[0].out_features)
    elif kind == "td3":
        sd = {k: v.detach().cpu().clone() for k, v in model.actor.mu.state_dict().items()}
        mu_linears = [m for m in model.actor.mu if isinstance(m, nn.Linear)]
        layers, width = len(mu_linears) - 1, int(mu_linears[0].out_features)
    else:
        raise ValueError(f"kind must be 'ppo' or 'td3', got {kind!r}")
    return {"kind": kind, "obs_dim": obs_dim, "width": width, "layers": layers}, sd


def load_actor(path: str) -> tuple[nn.Sequential, dict]:
    """(network in eval mode, config) from an exported actor, read with ``weights_only=True``."""
    ck = torch.load(path, map_location="cpu", weights_only=True)
    return _build(ck["config"], ck["state_dict"]), ck["config"]


def _build(cfg: dict, sd: dict[str, torch.Tensor]) -> nn.Sequential:
    build = ppo_actor if cfg["kind"] == "ppo" else td3_actor
    with torch.random.fork_rng(devices=[]):  # the initial weights are overwritten: draw nothing
        net = build(cfg["obs_dim"], cfg["width"], cfg["layers"])
    net.load_state_dict(sd)
    return net.eval()
