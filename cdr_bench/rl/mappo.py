"""IPPO and MAPPO: one shared policy for every controlled aircraft (parameter sharing), PPO on
the batched env.

    cdr-bench train mappo --scenario marl/high-all --run-dir runs/mappo --seed 1
    cdr-bench train ippo  --scenario marl/high-all --run-dir runs/ippo  --seed 1

CleanRL-style, in one process: ``n_envs`` episodes of a scenario whose controlled aircraft all
learn (the ``marl/*`` scenarios, docs/model.md §8.4) step together in a
:class:`~cdr_bench.rl.curriculum.CurriculumEnv` (no curriculum: its training-only failure
penalty, LoS penalty and episode cut, and its same-step restart). Every step gives ``E x M``
rows, one per episode and controlled aircraft; the rows of aircraft not flying are left out of
the batch. Each aircraft is its own agent with its own reward, its own ``done`` (its flight
ended) and its own GAE; all of them act with one actor and are updated together.

* **Actor** (both): Linear+Tanh x ``layers`` of ``width``, Linear -> 27 logits, on the
  aircraft's own observation; a masked categorical (infeasible logits set to -1e8) when
  training, the masked argmax when deployed (the layout of the PPO actor of
  :func:`cdr_bench.rl.sb3_policies.ppo_actor`, so the shipped checkpoint is read by
  :class:`cdr_bench.inference.MLP`).
* **Critic, IPPO**: the same shape, on the aircraft's own observation (decentralised).
* **Critic, MAPPO**: centralised: the aircraft's own observation, the mean and the elementwise
  max of the observations of the *other* controlled aircraft flying in the same episode at that
  step (zeros if none), and the fraction of the episode's controlled aircraft still flying:
  ``3 F + 1`` inputs, invariant to the order of the other aircraft and defined for any number
  of them. Only the critic sees it; the actor, and so the deployed agent, is decentralised.

The critic is used in training only; ``checkpoint.pt`` holds the actor (``config`` +
``state_dict``, read with ``torch.load(weights_only=True)``), loaded by agents/ippo and
agents/mappo. A flight cut by the training horizon or the scenario's horizon (truncated)
bootstraps from the critic's value of its last observation; a flight that ends otherwise does
not.
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from cdr_bench.rl import common
from cdr_bench.rl.common import OUTCOME_CHARTS, PPOArgs, RunArgs, from_namespace

# torch is imported inside run(): building the cdr-bench parser must not import it.

NAMES = ("ippo", "mappo")
"""The two trainers of this module (``cdr-bench train ippo`` / ``mappo``)."""


@dataclass
class Args(PPOArgs, RunArgs):
    run_dir: str = "runs/mappo"
    """directory for args.json, log.jsonl and checkpoint.pt"""
    total_steps: int = 2_500_000
    """budget in aircraft transitions (one flying aircraft, one step)"""
    resume: bool = False
    """not supported by this trainer (a run always starts afresh); kept for the train command's
    common checks"""
    scenario: str = "marl/high-all"
    """training scenario (every controlled aircraft learns: the marl/* scenarios)"""
    n_envs: int = 16
    """parallel episodes in the batched simulator"""
    n_steps: int = 32
    """PPO: environment steps per rollout (each gives up to n_envs x controlled aircraft rows)"""
    n_epochs: int = 4
    minibatches: int = 16
    """minibatches per pass"""
    lr: float = 1e-3
    """Adam step size (actor and critic), annealed linearly to 0"""
    gamma: float = 0.99
    """discount"""
    ent_coef: float = 0.01
    vf_coef: float = 0.5
    """value-loss weight"""
    max_grad_norm: float = 0.5
    """gradient-norm clip"""
    width: int = 64
    """hidden width of the actor and the critic"""
    layers: int = 2
    """hidden layers of the actor and the critic"""
    hold_bias: float = 3.0
    """initial logit bias of the hold action (13: keep heading, speed and level): the untrained
    policy then mostly flies its route instead of wandering to the sector's edge (0 = uniform)"""
    failure_penalty: float = 5.0
    """training-only extra penalty when a flight ends in LoS/NMAC/boundary (0 = literal reward)"""
    los_penalty: float = 1.0
    """training-only extra penalty per step and per aircraft in LoS or NMAC with the controlled
    aircraft"""
    max_episode_steps: int = 0
    """training-only episode cut (bootstrapped); 0 = the scenario's horizon"""
    log_every: int = 100_000
    """transitions between log lines"""
    progress: bool = False
    """show a tqdm progress bar"""

    def __post_init__(self) -> None:
        if self.resume:
            raise ValueError("--resume is not supported by ippo/mappo: start a new run")


def add_arguments(p: Any, name: str | None = None) -> None:
    """The flags of :class:`Args`; ``name`` (ippo or mappo) becomes the namespace's
    ``algorithm``."""
    common.add_arguments(p, Args, run_dir=f"runs/{name or 'mappo'}")
    p.set_defaults(algorithm=name or "mappo")


def _algorithm(ns: Any) -> str:
    name = getattr(ns, "algorithm", "mappo")
    if name not in NAMES:
        raise ValueError(f"algorithm must be one of {NAMES}, got {name!r}")
    return str(name)


def critic_inputs(obs: np.ndarray, flying: np.ndarray) -> np.ndarray:
    """(E, M, 3F + 1) centralised-critic inputs of (E, M, F) observations: own observation,
    mean and max over the *other* flying controlled aircraft of the episode (zeros when there is
    none), and the fraction of the episode's M controlled aircraft flying."""
    e_, m_, f_ = obs.shape
    x = obs.astype(np.float32, copy=False)
    fl = flying.astype(np.float32)[..., None]  # (E, M, 1)
    total = (x * fl).sum(axis=1, keepdims=True)  # (E, 1, F)
    n_fly = fl.sum(axis=1, keepdims=True)  # (E, 1, 1)
    n_other = n_fly - fl  # others flying, per row
    mean_other = np.where(n_other > 0, (total - x * fl) / np.maximum(n_other, 1.0), 0.0)
    # max over the others: the largest and the second largest of the flying rows
    neg = np.float32(-np.inf)
    masked = np.where(fl > 0, x, neg)  # (E, M, F)
    if m_ >= 2:
        top2 = -np.partition(-masked, 1, axis=1)[:, :2]  # (E, 2, F): largest, second largest
        first, second = top2[:, :1], top2[:, 1:2]
    else:
        first = masked.max(axis=1, keepdims=True)
        second = np.full_like(first, neg)
    # an aircraft that is the (or a) largest flying value takes the second largest
    is_first = (masked == first) & (fl > 0)
    # ties: if two rows hold the largest, the second largest equals it
    max_other = np.where(is_first, second, first)
    max_other = np.where(n_other > 0, max_other, 0.0)
    max_other = np.where(np.isfinite(max_other), max_other, 0.0)
    frac = np.broadcast_to(n_fly / m_, (e_, m_, 1))
    return np.concatenate([x, mean_other, max_other, frac], axis=-1).astype(np.float32)


def _mlp(torch: Any, d_in: int, width: int, layers: int, d_out: int, out_gain: float) -> Any:
    nn = torch.nn
    mods: list[Any] = []
    d = d_in
    for _ in range(layers):
        lin = nn.Linear(d, width)
        nn.init.orthogonal_(lin.weight, gain=float(np.sqrt(2)))
        nn.init.zeros_(lin.bias)
        mods += [lin, nn.Tanh()]
        d = width
    head = nn.Linear(d, d_out)
    nn.init.orthogonal_(head.weight, gain=out_gain)
    nn.init.zeros_(head.bias)
    mods.append(head)
    return nn.Sequential(*mods)


def save_actor(
    torch: Any, actor: Any, path: str, algorithm: str, args: Args, obs_dim: int, meta: dict
) -> None:
    """The actor as the PPO actor layout (``{2i}.weight``/``bias``, Linear+Tanh): what
    agents/ippo and agents/mappo read."""
    config = {
        "kind": "ppo",
        "algorithm": algorithm,
        "obs_dim": obs_dim,
        "width": args.width,
        "layers": args.layers,
    }
    sd = {k: v.detach().clone().contiguous() for k, v in actor.state_dict().items()}
    tmp = path + ".tmp"
    torch.save({"config": config, "state_dict": sd, "meta": meta}, tmp)
    os.replace(tmp, path)


def run(ns: Any) -> dict[str, Any]:
    import torch

    from cdr_bench.actions import HOLD
    from cdr_bench.rl.curriculum import CurriculumEnv
    from cdr_bench.sim.core import BOUNDARY, SUCCESS

    args: Args = from_namespace(Args, ns)
    algorithm = _algorithm(ns)
    centralised = algorithm == "mappo"
    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    rng = np.random.default_rng(args.seed)
    os.makedirs(args.run_dir, exist_ok=True)
    with open(os.path.join(args.run_dir, "args.json"), "w") as f:
        json.dump({**dataclasses.asdict(args), "algorithm": algorithm}, f, indent=2)
    log_path = os.path.join(args.run_dir, "log.jsonl")
    log = open(log_path, "w")  # noqa: SIM115 - closed in the finally below

    env = CurriculumEnv(
        args.n_envs,
        seed=args.seed,
        scenario=args.scenario,
        failure_penalty=args.failure_penalty,
        max_episode_steps=args.max_episode_steps,
        los_penalty=args.los_penalty,
    )
    E, M, F = args.n_envs, env.n_agents, env.observation_size
    C = 3 * F + 1 if centralised else F
    actor = _mlp(torch, F, args.width, args.layers, 27, 0.01)
    critic = _mlp(torch, C, args.width, args.layers, 1, 1.0)
    with torch.no_grad():
        actor[-1].bias[HOLD] = args.hold_bias
    params = list(actor.parameters()) + list(critic.parameters())
    opt = torch.optim.Adam(params, lr=args.lr, eps=1e-5)

    def critic_in(obs: np.ndarray, flying: np.ndarray) -> np.ndarray:
        return critic_inputs(obs, flying) if centralised else obs

    def values_of(x: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return critic(torch.from_numpy(x)).squeeze(-1).numpy()

    T = args.n_steps
    b_obs = np.zeros((T, E, M, F), np.float32)
    b_cin = np.zeros((T, E, M, C), np.float32)
    b_mask = np.zeros((T, E, M, 27), bool)
    b_act = np.zeros((T, E, M), np.int64)
    b_logp = np.zeros((T, E, M), np.float32)
    b_val = np.zeros((T, E, M), np.float32)
    b_rew = np.zeros((T, E, M), np.float32)
    b_done = np.zeros((T, E, M), bool)
    b_valid = np.zeros((T, E, M), bool)

    obs, masks = env.reset()
    flying = env.flying
    had_los = np.zeros((E, M), bool)
    flights: list[tuple[int, bool]] = []  # (outcome, had LoS) of the flights ended
    step = 0
    last_log = 0
    t0 = time.time()
    updates = 0
    losses: dict[str, float] = {}
    last_rec: dict[str, Any] | None = None
    pbar = None
    if args.progress:
        from tqdm import tqdm

        pbar = tqdm(total=args.total_steps, unit="step", dynamic_ncols=True)

    def write(rec: dict) -> None:
        log.write(json.dumps(rec) + "\n")
        log.flush()

    def interval_record() -> dict[str, Any]:
        oc = np.array([o for o, _ in flights], np.int64)
        hl = np.array([h for _, h in flights], bool)
        rec: dict[str, Any] = {
            "step": step,
            "wall_s": round(time.time() - t0, 1),
            "updates": updates,
            "charts/flights": len(oc),
        }
        if len(oc):
            rec["charts/clean"] = float(np.mean((oc == SUCCESS) & ~hl))
            rec["charts/had_los"] = float(np.mean(hl))
            for code, name in (*OUTCOME_CHARTS, (BOUNDARY, "boundary")):
                rec[f"charts/{name}"] = float(np.mean(oc == code))
        rec.update(losses)
        return rec

    try:
        while step < args.total_steps:
            if args.max_wall_minutes and time.time() - t0 > 60 * args.max_wall_minutes:
                break
            frac = 1.0 - min(1.0, step / args.total_steps)
            for g in opt.param_groups:
                g["lr"] = args.lr * max(frac, 0.05)
            # -- rollout --
            for t in range(T):
                valid = flying
                b_obs[t], b_mask[t], b_valid[t] = obs, masks.astype(bool), valid
                cin = critic_in(obs, flying)
                b_cin[t] = cin
                with torch.no_grad():
                    logits = actor(torch.from_numpy(obs.reshape(-1, F)))
                    logits = torch.where(torch.from_numpy(b_mask[t].reshape(-1, 27)), logits, -1e8)
                    dist = torch.distributions.Categorical(logits=logits)
                    a = dist.sample()
                    logp = dist.log_prob(a)
                    v = critic(torch.from_numpy(cin.reshape(-1, C))).squeeze(-1)
                act = a.numpy().reshape(E, M)
                b_act[t], b_logp[t] = act, logp.numpy().reshape(E, M)
                b_val[t] = v.numpy().reshape(E, M)
                st = env.step(np.where(valid, act, HOLD))
                res = st.result
                had_los |= res.los_with.any(axis=-1) & valid
                rew = st.reward.astype(np.float32)
                ended = st.flight_ended & valid
                trunc = st.truncated & ended
                if trunc.any():  # bootstrap the cut flights from their last observation
                    vt = values_of(critic_in(st.final_obs, valid))
                    rew = rew + np.where(trunc, args.gamma * vt, 0.0).astype(np.float32)
                b_rew[t], b_done[t] = np.where(valid, rew, 0.0), ended
                outcomes = env.env.outcomes
                for e, m in zip(*np.nonzero(ended), strict=True):
                    code = int(res.outcome[e, m]) or int(outcomes[e, m])
                    flights.append((code, bool(had_los[e, m])))
                had_los[ended] = False
                if st.episode_done.any():
                    had_los[st.episode_done] = False
                obs, masks = st.obs, st.action_mask
                flying = env.flying
                n = int(valid.sum())
                step += n
                if pbar is not None:
                    pbar.update(n)
            # -- GAE per aircraft --
            next_v = values_of(critic_in(obs, flying).reshape(-1, C)).reshape(E, M)
            next_v = np.where(flying, next_v, 0.0)
            adv = np.zeros((T, E, M), np.float32)
            last = np.zeros((E, M), np.float32)
            for t in reversed(range(T)):
                nv = next_v if t == T - 1 else b_val[t + 1]
                nonterm = 1.0 - b_done[t]
                delta = b_rew[t] + args.gamma * nv * nonterm - b_val[t]
                last = delta + args.gamma * args.gae_lambda * nonterm * last
                last = np.where(b_valid[t], last, 0.0).astype(np.float32)
                adv[t] = last
            ret = adv + b_val
            sel = b_valid.reshape(-1)
            x_o = torch.from_numpy(b_obs.reshape(-1, F)[sel])
            x_c = torch.from_numpy(b_cin.reshape(-1, C)[sel])
            x_m = torch.from_numpy(b_mask.reshape(-1, 27)[sel])
            x_a = torch.from_numpy(b_act.reshape(-1)[sel])
            x_lp = torch.from_numpy(b_logp.reshape(-1)[sel])
            x_adv = torch.from_numpy(adv.reshape(-1)[sel])
            x_ret = torch.from_numpy(ret.reshape(-1)[sel])
            n_rows = x_o.shape[0]
            stats: dict[str, list[float]] = {"pg": [], "v": [], "ent": [], "kl": [], "clip": []}
            for _ in range(args.n_epochs):
                perm = torch.from_numpy(rng.permutation(n_rows))
                for idx in torch.tensor_split(perm, min(args.minibatches, n_rows)):
                    logits = torch.where(x_m[idx], actor(x_o[idx]), -1e8)
                    dist = torch.distributions.Categorical(logits=logits)
                    lp = dist.log_prob(x_a[idx])
                    ratio = torch.exp(lp - x_lp[idx])
                    a_ = x_adv[idx]
                    a_ = (a_ - a_.mean()) / (a_.std(correction=0) + 1e-8)
                    pg = torch.max(
                        -a_ * ratio,
                        -a_ * torch.clamp(ratio, 1 - args.clip_range, 1 + args.clip_range),
                    ).mean()
                    v = critic(x_c[idx]).squeeze(-1)
                    vl = 0.5 * ((v - x_ret[idx]) ** 2).mean()
                    # entropy over the feasible actions only (masked logits carry 0 probability)
                    p = dist.probs
                    ent = -(p * torch.log(p.clamp_min(1e-12))).sum(-1).mean()
                    loss = pg + args.vf_coef * vl - args.ent_coef * ent
                    opt.zero_grad()
                    loss.backward()
                    torch.nn.utils.clip_grad_norm_(params, args.max_grad_norm)
                    opt.step()
                    with torch.no_grad():
                        stats["pg"].append(float(pg))
                        stats["v"].append(float(vl))
                        stats["ent"].append(float(ent))
                        stats["kl"].append(float(((ratio - 1) - torch.log(ratio)).mean()))
                        stats["clip"].append(
                            float(((ratio - 1).abs() > args.clip_range).float().mean())
                        )
            updates += 1
            losses = {
                "losses/policy": float(np.mean(stats["pg"])),
                "losses/value": float(np.mean(stats["v"])),
                "losses/entropy": float(np.mean(stats["ent"])),
                "losses/approx_kl": float(np.mean(stats["kl"])),
                "losses/clip_fraction": float(np.mean(stats["clip"])),
                "charts/lr": opt.param_groups[0]["lr"],
                "charts/rows_per_update": n_rows,
            }
            if step - last_log >= args.log_every:
                last_log = step
                last_rec = interval_record()
                write(last_rec)
                flights.clear()
        wall = time.time() - t0
        meta = {"steps": step, "updates": updates, "wall_s": round(wall, 1)}
        ck = os.path.join(args.run_dir, "checkpoint.pt")
        save_actor(torch, actor, ck, algorithm, args, F, meta)
        summary = {
            "algorithm": algorithm,
            "scenario": args.scenario,
            "seed": args.seed,
            "steps": step,
            "updates": updates,
            "wall_s": round(wall, 1),
            "checkpoint": ck,
        }
        if flights or last_rec is None:  # the flights since the last log line
            last_rec = interval_record()
            write(last_rec)
        summary.update({k: v for k, v in last_rec.items() if k.startswith("charts/")})
        write({"final": summary})
        return summary
    finally:
        log.close()
        if pbar is not None:
            pbar.close()
