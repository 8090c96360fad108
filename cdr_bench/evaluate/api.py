"""``evaluate(...)``: score one agent on scenarios; what ``cdr-bench evaluate`` calls."""

from __future__ import annotations

import math
import os
import re
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cdr_bench.errors import UserError
from cdr_bench.evaluate import results as rf
from cdr_bench.evaluate.loader import AgentError, agent_identity, resolve_agent_path
from cdr_bench.evaluate.metrics import latency_summary, scenario_metrics, system_metrics
from cdr_bench.evaluate.remote import AgentOptions, check_timeout
from cdr_bench.evaluate.runner import (
    DEFAULT_BATCH_SIZE,
    close_all,
    load_for,
    run_batch,
    run_batch_task,
)
from cdr_bench.evaluate.seeds import episode_seeds, split_of
from cdr_bench.scenarios import ScenarioConfig, list_scenarios, load_scenario

PAPER_EPISODES = 1000
SUITES: dict[str, tuple[str, ...]] = {
    "paper": (
        "low",
        "medium",
        "high",
        "tactical/head-on",
        "tactical/crossing",
        "tactical/overtaking",
    ),
    "marl": ("marl/low-all", "marl/medium-all", "marl/high-all", "marl/crossing-stack"),
}
"""Named suites: scenario names, each run at ``PAPER_EPISODES`` episodes unless overridden.
``marl``: every aircraft controlled at the three densities, then the multi-aircraft encounter
family (the leaderboard's multi-agent track)."""

BACKENDS = ("local", "ray")
"""Where ``evaluate`` runs its episode batches: local processes or Ray tasks. Backends other
than ``local`` are registered by the layers above the evaluator (:func:`register_backend`;
``cdr_bench.scale.ray_eval`` registers ``ray``), so the evaluator never imports Ray."""

TaskRunner = Callable[[list[tuple[Any, ...]], int, "str | None"], Iterator[dict[str, Any]]]
_REGISTERED: dict[str, TaskRunner] = {}


def register_backend(name: str, run_tasks: TaskRunner) -> None:
    """Make ``backend=name`` run episode batches with ``run_tasks(tasks, workers, address)``,
    which yields each batch's result dict (:func:`cdr_bench.evaluate.runner.run_batch_task`
    of a task's arguments) as it finishes."""
    _REGISTERED[name] = run_tasks


SEED_DERIVATION = (
    "seed_i = int(sha256(f'{base_seed}/{scenario_id}/{config_hash}/{i}')[:8], big-endian) >> 1"
)


@dataclass(frozen=True)
class Job:
    config: ScenarioConfig
    episodes: int


def resolve_jobs(
    scenarios: Sequence[str], suite: str | None, episodes: int | None
) -> tuple[list[Job], list[str]]:
    """The scenarios to run (explicit ``scenarios`` first, then the suite's) and notes about
    suite members that are not installed."""
    notes: list[str] = []
    names: list[str] = list(scenarios)
    if suite is not None:
        if suite not in SUITES:
            raise UserError(f"unknown suite {suite!r} (known: {', '.join(SUITES)})")
        known = set(list_scenarios())
        for name in SUITES[suite]:
            if name in known:
                names.append(name)
            else:
                notes.append(f"suite {suite}: scenario {name} is not installed, skipped")
    if not names:
        raise UserError("no scenarios to run")
    n = PAPER_EPISODES if episodes is None else episodes
    if n < 1:
        raise UserError(f"--episodes must be >= 1, got {n}")
    jobs, seen = [], set()
    for name in names:
        cfg = load_scenario(name)
        if cfg.id in seen:
            raise UserError(f"scenario {cfg.id} given twice")
        seen.add(cfg.id)
        jobs.append(Job(cfg, n))
    return jobs, notes


def default_out(agent_path: str | os.PathLike[str], jobs: list[Job], suite: str | None) -> Path:
    """``results/<agent>/<suite or scenario>.json``."""
    from cdr_bench.evaluate.loader import agent_name

    if suite is not None and len(jobs) > 0:
        stem = suite
    else:
        stem = "+".join(j.config.id.replace("/", "_") for j in jobs)
    return Path("results") / agent_name(agent_path) / f"{stem}.json"


