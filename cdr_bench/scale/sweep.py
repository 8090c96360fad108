"""``cdr-bench sweep``: many training runs plus their evaluations, as Ray tasks.

Why Ray core tasks and not Ray Tune: a trial here is an opaque, fixed piece of work (the
project's own trainer, then ``cdr-bench evaluate``, each a subprocess writing ordinary files),
and the sweep is a fixed list of them (a grid, a list, or one factor at a time). Tune's value
is in what we do not need (search algorithms, early-stopping schedulers fed by intermediate
reports, its own experiment state); its restore logic would be a second copy of the state that
the result files already hold. A core task gives exactly the two guarantees the sweep needs:
``max_retries`` re-runs a trial whose worker process or node died, and scheduling over every
node of a cluster (``--address``) or a local one started on demand (no setup).

Fault tolerance without a scheduler of our own:

- a trial works in ``<out>/.work/<key>-<random>/`` and, when training and evaluation both
  succeeded, renames that folder to ``<out>/<key>/`` (one ``rename``: atomic, and it fails if
  the folder exists, so two attempts of one trial can never both land);
- a trial folder exists only complete, with ``trial.json`` (settings, timings) and the result
  files ``result.json`` / ``result.jsonl.xz`` written by ``cdr-bench evaluate``;
- ``--resume`` skips every trial whose folder exists;
- an attempt that died (a killed sweep, a lost node, the end of a session) leaves its work
  folder with the trainer's last saved state (``state.pt``, every ``checkpoint_every``
  transitions); the next attempt of the trial takes the folder over and continues the training
  exactly (``cdr-bench train --resume``), losing at most the transitions since that state. An
  attempt holds an exclusive ``flock`` on ``<work>/.lock`` while it runs (released by the
  kernel when its process dies), so a live attempt's folder is never taken. At the end of a
  sweep the work folders with nothing to continue are removed; one that holds the saved state
  of a trial that has not landed is kept, whatever ended its attempt (a raylet killed under it,
  a failure that retries did not cure), so that the next ``--resume`` continues it.

On a cluster of several machines ``--out``, the agent file and the Python environment must be
at the same paths on every node (a shared file system), as for any Ray job without a
runtime environment.

Ray is imported here only, lazily, and only by ``cdr-bench sweep``; the rest of the package
never imports it.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import subprocess
import sys
import time
import uuid
from pathlib import Path
from typing import Any

from cdr_bench.errors import UserError
from cdr_bench.scale.config import Sweep, Trial

TRIAL_FILE = "trial.json"
RESULT_FILE = "result.json"
TRIAL_LOCK = ".lock"
"""``<out>/.work/<key>.lock``: held by the sweep process running the trial."""
ELSEWHERE = "running_elsewhere"
"""Key of what :func:`run_trial` returns for a trial another live process is running."""


def trial_done(out: Path, trial: Trial) -> bool:
    return (out / trial.key / TRIAL_FILE).is_file()


def _tail(path: Path, n: int = 12) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-n:])
    except OSError:
        return ""


def run_trial(trial: Trial, out: str) -> dict[str, Any]:
    """Train, evaluate and publish one trial (the body of the Ray task; also callable
    directly). Returns the ``trial.json`` record. Raises ``RuntimeError`` when a step fails."""

    import fcntl

    root = Path(out)
    final = root / trial.key
    if (final / TRIAL_FILE).is_file():  # an earlier attempt landed already
        return json.loads((final / TRIAL_FILE).read_text())
    # One live attempt per trial: another sweep process in the same output folder (one per
    # core) that is running this trial holds its lock; this process leaves the trial to it.
    (root / ".work").mkdir(parents=True, exist_ok=True)
    lock_path = root / ".work" / f"{trial.key}{TRIAL_LOCK}"
    owner = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(owner, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(owner)
        return {"key": trial.key, ELSEWHERE: True}
    try:
        if (final / TRIAL_FILE).is_file():  # landed while this process waited for the lock
            return json.loads((final / TRIAL_FILE).read_text())
        if _live_attempt(root, trial.key):  # e.g. a sweep process of an earlier version
            return {"key": trial.key, ELSEWHERE: True}
        work, lock, resumed = _claim_attempt(root, trial.key)
        try:
            return _run_attempt(trial, root, final, work, resumed)
        finally:
            os.close(lock)
    finally:
        with contextlib.suppress(OSError):  # still held: no other process is using the file
            lock_path.unlink()
        os.close(owner)


def _live_attempt(root: Path, key: str) -> bool:
    """Whether a live process holds the lock of one of the trial's work folders."""
    import fcntl

    for d in (root / ".work").glob(f"{key}-*"):
        if not (d / ".lock").is_file():
            continue
        fd = os.open(d / ".lock", os.O_RDWR)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            return True
        finally:
            os.close(fd)  # closing releases a lock this process took
    return False


