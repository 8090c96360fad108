"""A teacher's demonstrations for PPO and MaskablePPO: imitation first, then RL (issue 16 item 6,
"``mvp`` as a teacher").

``cdr-bench train maskable-ppo --teacher agents/mvp --teacher-transitions 200000`` rolls the
teacher (any agent folder or file of the agent protocol, run in this process: it is the
trainer's own choice, not a scored entry) through its own copy of the training environment
(the same scenario, curriculum stage 1 or ``--scenario``, penalties and cut; a separate episode
stream, so the RL phase sees the same episodes as without a teacher), then fits the policy to
the teacher's actions (cross-entropy over the feasible actions for MaskablePPO) and the value
head to the teacher's discounted returns, before PPO starts. The returns are those of the
training reward (failure and LoS penalties included) summed to the end of each flight; flights
cut by the training horizon or still flying when the demonstrations end are dropped from the
value fit only. Pure numpy and torch; the policy is an SB3 ``ActorCriticPolicy``.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cdr_bench.actions import N_ACTIONS
from cdr_bench.errors import UserError
from cdr_bench.rl.common import TrainArgs, training_env

TEACHER_SEED_OFFSET = 7_919
"""the teacher's environment is seeded ``seed + TEACHER_SEED_OFFSET`` (its own episodes)"""


def _teacher_actions(act_batch: Any, obs: NDArray[Any], mask: NDArray[Any]) -> NDArray[np.int64]:
    """The teacher's (N,) actions, checked: integers in 0..26 (else a :class:`UserError`)."""
    try:
        out = np.asarray(act_batch(obs, mask))
    except Exception as e:
        raise UserError(f"--teacher: act_batch raised {type(e).__name__}: {e}") from None
    if (
        out.shape != (len(obs),)
        or out.dtype.kind not in "iu"
        or not ((out >= 0) & (out < N_ACTIONS)).all()
    ):
        raise UserError(
            f"--teacher: act_batch must return {len(obs)} integer actions in 0..{N_ACTIONS - 1}, "
            f"got shape {out.shape}, dtype {out.dtype}"
        )
    return out.astype(np.int64)


def demonstrations(act_batch: Any, args: TrainArgs, transitions: int) -> dict[str, NDArray[Any]]:
    """At least ``transitions`` (obs, mask, action) rows of the teacher ``act_batch`` in the
    training environment of ``args``, with ``ret`` (discounted return of the training reward
    from that step to the end of the flight) and ``has_ret`` (False where the flight did not
    end by itself before the demonstrations stopped)."""
    env = training_env(dataclasses.replace(args, seed=args.seed + TEACHER_SEED_OFFSET))
    obs, mask = env.observe()
    cols: dict[str, list[NDArray[Any]]] = {"obs": [], "mask": [], "action": []}
    rewards: list[float] = []
    open_rows: dict[int, list[int]] = {}  # slot -> rows of its flight so far
    ret: list[float] = []
    has_ret: list[bool] = []
    n = 0
    while n < transitions:
        acting = env.flying
        actions = np.full(acting.shape, 13, dtype=np.int64)
        if acting.any():
            actions[acting] = _teacher_actions(act_batch, obs[acting], mask[acting])
        st = env.step(actions)
        slots = np.flatnonzero(acting)
        cols["obs"].append(obs[acting])
        cols["mask"].append(mask[acting])
        cols["action"].append(actions[acting])
        flat_reward = st.reward.reshape(-1)
        ended = st.flight_ended.reshape(-1)
        # cut by the horizon or the training cut, or discarded by a promotion: not complete
        cut = st.truncated.reshape(-1) | st.promoted
        for s in slots:
            row = len(rewards)
            rewards.append(float(flat_reward[s]))
            ret.append(0.0)
            has_ret.append(False)
            open_rows.setdefault(int(s), []).append(row)
            if ended[s]:
                rows = open_rows.pop(int(s))
                if not cut[s]:  # ended by itself: the return is complete
                    g = 0.0
                    for r in reversed(rows):
                        g = rewards[r] + args.gamma * g
                        ret[r], has_ret[r] = g, True
        n += len(slots)
        obs, mask = st.obs, st.action_mask
    out = {k: np.concatenate(v) for k, v in cols.items()}
    out["ret"] = np.asarray(ret, np.float32)
    out["has_ret"] = np.asarray(has_ret, bool)
    return out


def fit_policy(
    policy: Any,
    data: dict[str, NDArray[Any]],
    epochs: int,
    batch_size: int,
    seed: int,
    masked: bool,
    vf_coef: float = 0.5,
) -> dict[str, float]:
    """Behaviour cloning of an SB3 actor-critic ``policy`` on ``data`` (from
    :func:`demonstrations`) with the policy's own optimizer: minimise
    ``-log pi(a_teacher | s) + vf_coef * (V(s) - ret)^2`` (the value term on rows with a
    complete return). Returns ``teacher/*`` statistics: the greedy policy's agreement with the
    teacher before and after, and the last epoch's losses."""
    import torch

    dev = policy.device  # the demonstrations on the policy's device
    obs = torch.as_tensor(data["obs"], dtype=torch.float32, device=dev)
    mask = torch.as_tensor(data["mask"] != 0, device=dev)
    act = torch.as_tensor(data["action"], dtype=torch.int64, device=dev)
    ret = torch.as_tensor(data["ret"], dtype=torch.float32, device=dev)
    has_ret = torch.as_tensor(data["has_ret"], dtype=torch.float32, device=dev)
    gen = torch.Generator().manual_seed(seed)

    def agreement() -> float:
        with torch.no_grad():
            logits = policy.get_distribution(obs).distribution.logits
            if masked:
                logits = logits.masked_fill(~mask, -torch.inf)
            return float((logits.argmax(1) == act).float().mean())

    stats = {"teacher/transitions": float(len(act)), "teacher/agreement_before": agreement()}
    policy.set_training_mode(True)
    bc = vf = 0.0
    for _ in range(epochs):
        order = torch.randperm(len(act), generator=gen)
        bc_sum = vf_sum = 0.0
        for start in range(0, len(act), batch_size):
            i = order[start : start + batch_size].to(dev)
            kw = {"action_masks": mask[i].cpu().numpy()} if masked else {}
            values, logp, _ = policy.evaluate_actions(obs[i], act[i], **kw)
            w = has_ret[i]
            v_loss = (w * (values.flatten() - ret[i]) ** 2).sum() / w.sum().clamp(min=1.0)
            loss = -logp.mean() + vf_coef * v_loss
            policy.optimizer.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(policy.parameters(), 0.5)
            policy.optimizer.step()
            bc_sum += float(-logp.detach().mean()) * len(i)
            vf_sum += float(v_loss.detach()) * len(i)
        bc, vf = bc_sum / len(act), vf_sum / len(act)
    policy.set_training_mode(False)
    stats.update(
        {
            "teacher/epochs": float(epochs),
            "teacher/bc_loss": bc,
            "teacher/value_loss": vf,
            "teacher/agreement_after": agreement(),
            "teacher/complete_returns": float(data["has_ret"].mean()),
        }
    )
    return stats