def evaluate(
    agent_path: str | os.PathLike[str],
    jobs: list[Job],
    out: str | os.PathLike[str],
    *,
    base_seed: int = 0,
    suite: str | None = None,
    workers: int = 1,
    resume: bool = False,
    batch_size: int = DEFAULT_BATCH_SIZE,
    agent_options: AgentOptions | None = None,
    progress: bool = True,
    backend: str = "local",
    address: str | None = None,
    agent_key: str = "",
) -> dict[str, Any]:
    """Run every job, write ``out`` (JSON) and its JSONL, and return the result dict.

    ``agent_key`` (hex, drawn by a scorer that does not trust the agent): the agent's ``reset``
    seeds are derived with it (:func:`cdr_bench.evaluate.runner.batch_seed`), so they do not
    tell the agent which public episodes it flies; it is recorded in the result
    (``agent_seed_key``) once the run is over, so that the run can be checked again.

    ``backend`` runs the episode batches in ``workers`` local processes (``"local"``) or as Ray
    tasks (``"ray"``: a local Ray with ``workers`` CPUs, or the cluster at ``address``); the
    result is the same either way, only ``timing`` differs. The agent runs in its own process
    (one per worker), confined when ``agent_options.confinement`` is set (:mod:`.remote`).

    Raises :class:`AgentError` (nothing written, checkpoint removed) when the agent cannot be
    loaded or misbehaves; an interruption leaves only the checkpoint ``<out>.partial.jsonl``.
    """
    out = Path(out)
    if out.suffix != ".json":
        raise UserError(f"--out {out}: expected a .json path")
    if workers < 1:
        raise UserError(f"--workers must be >= 1, got {workers}")
    if backend not in BACKENDS:
        raise UserError(f"--backend: expected one of {', '.join(BACKENDS)}, got {backend!r}")
    if address is not None and backend != "ray":
        raise UserError("--address needs --backend ray")
    if batch_size < 1:
        raise UserError(f"--batch-size must be >= 1, got {batch_size}")
    if agent_key and not re.fullmatch(r"[0-9a-f]{1,64}", agent_key):
        raise UserError("agent_key: expected up to 64 lowercase hexadecimal digits")
    options = agent_options or AgentOptions()
    check_timeout("--decision-timeout", options.decision_timeout_s)
    check_timeout("--load-timeout", options.load_timeout_s)
    identity = agent_identity(agent_path)
    agent_file = str(resolve_agent_path(agent_path))  # a built-in name too (mvp)
    joint = False
    for job in jobs:  # load errors now, before any work
        joint = load_for(agent_file, job.config, options).joint or joint
    if workers > 1 or backend != "local":
        close_all()  # the workers start their own agent processes

    jobs_n = [(j.config, j.episodes) for j in jobs]
    head = result_head(identity, jobs_n, base_seed, batch_size, agent_key, suite, joint)
    run_key, scen_keys = (
        head["run_key"],
        [
            {"id": j.config.id, "config_hash": j.config.config_hash(), "episodes": j.episodes}
            for j in jobs
        ],
    )
    log = rf.PartialLog(rf.partial_path(out), run_key)
    done: dict[tuple[str, int], dict[str, Any]] = {}
    if resume:
        try:
            done = log.load(_batch_check(jobs, base_seed, batch_size))
        except ValueError as e:
            raise UserError(str(e)) from None
        if not log.path.exists():
            print(f"cdr-bench: no checkpoint {log.path}, starting from scratch", file=sys.stderr)
    if not log.path.exists() or not resume:
        log.start({"run_key": run_key, "agent": identity["path"], "scenarios": scen_keys})

    tasks = []
    for j in jobs:
        for k in range(math.ceil(j.episodes / batch_size)):
            if (j.config.id, k) not in done:
                tasks.append(
                    (agent_file, j.config, base_seed, k, batch_size, j.episodes, options, agent_key)
                )
    total = sum(j.episodes for j in jobs)
    already = sum(len(b["episodes"]) for b in done.values())
    bar = _progress(total, already, identity["name"], progress)
    t0 = time.perf_counter()
    try:
        for batch in _run_tasks(tasks, workers, backend, address):
            log.append(batch)
            done[(batch["scenario"], batch["batch"])] = batch
            bar.update(len(batch["episodes"]))
    except AgentError:
        bar.close()
        log.remove()
        raise
    except BrokenProcessPool:
        bar.close()
        log.remove()
        raise AgentError(
            f"agent {identity['name']}: a worker process died (the agent process can only kill "
            "itself; this is a fault of the evaluator or of the machine: out of memory?)"
        ) from None
    except KeyboardInterrupt:
        bar.close()
        print(
            f"cdr-bench: interrupted; finished batches are kept in {log.path}, "
            "finish with the same command and --resume",
            file=sys.stderr,
        )
        raise
    finally:
        close_all()
    bar.close()
    wall = time.perf_counter() - t0

    scenarios_out, all_episodes, latency = [], [], {}
    for j in jobs:
        cid = j.config.id
        batches = sorted((b for (s, _), b in done.items() if s == cid), key=lambda b: b["batch"])
        eps = [e for b in batches for e in b["episodes"]]
        scenarios_out.append(scenario_entry(j.config, base_seed, j.episodes, eps))
        all_episodes += [{"scenario": cid, **e} for e in eps]
        latency[cid] = latency_summary(
            [x for b in batches for x in b["timing"]["per_decision_ms"]],
            [x for b in batches for x in b["timing"]["per_call_ms"]],
        )
    ran = total - already
    result = {
        **head,
        "episodes_file": rf.episodes_path(out).name,
        "scenarios": scenarios_out,
        "timing": {
            "note": "not reproducible: excluded from result identity",
            "wall_s": round(wall, 3),
            "episodes_run": ran,
            "episodes_per_s": round(ran / wall, 2) if wall > 0 and ran else None,
            "workers": workers,
            "backend": backend,
            "resumed": bool(already),
            "decision_timeout_s": options.decision_timeout_s,
            "confined": options.confinement is not None,
            "decision_latency": latency,
        },
    }
    rf.write_results(out, result, all_episodes)
    log.remove()
    return result