def _claim_attempt(root: Path, key: str) -> tuple[Path, int, str]:
    """The work folder of this attempt, its lock's descriptor, and what it resumes: ``""`` (a
    new folder), ``"train"`` (a dead attempt's saved training state) or ``"evaluate"`` (a dead
    attempt that finished training)."""
    import fcntl

    for old in sorted(
        (root / ".work").glob(f"{key}-*"), key=lambda p: p.stat().st_mtime, reverse=True
    ):
        trained = (old / "train.done").is_file()
        if not (trained or (old / "state.pt").is_file()):
            continue
        fd = os.open(old / ".lock", os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:  # a live attempt holds it
            os.close(fd)
            continue
        return old, fd, "evaluate" if trained else "train"
    work = root / ".work" / f"{key}-{uuid.uuid4().hex[:8]}"
    work.mkdir(parents=True)
    fd = os.open(work / ".lock", os.O_RDWR | os.O_CREAT, 0o644)
    fcntl.flock(fd, fcntl.LOCK_EX)
    return work, fd, ""


def remove_idle_work(out: Path) -> list[Path]:
    """Remove the work folders of ``out`` that no live attempt holds and that hold nothing to
    continue (and ``.work`` once empty); return the idle ones kept because they do.
    Another sweep process may run in the same output folder (one per core, several seeds): its
    attempts hold the lock of their folder until they land, so they are left alone. An idle
    folder with a saved training state (``state.pt``) or a finished training (``train.done``)
    of a trial that has not landed is the progress ``--resume`` continues: kept. (Before this, a
    sweep whose raylet was killed under a running trial deleted an hour of its training.)"""
    import fcntl

    work = out / ".work"
    kept: list[Path] = []
    if not work.is_dir():
        return kept
    for d in sorted(work.iterdir()):
        if d.name.endswith(TRIAL_LOCK):  # a trial's lock: removed unless a live attempt holds it
            fd = os.open(d, os.O_RDWR)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                d.unlink()
            except OSError:
                pass
            finally:
                os.close(fd)
            continue
        lock = d / ".lock"
        if lock.is_file():
            fd = os.open(lock, os.O_RDWR)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:  # a live attempt of another sweep process
                continue
            finally:
                os.close(fd)
        key = d.name.rsplit("-", 1)[0]
        resumable = (d / "state.pt").is_file() or (d / "train.done").is_file()
        if resumable and not (out / key / TRIAL_FILE).is_file():
            kept.append(d)
            continue
        shutil.rmtree(d, ignore_errors=True)
    with contextlib.suppress(OSError):
        work.rmdir()
    return kept


def _run_attempt(trial: Trial, root: Path, final: Path, work: Path, resumed: str) -> dict[str, Any]:
    from cdr_bench.evaluate.results import atomic_write_text

    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    env.pop(_checkpoint_env(), None)
    t0 = time.time()
    steps: dict[str, float] = {}
    train_cmd = [sys.executable, "-m", "cdr_bench", "train", *trial.train_argv(str(work))]
    if resumed == "train":
        train_cmd.append("--resume")
    shutil.copyfile(trial.agent_file, work / "agent.py")
    ev = trial.evaluation
    eval_cmd = [sys.executable, "-m", "cdr_bench", "evaluate", str(work / "agent.py")]
    for s in ev["scenarios"]:
        eval_cmd += ["--scenario", s]
    eval_cmd += ["--episodes", str(ev["episodes"]), "--seed", str(ev["seed"])]
    if "batch_size" in ev:
        eval_cmd += ["--batch-size", str(ev["batch_size"])]
    eval_cmd += ["--out", str(work / RESULT_FILE), "--no-progress"]
    stages = [("evaluate", eval_cmd)]
    if resumed != "evaluate":
        stages.insert(0, ("train", train_cmd))
    for name, cmd in stages:
        log = work / f"{name}.log"
        ts = time.time()
        with open(log, "a" if resumed else "w") as f:
            rc = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT, env=env).returncode
        steps[f"{name}_s"] = round(time.time() - ts, 2)
        if rc != 0:
            raise RuntimeError(f"trial {trial.key}: {name} exited with {rc}:\n{_tail(log)}")
        if name == "train":  # the full training state (replay buffer): not needed afterwards
            (work / "train.done").write_text("")
            (work / "state.pt").unlink(missing_ok=True)
    # the result names the folder it will live in, not the work folder
    res_path = work / RESULT_FILE
    res = json.loads(res_path.read_text())
    res["agent"]["path"] = str(final / "agent.py")
    # compact: landed trials are committed (sweeps/landed/), hundreds of them
    atomic_write_text(res_path, json.dumps(res, separators=(",", ":")) + "\n")
    record = {
        "key": trial.key,
        "factor": trial.factor,
        "label": trial.label,
        "seed": trial.seed,
        "agent": trial.agent,
        "train_flags": trial.train_flags,
        "train_command": ["cdr-bench", "train", *trial.train_argv(str(final))],
        "evaluation": trial.evaluation,
        "result": RESULT_FILE,
        "host": os.uname().nodename,
        "ray_node": _ray_node_id(),
        "attempt": work.name,
        "resumed": resumed or None,
        "pid": os.getpid(),
        "wall_s": round(time.time() - t0, 2),
        **steps,
    }
    atomic_write_text(work / TRIAL_FILE, json.dumps(record, separators=(",", ":")) + "\n")
    try:
        os.rename(work, final)
    except OSError:  # another attempt of this trial landed first: keep that one
        shutil.rmtree(work, ignore_errors=True)
        if not (final / TRIAL_FILE).is_file():
            raise
        return json.loads((final / TRIAL_FILE).read_text())
    return record


