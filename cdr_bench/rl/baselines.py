"""Shared pieces of the baseline trainers (PPO, MaskablePPO, TD3, Rainbow-DQN, Safe-DQN-X).

Pure numpy (no torch, no SB3): the trainer modules import this at module level, and building the
``cdr-bench`` parser must stay torch-free.

* :class:`SplitTrainEnv` -- :class:`~cdr_bench.rl.vecenv.TrainEnv` (the batched simulator with the
  DPSC curriculum, the same environment and reward Diffusion-AC trains on) that also returns the
  goal part and the safety part of each transition's reward (Safe-DQN-X learns them apart) and
  which rows ended their episode (n-step returns and SB3 vector envs need it);
* flags from a CleanRL-style ``Args`` dataclass (one flag per field, its docstring as the help);
* the JSONL log and the learning-curve PNG.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import json
import os
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cdr_bench.rl.vecenv import TrainEnv
from cdr_bench.scenarios import load_scenario
from cdr_bench.sim import Simulator
from cdr_bench.sim.core import GOAL_TERMS, LOS, NMAC, SAFETY_TERMS, StepResult

OUTCOME_CHARTS = ((1, "success"), (2, "nmac"), (3, "los_end"), (5, "timeout"))
"""Outcome codes of :mod:`cdr_bench.sim.core` reported in the log as ``charts/<name>``."""


class _RecordingSimulator(Simulator):
    """A :class:`Simulator` that keeps the last :class:`StepResult` (its named reward terms)."""

    last: StepResult | None = None

    def step(self, actions: NDArray[np.integer]) -> StepResult:
        self.last = super().step(actions)
        return self.last


class SplitTrainEnv(TrainEnv):
    """:class:`TrainEnv` whose :meth:`step` also returns, per returned row:

    * ``goal_reward``: the goal part R_G (terms ``goal, path, boundary, step, timeout``),
    * ``safety_reward``: the safety part R_S (terms ``los, nmac``) minus the training-only
      ``failure_penalty`` of a transition that ends the episode in LoS or NMAC (so that
      ``goal_reward + safety_reward == reward`` exactly),
    * ``ended``: this row's episode ended at this step (terminated, cut by
      ``max_episode_steps`` or the horizon, or discarded by a curriculum promotion); the row's
      next observation from :meth:`observe` is then the first of a new episode.

    Only single-ownship scenarios (M = 1: every density and curriculum scenario), so row i is
    episode i at every step.
    """

    def _build(self) -> None:
        self.sim = _RecordingSimulator(load_scenario(self.scenario), n_episodes=self.E)
        self.sim.reset(self._seeds(self.E))
        self.M = self.sim.M
        if self.M != 1:
            raise ValueError(
                f"scenario {self.scenario!r} has {self.M} controlled aircraft; the baseline "
                "trainers train the ownship of single-ownship scenarios"
            )

    def step(self, actions: NDArray[np.integer]) -> dict:
        sim = self.sim  # a promotion replaces self.sim inside TrainEnv.step
        flying = sim.ac_active.reshape(-1).copy()
        out = super().step(actions)
        assert isinstance(sim, _RecordingSimulator) and sim.last is not None
        res = sim.last
        goal = np.sum([res.rewards[k] for k in GOAL_TERMS], axis=0).reshape(-1)
        safety = np.sum([res.rewards[k] for k in SAFETY_TERMS], axis=0).reshape(-1)
        failed = np.isin(res.outcome, (LOS, NMAC)).reshape(-1)
        safety = safety - self.failure_penalty * failed
        if out["promoted"]:
            ended = np.ones(self.E, bool)
        else:
            # Episodes that ended were reset by TrainEnv.step, and only a reset sets steps to 0.
            ended = sim.steps.reshape(-1) == 0
        out["goal_reward"] = goal[flying].astype(np.float32)
        out["safety_reward"] = safety[flying].astype(np.float32)
        out["ended"] = ended[flying]
        return out


# --- flags from an Args dataclass -----------------------------------------------------------


def field_docs(cls: type) -> dict[str, str]:
    """The docstring under each field of the dataclass ``cls``, read from its source."""
    tree = ast.parse(inspect.getsource(cls))
    body = tree.body[0].body  # type: ignore[attr-defined]
    docs = {}
    for a, b in zip(body, body[1:], strict=False):
        if isinstance(a, ast.AnnAssign) and isinstance(b, ast.Expr):
            docs[a.target.id] = str(b.value.value)  # type: ignore[union-attr,attr-defined]
    return docs


def add_dataclass_arguments(p: argparse.ArgumentParser, cls: type, **defaults: Any) -> None:
    """One flag per field of ``cls`` (``--no-curriculum`` etc. for booleans); ``defaults``
    overrides field defaults (one Args class serves several algorithms)."""
    docs = field_docs(cls)
    for f in dataclasses.fields(cls):
        default = defaults.get(f.name, f.default)
        flag = "--" + f.name.replace("_", "-")
        doc = docs.get(f.name, "").replace("%", "%%") + f" (default: {default})"
        if f.type in ("bool", bool):
            p.add_argument(flag, action=argparse.BooleanOptionalAction, default=default, help=doc)
        else:
            typ = {"int": int, "float": float, "str": str}[str(f.type)]
            p.add_argument(flag, type=typ, default=default, help=doc)


def from_namespace(cls: type, ns: argparse.Namespace) -> Any:
    return cls(**{f.name: getattr(ns, f.name) for f in dataclasses.fields(cls)})


def write_args(run_dir: str, args: Any, **extra: Any) -> None:
    with open(os.path.join(run_dir, "args.json"), "w") as f:
        json.dump({**dataclasses.asdict(args), **extra}, f, indent=2)


# --- logging ----------------------------------------------------------------------------------


class JsonlLog:
    """Append-only JSONL log (``run_dir/log.jsonl``), truncated on a fresh (non-resumed) run."""

    def __init__(self, run_dir: str, resume: bool):
        self.path = os.path.join(run_dir, "log.jsonl")
        if not resume:
            with open(self.path, "w"):
                pass

    def write(self, rec: dict) -> None:
        with open(self.path, "a") as f:
            f.write(json.dumps(rec) + "\n")


def outcome_charts(outcomes: list[int]) -> dict[str, float]:
    """``charts/<outcome>``: share of the episodes that ended in the interval, per outcome."""
    oc = np.asarray(outcomes)
    rec: dict[str, float] = {"charts/episodes_in_interval": float(len(oc))}
    for code, name in OUTCOME_CHARTS:
        rec[f"charts/{name}"] = float(np.mean(oc == code)) if len(oc) else float("nan")
    return rec


def plot_curve(log_path: str, out_png: str, title: str) -> None:
    """Learning curve from ``log.jsonl``: success (rolling and per interval), DPSC stage, losses
    (every ``losses/*`` key, log scale)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [json.loads(x) for x in open(log_path) if x.strip()]
    rows = [r for r in rows if "charts/success_rolling" in r]
    if not rows:
        return
    s = [r["step"] for r in rows]
    fig, ax = plt.subplots(1, 3, figsize=(15, 4))
    ax[0].plot(s, [r["charts/success_rolling"] for r in rows], label="rolling success")
    ax[0].plot(
        s,
        [np.nan if r["charts/success"] is None else r["charts/success"] for r in rows],
        alpha=0.5,
        label="success in interval",
    )
    ax[0].set_ylim(0, 1)
    ax[0].legend()
    ax[0].set_title(title)
    ax[1].plot(s, [r.get("curriculum/stage", 0) for r in rows])
    ax[1].set_title("DPSC stage (0 = no curriculum)")
    keys = sorted({k for r in rows for k in r if k.startswith("losses/")})
    for k in keys:
        v = np.array([r.get(k, np.nan) for r in rows], float)
        ax[2].plot(s, np.abs(v), label=k.split("/", 1)[1])
    if keys:
        ax[2].set_yscale("log")
        ax[2].legend()
        ax[2].set_title("|loss|")
    for a in ax:
        a.set_xlabel("environment steps")
    fig.tight_layout()
    fig.savefig(out_png, dpi=80)
    plt.close(fig)


# --- TD3's hybrid adaptation (paper §5.2) ---------------------------------------------------


def continuous_to_index(action: NDArray[np.floating]) -> NDArray[np.int64]:
    """TD3's continuous output (N, 3) in [-1, 1]^3, ordered (a_psi, a_v, a_h), rounded to the
    nearest value of {-1, 0, +1} per component (below -0.5 -> -1, above +0.5 -> +1, else 0;
    +-0.5 itself -> 0), then encoded as the action index 9 (a_psi + 1) + 3 (a_v + 1) + (a_h + 1).

    No mask is applied (the paper's TD3 is unmasked): a climb rounded at the top level (or a
    descent at level 0) is executed without its level change and counted as an invalid action.
    """
    a = np.asarray(action, np.float64).reshape(-1, 3)
    triple = (a > 0.5).astype(np.int64) - (a < -0.5).astype(np.int64)
    return 9 * (triple[:, 0] + 1) + 3 * (triple[:, 1] + 1) + (triple[:, 2] + 1)