def result_head(
    identity: dict[str, Any],
    scenarios: list[tuple[ScenarioConfig, int]],
    base_seed: int,
    batch_size: int,
    agent_key: str = "",
    suite: str | None = None,
    joint: bool = False,
) -> dict[str, Any]:
    """The provenance fields of a result (schema, kind, agent identity, suite, episodes' base
    seed and split, batch size, seed derivation, the agent's seed key, the acting mode,
    versions), in the order a result file holds them, and its ``run_key``: the digest of what
    determines its records (the agent's identity, the scenarios' configurations and episode
    counts, the base seed, the batch size, the versions and the agent's seed key)."""
    versions = rf.package_versions()
    scen_keys = [{"id": c.id, "config_hash": c.config_hash(), "episodes": n} for c, n in scenarios]
    key = {
        "schema_version": rf.SCHEMA_VERSION,
        "agent": identity["sha256"],
        "scenarios": scen_keys,
        "base_seed": base_seed,
        "batch_size": batch_size,
        "versions": versions,
        **({"agent_seed_key": agent_key} if agent_key else {}),
    }
    return {
        "schema_version": rf.SCHEMA_VERSION,
        "kind": rf.RESULT_KIND,
        "agent": identity,
        "suite": suite,
        "base_seed": base_seed,
        "split": split_of(base_seed),
        "batch_size": batch_size,
        "seed_derivation": SEED_DERIVATION,
        **({"agent_seed_key": agent_key} if agent_key else {}),
        **({"acting": "joint"} if joint else {}),
        "versions": versions,
        "run_key": rf.sha256_text(rf.canonical(key)),
    }


def scenario_entry(
    config: ScenarioConfig, base_seed: int, n_episodes: int, records: list[dict[str, Any]]
) -> dict[str, Any]:
    """A result's entry for one scenario: its configuration and hash, the episode count and the
    digest of their seeds, and the metrics of ``records`` (every episode, in order)."""
    seeds = episode_seeds(base_seed, config.id, config.config_hash(), 0, n_episodes)
    if [e["seed"] for e in records] != seeds:  # pragma: no cover - guards the checkpoint logic
        raise RuntimeError(f"episodes of {config.id} are incomplete or out of order")
    out = {
        "id": config.id,
        "config_hash": config.config_hash(),
        "config": config.to_dict(),
        "episodes": n_episodes,
        "seeds_sha256": rf.sha256_text(",".join(map(str, seeds))),
        "metrics": scenario_metrics(records),
    }
    system = system_metrics(records)
    if system is not None:
        out["system_metrics"] = system
    return out