def _ray_node_id() -> str | None:
    if "ray" not in sys.modules:  # called outside Ray: do not import it
        return None
    import ray

    return ray.get_runtime_context().get_node_id() if ray.is_initialized() else None


def _checkpoint_env() -> str:
    from cdr_bench.evaluate.loader import CHECKPOINT_ENV

    return CHECKPOINT_ENV


def run_sweep(
    sweep: Sweep,
    out: str | Path,
    *,
    address: str | None = None,
    resume: bool = False,
    num_cpus: int | None = None,
    progress: bool = True,
    command: list[str] | None = None,
) -> dict[str, Any]:
    """Run every unfinished trial of ``sweep`` on Ray; write ``<out>/sweep.json``.

    Raises :class:`UserError` when ``out`` already holds trials and ``resume`` is false, or when
    trials failed (after the finished ones were published)."""
    from cdr_bench.evaluate.results import atomic_write_text

    out = Path(out).resolve()
    done = [t for t in sweep.trials if trial_done(out, t)]
    if done and not resume:
        raise UserError(
            f"{out} already holds {len(done)} finished trial(s) of this sweep; "
            "add --resume to run only the missing ones (or choose another --out)"
        )
    todo = [t for t in sweep.trials if not trial_done(out, t)]
    out.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(sweep.source, out / "sweep.yaml")
    say = print if progress else (lambda *a, **k: None)
    say(
        f"sweep {sweep.name}: {len(sweep.trials)} trials, {len(done)} finished, "
        f"{len(todo)} to run -> {out}",
        file=sys.stderr,
    )
    failures: dict[str, str] = {}
    if todo:
        failures = _run_on_ray(todo, out, sweep, address, num_cpus, say)
    kept = remove_idle_work(out)
    summary = {
        "name": sweep.name,
        "sweep_file": str(sweep.source),
        "agent": sweep.agent,
        "command": ["cdr-bench", *sys.argv[1:]] if command is None else command,
        "trials": [
            {
                "key": t.key,
                "factor": t.factor,
                "label": t.label,
                "seed": t.seed,
                "train_flags": t.train_flags,
                "done": trial_done(out, t),
            }
            for t in sweep.trials
        ],
        "failures": failures,
        "resumable": sorted(str(d.relative_to(out)) for d in kept),
    }
    atomic_write_text(out / "sweep.json", json.dumps(summary, indent=1) + "\n")
    if failures:
        first = next(iter(failures.values()))
        raise UserError(
            f"{len(failures)} of {len(sweep.trials)} trials failed (see {out}/sweep.json); "
            f"the others are kept; first: {first.splitlines()[0]}"
            + (
                f"; the saved training state of {len(kept)} unfinished trial(s) is kept in "
                f"{out}/.work: run the sweep again with --resume to continue it"
                if kept
                else ""
            )
        )
    return summary


