"""What every trainer shares (the off-policy loop and the Stable-Baselines3 trainer).

Pure numpy (no torch, no SB3): the trainer modules import this at module level, and building the
``cdr-bench`` parser must stay torch-free.

* :class:`TrainArgs` -- the flags of every trainer, CleanRL style: one dataclass field per flag,
  the docstring under it is the help (:func:`add_arguments`, :func:`from_namespace`); those of
  every run, whatever its algorithm (also IPPO/MAPPO's), are its base :class:`RunArgs`; those
  of the PPO update, for the trainers that run it, :class:`PPOArgs`;
* :func:`training_env` -- the :class:`~cdr_bench.rl.curriculum.CurriculumEnv` the flags describe;
* :class:`RunLog` -- the run directory's ``args.json`` and ``log.jsonl``, the progress bar, the
  wall-time limit and the learning curve. Log keys have fixed prefixes: ``charts/`` (rollout
  statistics and scheduled hyper-parameters), ``losses/`` (what the learner's update returns),
  ``curriculum/`` (stage, promotions), ``curve/`` (the greedy policy on the fixed evaluation
  set, every ``curve_every`` transitions: the learning curve), ``eval/`` (the final quick
  evaluation, in the ``final`` line);
* :func:`quick_evaluation` -- the final quick evaluation on the three densities;
* :func:`untouched_rng` -- runs an evaluation without moving any random stream of training.
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import dataclasses
import inspect
import json
import os
import random
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cdr_bench.checks import ranged
from cdr_bench.evaluate.results import atomic_write_text
from cdr_bench.render import figure_png
from cdr_bench.rl.curriculum import Curriculum, CurriculumEnv
from cdr_bench.rl.quick_eval import ActBatch, quick_eval

OUTCOME_CHARTS = ((1, "success"), (2, "nmac"), (3, "los_end"), (5, "timeout"))
"""Outcome codes of :mod:`cdr_bench.sim.core` reported in the log as ``charts/<name>``."""

CURVE_SCENARIO, CURVE_SEED = "high", 20_000
"""The fixed evaluation set of the learning curve: ``curve_episodes`` episodes of ``high`` with
episode seeds 20000.. (the same episodes at every point of every run; other controlled
aircraft hold)."""


@dataclass
class RunArgs:
    """The flags of every training run, whatever its algorithm: where it writes, its seed,
    budget, wall-time limit and threads, and whether it resumes. A trainer's Args extends it
    (:class:`TrainArgs`, or :class:`cdr_bench.rl.mappo.Args` directly), redeclaring a field whose
    default or help differs."""

    run_dir: str = "runs/train"
    """directory for logs, checkpoints and the curve"""
    seed: int = 1
    """seed of torch, numpy and the episode-seed stream"""
    total_steps: int = 200_000
    """budget in environment transitions (one flying aircraft, one step)"""
    max_wall_minutes: float = 0.0
    """stop (and finish normally) after this wall time; 0 = no limit"""
    threads: int = 1
    """torch intra-op threads of the training process (1: one per process; the networks are small
    and the simulator single-threaded, so more threads mostly contend)"""
    resume: bool = False
    """continue exactly from the state saved in run_dir"""


@dataclass
class PPOArgs:
    """The flags of the PPO update, declared once for the trainers that run it (PPO and
    MaskablePPO of :mod:`cdr_bench.rl.train_sb3`, IPPO/MAPPO): their Args list it as the first
    base, redeclaring a default or help that differs."""

    n_steps: int = 128
    """PPO: rollout length per sub-environment"""
    n_epochs: int = 10
    """PPO: passes over each rollout"""
    clip_range: float = 0.2
    """PPO: clip of the probability ratio"""
    gae_lambda: float = 0.95
    """PPO: GAE lambda"""
    ent_coef: float = 0.0
    """PPO: entropy bonus coefficient"""


@dataclass
class TrainArgs(RunArgs):
    n_envs: int = 32
    """parallel episodes in the batched simulator"""
    device: str = "cpu"
    """where the networks train: cpu (the tested, deterministic default), cuda, or auto (cuda
    if available); collection stays on the host"""
    scenario: str = "medium"
    """training scenario without the curriculum"""
    failure_penalty: float = 5.0
    """training-only extra penalty when a flight ends in LoS/NMAC (0 = literal reward)"""
    max_episode_steps: int = 200
    """training-only episode cut (bootstrapped, counted as a failure); 0 = scenario horizon"""
    los_penalty: float = 0.0
    """training-only extra penalty per step and per aircraft in LoS or NMAC with the controlled
    aircraft (0 = the scenario's own weights only)"""
    soft_boundary: bool = False
    """training-only: the paper's soft boundary (``sector.boundary_margin_km: null``, the reward
    of cdr-bench 0.1 that the Diffusion-AC reference run was trained with: flights never end
    outside the sector and the path term is unbounded) instead of each scenario's margin"""
    curriculum: bool = True
    """DPSC on (stages 1..12) or off (train on ``scenario``)"""
    window: int = 100
    """DPSC promotion window (episodes)"""
    promote_at: float = 0.9
    """DPSC promotion threshold on the rolling success rate"""
    gamma: float = 0.99
    """discount"""
    progress: bool = True
    """show a tqdm progress bar"""
    log_every: int = 10_000
    """transitions between log lines"""
    checkpoint_every: int = 50_000
    """transitions between checkpoints"""
    eval_episodes: int = 100
    """episodes per density for the final quick evaluation (0 = skip)"""
    curve_every: int = 50_000
    """transitions between evaluations of the greedy policy on the fixed evaluation set (the
    learning curve; 0 = off; training is the same with or without them)"""
    curve_episodes: int = 100
    """episodes of the fixed evaluation set (high, episode seeds 20000..)"""


def training_env(args: TrainArgs) -> CurriculumEnv:
    return CurriculumEnv(
        args.n_envs,
        seed=args.seed,
        scenario=args.scenario,
        curriculum=Curriculum(args.window, args.promote_at) if args.curriculum else None,
        failure_penalty=args.failure_penalty,
        max_episode_steps=args.max_episode_steps,
        los_penalty=args.los_penalty,
        **({"sector": {"boundary_margin_km": None}} if args.soft_boundary else {}),
    )


def linear_schedule(start: float, end: float, duration: float, t: float) -> float:
    """``start`` at t = 0, linear to ``end`` at t = ``duration`` (at least 1), ``end`` after."""
    return start + min(1.0, t / max(1.0, duration)) * (end - start)


# --- flags from an Args dataclass -----------------------------------------------------------


def field_docs(cls: type) -> dict[str, str]:
    """The docstring under each field of the dataclass ``cls`` and of its dataclass bases
    (a field redeclared without a docstring keeps its base's)."""
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if not dataclasses.is_dataclass(klass):
            continue
        body = ast.parse(inspect.getsource(klass)).body[0].body  # type: ignore[attr-defined]
        for a, b in zip(body, body[1:], strict=False):
            if isinstance(a, ast.AnnAssign) and isinstance(b, ast.Expr):
                docs[a.target.id] = str(b.value.value)  # type: ignore[union-attr,attr-defined]
    return docs


_SCALARS = {"int": int, "float": float, "str": str}

_INF = float("inf")
FLAG_RANGES: dict[str, tuple[float, float, bool]] = {
    # whole numbers >= 1: sizes, counts and intervals
    **{
        n: (1, _INF, True)
        for n in (
            "T", "batch_size", "buffer_size", "checkpoint_every", "critic_width",
            "curve_episodes", "layers", "log_every", "minibatches", "n_atoms", "n_blocks",
            "n_envs", "n_epochs", "n_step", "n_steps", "ppo_batch_size", "threads",
            "total_steps", "update_every", "width", "window",
        )
    },
    # whole numbers >= 0 (0 = off, none or the scenario's own)
    **{
        n: (0, _INF, True)
        for n in (
            "curve_every", "eval_episodes", "learning_starts", "max_episode_steps", "seed",
            "stop_at", "teacher_epochs", "teacher_transitions",
        )
    },
    # fractions and probabilities
    **{
        n: (0, 1, True)
        for n in (
            "alpha", "beta_start", "eps_end", "eps_fraction", "eps_smooth", "eps_start",
            "gae_lambda", "gamma", "polyak", "promote_at",
        )
    },
    # step sizes and temperatures: > 0
    **{
        n: (0, _INF, False)
        for n in ("lr", "lr_actor", "lr_critic", "max_grad_norm", "tau_start", "tau_end")
    },
    # weights, penalties, noise scales, margins and limits: >= 0
    **{
        n: (0, _INF, True)
        for n in (
            "action_noise", "ce_weight", "clip_range", "ent_coef", "failure_penalty", "hold_bias",
            "los_penalty", "max_wall_minutes", "sigma0", "slack", "vf_coef",
        )
    },
    # any number (v_min < v_max is checked with the other fields); q_target_max may be inf
    **{n: (-_INF, _INF, True) for n in ("v_min", "v_max")},
    "q_target_max": (-_INF, _INF, True),
}  # fmt: skip
"""The values each numeric training flag accepts: (low, high, low included). A value outside,
or NaN, or an infinity where the range is finite, is refused when the flags are parsed, with
the flag's name and range (exit 2): a trainer never starts on a value it cannot use. A numeric
flag missing here is an error when its parser is built (tests/rl/test_flag_ranges.py)."""


def _ranged(kind: type, name: str) -> Any:
    """The argparse ``type`` of a numeric flag: parse, then check :data:`FLAG_RANGES` (with the
    one range check of every command, :func:`cdr_bench.checks.ranged`)."""
    low, high, low_in = FLAG_RANGES[name]
    return ranged(kind, low, high, low_in=low_in, inf_ok=name == "q_target_max")


def _type_name(f: dataclasses.Field) -> str:
    return f.type if isinstance(f.type, str) else getattr(f.type, "__name__", "")


def flag_fields(cls: type) -> list[dataclasses.Field]:
    """The fields of ``cls`` that are flags (booleans and scalars)."""
    return [f for f in dataclasses.fields(cls) if _type_name(f) in (*_SCALARS, "bool")]


def add_arguments(p: argparse.ArgumentParser, cls: type, **defaults: Any) -> None:
    """One flag per field of ``cls`` (``--no-curriculum`` etc. for booleans); ``defaults``
    overrides field defaults (one Args class serves several algorithms)."""
    docs = field_docs(cls)
    for f in flag_fields(cls):
        default = defaults.get(f.name, f.default)
        flag = "--" + f.name.replace("_", "-")
        doc = docs.get(f.name, "").replace("%", "%%") + f" (default: {default})"
        if _type_name(f) == "bool":
            p.add_argument(flag, action=argparse.BooleanOptionalAction, default=default, help=doc)
        else:
            kind = _SCALARS[_type_name(f)]
            if kind is not str and f.name not in FLAG_RANGES:
                raise TypeError(f"{cls.__name__}.{f.name}: a numeric flag without a range")
            typ = kind if kind is str else _ranged(kind, f.name)
            p.add_argument(flag, type=typ, default=default, help=doc)


def from_namespace(cls: type, ns: argparse.Namespace) -> Any:
    return cls(**{f.name: getattr(ns, f.name) for f in flag_fields(cls)})


def same_named(args: Any, names: Any, **explicit: Any) -> dict[str, Any]:
    """The values of ``args``'s fields named in ``names`` (a dataclass: its fields) that
    ``args`` has, then ``explicit``: keyword arguments that mirror the flags."""
    if dataclasses.is_dataclass(names):
        names = [f.name for f in dataclasses.fields(names)]
    return {**{n: getattr(args, n) for n in names if hasattr(args, n)}, **explicit}


# --- the run directory ----------------------------------------------------------------------


class RunLog:
    """``args.json``, the append-only ``log.jsonl`` (truncated unless resuming), the progress
    bar, the wall clock and when log lines and checkpoints are due. ``state``: what
    :meth:`state_dict` gave in the process that wrote the state a run resumes from."""

    def __init__(self, args: TrainArgs, algorithm: str, state: dict[str, Any] | None = None):
        self.args, self.t0 = args, time.time()
        st = state or {"step": 0, "wall_s": 0.0, "last_log": 0, "last_ckpt": 0}
        self.wall_before = st["wall_s"]
        self.last_log, self.last_ckpt = st["last_log"], st["last_ckpt"]
        # The first point at the first transition (the initial policy); a state written before
        # the curve existed likewise gets its first point at the next transition.
        self.last_curve = st.get("last_curve", st["step"] - args.curve_every)
        os.makedirs(args.run_dir, exist_ok=True)
        self.path = os.path.join(args.run_dir, "log.jsonl")
        if not args.resume:
            with open(self.path, "w"):
                pass
        elif os.path.exists(self.path):
            self._drop_lines_after(st["step"])
        with open(os.path.join(args.run_dir, "args.json"), "w") as f:
            json.dump({**dataclasses.asdict(args), "algorithm": algorithm}, f, indent=2)
        self.pbar = None
        if args.progress:
            from tqdm import tqdm

            self.pbar = tqdm(
                total=args.total_steps, initial=st["step"], unit="step", dynamic_ncols=True
            )

    def _drop_lines_after(self, step: int) -> None:
        """A run that died after its last saved state wrote log lines the resumed run will
        write again: keep only the lines up to the state's ``step`` (a ``final`` line of a run
        that finished and is extended stays: it records where that run ended)."""
        with open(self.path, encoding="utf-8") as f:
            lines = f.readlines()
        keep = []
        for line in lines:
            try:
                row = json.loads(line)
            except json.JSONDecodeError:  # a line cut by the death
                continue
            if isinstance(row, dict) and isinstance(row.get("step"), int) and row["step"] > step:
                continue
            keep.append(line if line.endswith("\n") else line + "\n")
        if keep != lines:
            tmp = self.path + ".tmp"
            with open(tmp, "w", encoding="utf-8") as f:
                f.writelines(keep)
            os.replace(tmp, self.path)

    def state_dict(self, step: int) -> dict[str, Any]:
        return {
            "step": step,
            "wall_s": self.wall(),
            "last_log": self.last_log,
            "last_ckpt": self.last_ckpt,
            "last_curve": self.last_curve,
        }

    def log_due(self, step: int) -> bool:
        """``log_every`` transitions since the last log line (then it is due no more)."""
        due = step - self.last_log >= self.args.log_every
        self.last_log = step if due else self.last_log
        return due

    def checkpoint_due(self, step: int) -> bool:
        """``checkpoint_every`` transitions since the last checkpoint (then it is due no more)."""
        due = step - self.last_ckpt >= self.args.checkpoint_every
        self.last_ckpt = step if due else self.last_ckpt
        return due

    def curve_due(self, step: int) -> bool:
        """``curve_every`` transitions since the last point of the learning curve (then it is
        due no more); never when ``curve_every`` is 0."""
        due = bool(self.args.curve_every) and step - self.last_curve >= self.args.curve_every
        self.last_curve = step if due else self.last_curve
        return due

    def curve_point(self, step: int, act_batch: ActBatch, *owners: object) -> None:
        """One point of the learning curve: ``act_batch`` (the greedy policy) on the fixed
        evaluation set, logged as ``curve/<key>``. The random streams of training (torch's,
        numpy's and Python's global ones and every generator held by ``owners``) are restored
        afterwards, so a run with curve points trains exactly as one without."""
        with untouched_rng(*owners):
            r = quick_eval(act_batch, CURVE_SCENARIO, self.args.curve_episodes, seed=CURVE_SEED)
        rec: dict[str, Any] = {"step": step, "wall_s": round(self.wall(), 1)}
        rec["curve/scenario"] = r.pop("scenario")
        rec.update({f"curve/{k}": v for k, v in r.items()})
        self.write(rec)

    def wall(self) -> float:
        return self.wall_before + time.time() - self.t0

    def out_of_time(self) -> bool:
        minutes = self.args.max_wall_minutes
        return bool(minutes) and time.time() - self.t0 > 60 * minutes

    def write(self, rec: dict) -> None:
        with open(self.path, "a") as f:
            f.write(json.dumps(rec) + "\n")

    def advance(self, step: int, n: int, env: CurriculumEnv) -> None:
        """After a step of ``n`` transitions: the progress bar and one line per promotion."""
        if self.pbar is not None:
            self.pbar.update(n)
        for stage in env.take_promotions():
            self.write({"step": step, "curriculum/promoted_to": stage, "wall_s": self.wall()})

    def interval(self, step: int, env: CurriculumEnv, outcomes: list[int], **extra: Any) -> None:
        """One log line: the episodes that ended in the interval (``outcomes``) and ``extra``
        (keys with their prefix)."""
        oc = np.asarray(outcomes)
        rec: dict[str, Any] = {
            "step": step,
            "wall_s": round(self.wall(), 1),
            "curriculum/stage": env.stage or 0,
            "charts/success_rolling": env.success_rate(),
            "charts/episodes": env.episodes,
            "charts/episodes_in_interval": len(oc),
        }
        for code, name in OUTCOME_CHARTS:
            rec[f"charts/{name}"] = float(np.mean(oc == code)) if len(oc) else float("nan")
        rec.update(extra)
        self.write(rec)
        if self.pbar is not None:
            losses = [f"{k[7:]}={v:.3g}" for k, v in rec.items() if k.startswith("losses/")]
            self.pbar.set_postfix_str(
                f"stage={rec['curriculum/stage']} succ={rec['charts/success_rolling']:.2f} "
                + " ".join(losses[:2])
            )

    def finish(self, summary: dict, title: str) -> dict:
        """The ``final`` line and the learning curve; returns ``summary``."""
        if self.pbar is not None:
            self.pbar.close()
        self.write({"final": summary})
        try:
            plot_curve(self.path, os.path.join(self.args.run_dir, "curve.png"), title)
        except Exception as e:  # plotting must never lose a finished run
            print(f"curve not written: {e}")
        return summary


def quick_evaluation(act_batch: ActBatch, episodes: int) -> dict[str, Any]:
    """``eval/<density>``: :func:`quick_eval` of the ownship policy ``act_batch`` on low, medium
    and high (episode seeds 10000..)."""
    if not episodes:
        return {}
    return {
        f"eval/{sc}": quick_eval(act_batch, sc, episodes, seed=10_000)
        for sc in ("low", "medium", "high")
    }


@contextlib.contextmanager
def untouched_rng(*owners: object) -> Iterator[None]:
    """Restore, on exit, the global random states of Python, numpy and (if imported) torch, and
    the state of every ``torch.Generator`` and ``numpy.random.Generator`` that is an attribute
    of one of ``owners``."""
    torch = sys.modules.get("torch")
    saved_py, saved_np = random.getstate(), np.random.get_state()  # noqa: NPY002 - SB3 uses it
    saved_torch = torch.random.get_rng_state() if torch is not None else None
    gens = [g for o in owners for g in vars(o).values()]
    t_gen = torch.Generator if torch is not None else ()
    saved_t = [(g, g.get_state()) for g in gens if isinstance(g, t_gen)]
    saved_n = [(g, g.bit_generator.state) for g in gens if isinstance(g, np.random.Generator)]
    try:
        yield
    finally:
        random.setstate(saved_py)
        np.random.set_state(saved_np)  # noqa: NPY002
        if torch is not None:
            torch.random.set_rng_state(saved_torch)
        for g, st in saved_t:
            g.set_state(st)
        for g, st in saved_n:
            g.bit_generator.state = st


def plot_curve(log_path: str, out_png: str, title: str) -> None:
    """Learning curve from ``log.jsonl``: success (rolling and per interval), DPSC stage, losses
    (every ``losses/*`` key, absolute value, log scale)."""
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
    atomic_write_text(Path(out_png), figure_png(fig, 80))