def record_traces(
    agent_path: str | os.PathLike[str],
    scenario: str | ScenarioConfig,
    episodes: int,
    *,
    base_seed: int = 0,
    agent_options: AgentOptions | None = None,
    batch_size: int = DEFAULT_BATCH_SIZE,
    n_episodes: int = PAPER_EPISODES,
    agent_key: str = "",
) -> list[dict[str, Any]]:
    """Trajectories of episodes ``0 .. episodes - 1`` of ``scenario`` flown by the agent
    (:func:`cdr_bench.evaluate.runner.run_batch` with ``trace``), for replays.

    The whole first batch of an evaluation with ``batch_size`` and ``n_episodes`` is run, so
    the traced episodes are exactly those of such an evaluation (the same seeds, and the same
    agent reset seed (with the same ``agent_key``) and batch, so a stochastic agent draws the
    same actions too); their
    ``outcomes`` equal the evaluation's records.
    """
    config = scenario if isinstance(scenario, ScenarioConfig) else load_scenario(scenario)
    size = min(batch_size, n_episodes)
    if not 1 <= episodes <= size:
        raise UserError(f"episodes to trace: expected 1..{size}, got {episodes}")
    agent = load_for(str(resolve_agent_path(agent_path)), config, agent_options)
    try:
        batch = run_batch(
            agent, config, base_seed, 0, batch_size, n_episodes, trace=episodes, agent_key=agent_key
        )
    finally:
        close_all()
    return list(batch["traces"])


def _batch_check(
    jobs: list[Job], base_seed: int, batch_size: int
) -> Callable[[dict[str, Any]], str | None]:
    """A validator of checkpoint lines: the batch belongs to this run, holds the episodes of
    its place on the grid, with their derived seeds."""
    configs = {j.config.id: j for j in jobs}

    def check(row: dict[str, Any]) -> str | None:
        job = configs.get(row.get("scenario"))  # type: ignore[arg-type]
        k = row.get("batch")
        if job is None or not isinstance(k, int) or not 0 <= k * batch_size < job.episodes:
            return "a batch that is not part of this run"
        start, stop = k * batch_size, min((k + 1) * batch_size, job.episodes)
        seeds = episode_seeds(base_seed, job.config.id, job.config.config_hash(), start, stop)
        eps = row.get("episodes")
        if not isinstance(eps, list) or [
            (e.get("episode"), e.get("seed")) if isinstance(e, dict) else None for e in eps
        ] != [(start + i, s) for i, s in enumerate(seeds)]:
            return f"batch {k} of {job.config.id} does not hold episodes {start}..{stop - 1}"
        timing = row.get("timing")
        if not isinstance(timing, dict) or not all(
            isinstance(timing.get(t), list) for t in ("per_decision_ms", "per_call_ms")
        ):
            return f"batch {k} of {job.config.id} has no timing"
        return None

    return check


def _run_tasks(
    tasks: list[tuple[Any, ...]], workers: int, backend: str = "local", address: str | None = None
):
    if backend != "local":
        run = _REGISTERED.get(backend)
        if run is None:
            raise UserError(
                f"--backend {backend}: not available in this process (the command line "
                "registers 'ray'; from Python, import cdr_bench.scale.ray_eval first)"
            )
        yield from run(tasks, workers, address)
        return
    if workers == 1 or len(tasks) <= 1:
        for t in tasks:
            yield run_batch_task(*t)
        return
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    from cdr_bench.evaluate.sandbox import die_with_parent

    ctx = multiprocessing.get_context("spawn")
    ex = ProcessPoolExecutor(
        max_workers=min(workers, len(tasks)),
        mp_context=ctx,
        initializer=die_with_parent,  # a worker (and its agent) dies with this process
        initargs=(os.getpid(),),
    )
    try:
        pending = {ex.submit(run_batch_task, *t) for t in tasks}
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for f in sorted(finished, key=lambda f: id(f)):
                yield f.result()
    finally:
        ex.shutdown(wait=False, cancel_futures=True)


class _NoBar:
    def update(self, n: int) -> None:
        pass

    def close(self) -> None:
        pass


def _progress(total: int, initial: int, name: str, enabled: bool) -> Any:
    if not enabled:
        return _NoBar()
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover - tqdm is a dependency of the evaluate extra
        return _NoBar()
    return tqdm(
        total=total,
        initial=initial,
        desc=f"evaluate {name}",
        unit="ep",
        file=sys.stderr,
        dynamic_ncols=True,
    )