def _run_on_ray(
    todo: list[Trial],
    out: Path,
    sweep: Sweep,
    address: str | None,
    num_cpus: int | None,
    say: Any,
) -> dict[str, str]:
    try:
        import ray
    except ImportError:
        raise UserError('cdr-bench sweep needs Ray: pip install "cdr-bench[ray]"') from None
    import logging

    started = not ray.is_initialized()
    if started:
        ray_init(ray, address, num_cpus)
    task = ray.remote(run_trial).options(
        num_cpus=sweep.num_cpus_per_trial,
        max_retries=sweep.max_retries,
        retry_exceptions=False,
    )
    logging.getLogger("ray").setLevel(logging.ERROR)
    refs = {task.remote(t, str(out)): t for t in todo}
    failures: dict[str, str] = {}
    n = 0
    try:
        while refs:
            # a timeout, so that Ctrl-C is seen between waits
            ready, _ = ray.wait(list(refs), num_returns=1, timeout=1.0)
            if not ready:
                continue
            t = refs.pop(ready[0])
            n += 1
            try:
                rec = ray.get(ready[0])
                if rec.get(ELSEWHERE):
                    say(
                        f"[{n}/{len(todo)}] {t.key} {t.factor} {t.label} seed {t.seed}: running "
                        "in another sweep process, left to it",
                        file=sys.stderr,
                    )
                    continue
                say(
                    f"[{n}/{len(todo)}] {t.key} {t.factor} {t.label} seed {t.seed}: done "
                    f"in {rec['wall_s']} s on {rec['host']}",
                    file=sys.stderr,
                )
            except ray.exceptions.RayError as e:
                cause = getattr(e, "cause", None) or e
                failures[t.key] = f"{type(cause).__name__}: {cause}"
                say(
                    f"[{n}/{len(todo)}] {t.key}: FAILED {failures[t.key].splitlines()[0]}",
                    file=sys.stderr,
                )
    finally:
        if started:
            ray.shutdown()
    return failures


def ray_init(ray: Any, address: str | None, num_cpus: int | None) -> None:
    """Connect to ``address`` or start a local Ray (quiet: no dashboard, no log forwarding)."""
    import logging

    os.environ.setdefault("RAY_ACCEL_ENV_VAR_OVERRIDE_ON_ZERO", "0")  # silence a FutureWarning
    kw: dict[str, Any] = {
        "logging_level": logging.ERROR,
        "log_to_driver": False,
        "configure_logging": True,
    }
    if address:
        kw["address"] = address
    else:
        kw["include_dashboard"] = False
        if num_cpus is not None:
            kw["num_cpus"] = num_cpus
    try:
        ray.init(**kw)
    except (ConnectionError, RuntimeError, ValueError) as e:
        raise UserError(f"cannot start or reach Ray at {address or 'local'}: {e}") from None
