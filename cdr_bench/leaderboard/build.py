"""``cdr-bench leaderboard build [--evaluate [NAME ...]] [--check]``.

* ``build``: render ``README.md``, ``index.html``, ``leaderboard.json`` and ``plots/*.png`` from
  the submissions, the result files in ``results/`` and the training logs the submissions name
  (nothing is evaluated). A plot whose input (the part of the data it draws, the plotting code
  and the matplotlib version: :meth:`.plots.Plot.digest`) is what ``plots/manifest.json``
  records for the committed PNG is not drawn again: that PNG is kept, with the bytes a redraw
  gives (:func:`.plots.render_plots`); only the plots that show what changed are redrawn.
* ``build --evaluate``: first evaluate (and map the first-action distribution and record the
  replayed episodes where a submission asks) every submission (or the named ones), then
  render. Each submission is scored by a trusted child process (:mod:`.entry`: simulator,
  runner, result files; itself confined where it can be, :mod:`.scorer_box`) while its agent
  runs in another process confined by bubblewrap (:mod:`cdr_bench.evaluate.sandbox`: only the
  agent's files visible, read-only, private scratch, no network, own PID namespace, CPU and
  memory limits); the two exchange only observations and actions.
* ``build --check``: replay every committed episode from its recorded decisions (exact,
  :mod:`.verify`), ask each entry's agent again along a random sample of committed episodes
  and fly it on fresh episodes drawn now, then re-render from the committed results and
  compare with the committed pages; exit code 1 and a readable diff if anything differs.
  Writes nothing. Submissions run side by side (``--workers`` at a time, one process each:
  no timing is compared, so they may share the cores).

All-or-nothing: everything is produced in a staging folder inside the leaderboard folder (hidden
from every agent); only when every submission succeeded and every page rendered are the files
moved into place: the results folder in one rename, then the plots folder and each page (renames
only). A failing or hostile submission leaves every committed file byte-identical: its agent
could not write anywhere but its own scratch folder.

What ``--check`` compares: result files byte for byte (the per-episode JSONL) and field for
field (the JSON), except ``timing`` (wall time, latency: machine-dependent), ``versions`` and
``run_key`` (differences there are reported as notes); with ``--episodes`` below the committed
count, the first episodes of each scenario (a multiple of the batch size, so each batch is run
exactly as it was). Pages byte for byte; PNGs (and the images inside ``index.html``) only when
this machine's matplotlib is the version that rendered them, otherwise their data is still
compared through ``leaderboard.json`` and a note says so; ``--check`` draws every plot (it never
reuses a committed PNG; one this machine has drawn before is read from its plot cache,
:func:`.plots.plot_cache_dir`) and does not compare ``plots/manifest.json`` (a record of what the
plots were drawn from, not an output). Latency is never re-measured by ``--check``: the
tables' latency columns come from the committed result files (measured while each entry was
scored), the latency claim from ``latency.json`` (one controlled run of
``benchmarks/latency.py``).
"""

from __future__ import annotations

import difflib
import json
import os
import random
import re
import secrets
import shutil
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cdr_bench.errors import UserError
from cdr_bench.evaluate.analysis import DEFAULT_EPISODES, DEFAULT_SAMPLES
from cdr_bench.evaluate.loader import agent_files, check_module_names, resolve_agent_path
from cdr_bench.evaluate.results import atomic_write_text, read_result
from cdr_bench.evaluate.runner import DEFAULT_BATCH_SIZE
from cdr_bench.evaluate.sandbox import (
    Cgroup,
    Confinement,
    Limits,
    SandboxError,
    child_setup,
    clean,
    confined,
    isolation,
    remove_stale_scratch,
    tail,
)
from cdr_bench.evaluate.seeds import TEST_SEED
from cdr_bench.leaderboard.data import (
    DEFAULT_REFERENCE,
    build_data,
    current_identity,
    headroom_data,
    headroom_path,
    load_entries,
    load_latency,
    load_multimodal,
    load_replays,
    multimodal_path,
    replays_path,
    result_path,
)
from cdr_bench.leaderboard.multi_agent import track_data
from cdr_bench.leaderboard.published import load_published
from cdr_bench.leaderboard.scorer_box import scorer_box, scorer_isolation
from cdr_bench.leaderboard.submission import (
    TRACK_EPISODES,
    TRACKS,
    Submission,
    load_submissions,
)
from cdr_bench.leaderboard.verify import (
    FRESH_ALPHA,
    FRESH_EPISODES,
    MIN_AGREEMENT,
    agreement_verdict,
    batches_of,
    committed_ownship,
    fresh_verdict,
    replay_result,
)

PAPER_EPISODES = TRACK_EPISODES["single-agent"]
BASE_SEED = TEST_SEED
"""The leaderboard's test episodes (:data:`cdr_bench.evaluate.seeds.SPLITS`)."""
REPLAY_EPISODES = {"single-agent": 3, "multi-agent": 1}
"""Recorded episodes per replayed scenario (a multi-agent episode holds every aircraft's
trajectory: one is shown)."""
"""Episodes recorded per replayed scenario (the first ones of the evaluation)."""
PAGES = ("README.md", "index.html", "leaderboard.json")
_MPL_META = re.compile(r'<meta name="generator" content="[^"]*; plots: matplotlib ([^"]+)">')


def log(msg: str) -> None:
    print(f"cdr-bench leaderboard: {msg}", file=sys.stderr, flush=True)


@dataclass
class Options:
    leaderboard_dir: Path
    evaluate: list[str] | None = None
    """None: render only; []: every submission; names: those."""
    check: bool = False
    episodes: int | None = None
    workers: int = 2
    limits: Limits = field(default_factory=Limits)
    reference: str = DEFAULT_REFERENCE
    all_seeds: bool = False
    """``--check``: ask the agent of every training seed of every entry again, not one run per
    entry drawn at random."""
    sample_seed: int | None = None
    """``--check``: the seed of the agent re-run sample (None: drawn at random, and printed)."""
    rerun_batches: int = 1
    """``--check``: batches of committed episodes per run on which the agent is asked again
    (the first drawn among the headline scenario's batches, the others among all)."""
    fresh_episodes: int = FRESH_EPISODES
    """``--check``: fresh headline episodes per entry (0: no fresh-episode test)."""


def json_page(data: dict[str, Any]) -> str:
    """``leaderboard.json``: each top-level key on a line, a list one item per line (an entry,
    a table, a claim), each item compact JSON: half the bytes of an indented file, and a
    change still shows as the lines of the items it touched."""

    def one(v: Any) -> str:
        return json.dumps(v, separators=(",", ":"), ensure_ascii=False)

    lines = []
    for k, v in data.items():
        if isinstance(v, list) and v:
            items = ",\n  ".join(one(x) for x in v)
            lines.append(f" {one(k)}:[\n  {items}\n ]")
        else:
            lines.append(f" {one(k)}:{one(v)}")
    return "{\n" + ",\n".join(lines) + "\n}\n"


# ----------------------------------------------------------------------------------------------
# Rendering


def render_all(
    lb_dir: Path,
    results_dir: Path,
    reference: str,
    reuse_plots: bool = False,
    drawn: list[str] | None = None,
) -> dict[str, bytes]:
    """Every generated file (relative path -> bytes) from submissions and result files, with
    ``plots/manifest.json``. ``reuse_plots``: keep each committed PNG of ``lb_dir/plots`` whose
    input is unchanged (:func:`.plots.render_plots`; the same bytes as drawing it);
    ``drawn``: appended the names of the plots drawn."""
    from cdr_bench.leaderboard.plots import (
        MANIFEST,
        matplotlib_version,
        plots_manifest,
        render_plots,
    )
    from cdr_bench.leaderboard.render import render_html, render_markdown
    from cdr_bench.leaderboard.sensitivity import load_study

    published = load_published(lb_dir)
    subs = load_submissions(lb_dir, published.names)
    entries = load_entries(subs, results_dir)
    single = [e for e in entries if e.sub.track == "single-agent"]
    data = build_data(single, published, reference, load_study(lb_dir), load_latency(lb_dir))
    data["headroom"] = headroom_data(headroom_path(lb_dir), single, data["ranking"])
    multi = [e for e in entries if e.sub.track == "multi-agent"]
    data["multi_agent"] = track_data(multi)
    if data["multi_agent"] is not None:  # their replays beside the single-agent ones
        rp = data["replays"]
        order = [r["entry"] for r in data["multi_agent"]["ranking"]]
        for e in sorted((e for e in multi if e.replays), key=lambda e: order.index(e.name)):
            rp["entries"].append(e.name)
            rp["files"][e.name] = f"results/{e.name}.replays.json"
            rp["scenarios"] += [s for s in e.sub.replays if s not in rp["scenarios"]]
    if reuse_plots:
        plots = render_plots(data, reuse=lb_dir / "plots", drawn=drawn)
    else:
        plots = render_plots(data)
    files: dict[str, bytes] = {
        "README.md": render_markdown(data, published, list(plots)).encode(),
        "index.html": render_html(
            data,
            published,
            plots,
            matplotlib_version(),
            {e.name: e.replays for e in entries if e.replays is not None},
        ).encode(),
        "leaderboard.json": json_page(data).encode(),
    }
    files.update({f"plots/{k}": v for k, v in plots.items()})
    files[f"plots/{MANIFEST}"] = plots_manifest(data, plots)
    return files


# ----------------------------------------------------------------------------------------------
# Evaluation of one submission (sandboxed)


def run_child(
    argv: list[str],
    *,
    what: str,
    cwd: Path,
    log_dir: Path,
    wall_s: float,
    env: dict[str, str] | None = None,
    limits: Limits | None = None,
    pass_fds: tuple[int, ...] = (),
    cgroup: Cgroup | None = None,
) -> float:
    """Run ``argv`` in its own session with a wall-clock limit (then its whole process group is
    killed), in ``cgroup`` when given; returns the wall time. The child
    gets ``SIGKILL`` when this process dies (:func:`~cdr_bench.evaluate.sandbox.child_setup`),
    ``kill -9`` included, and passes that on to what it starts. :class:`SandboxError` naming
    ``what`` when it fails, with its last output (control characters removed)."""
    import signal
    import subprocess

    log_dir.mkdir(parents=True, exist_ok=True)
    out_log, err_log = log_dir / "stdout.log", log_dir / "stderr.log"
    t0 = time.perf_counter()
    with open(out_log, "wb") as out, open(err_log, "wb") as err:
        proc = subprocess.Popen(
            argv,
            cwd=cwd,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=err,
            start_new_session=True,
            pass_fds=pass_fds,
            preexec_fn=child_setup(limits, cgroup=cgroup),
        )
        try:
            code = proc.wait(timeout=wall_s)
        except subprocess.TimeoutExpired:
            code = None
        finally:
            try:
                os.killpg(proc.pid, signal.SIGKILL)  # whatever it left behind
            except (ProcessLookupError, PermissionError):
                pass
            proc.wait()
    wall = time.perf_counter() - t0
    text = clean(tail(err_log)) or clean(tail(out_log))
    last = "\n  last output:\n    " + text.replace("\n", "\n    ") if text else ""
    if code is None:
        raise SandboxError(
            f"{what}: did not finish within the wall-clock limit of {wall_s:g} s (killed){last}"
        )
    if code == 0:
        return wall
    errors = [r for r in clean(tail(err_log), 400, 2000).splitlines() if r.startswith(_ERROR)]
    if code == 2 and errors:  # the scorer's own one-line error (e.g. what the agent did)
        raise SandboxError(f"{what}: {errors[-1].removeprefix(_ERROR)}")
    why = f"exit code {code}" if code > 0 else f"killed by {signal.Signals(-code).name}"
    raise SandboxError(f"{what}: failed ({why}){last}")


_ERROR = "cdr-bench: error: "


def _inside(root: Path, rel: str, what: str, field_name: str) -> Path:
    """``root/rel`` with symlinks resolved, refused unless it stays inside ``root``."""
    full = (root / rel).resolve()
    if not full.is_relative_to(root.resolve()):
        raise SandboxError(f"{what}: {field_name} {rel} resolves to {full}, outside {root}")
    return full


def evaluate_submission(
    sub: Submission,
    root: Path,
    out_dir: Path,
    scratch: Path,
    episodes: int,
    workers: int,
    limits: Limits,
    rerun: dict[str, Any] | None = None,
) -> float:
    """Write ``out_dir/<name>.json`` and its per-episode log (and multimodality files) for one
    submission; returns the wall time. With ``rerun`` (``{"result", "batches", "out"}``)
    nothing is scored: the agent is asked again along the committed episodes of those batches
    (:mod:`.verify`) and the agreement written to ``rerun["out"]``. :class:`SandboxError` /
    :class:`UserError` name the submission."""
    what = f"submission {sub.name} ({sub.source})"
    lb_dir = sub.source.resolve().parent.parent
    agent = _inside(root, sub.agent, what, "agent")
    if agent.is_relative_to(lb_dir):
        raise SandboxError(f"{what}: agent {sub.agent} lies inside the leaderboard folder")
    if resolve_agent_path(agent).parent == root.resolve():
        raise SandboxError(
            f"{what}: agent {sub.agent} lies at the repository root; put it in a folder of its "
            "own (agents/<name>/agent.py)"
        )
    files = agent_files(agent, root / sub.checkpoint if sub.checkpoint else None)
    for f in files:
        _inside(root, str(f), what, "agent file")
    check_module_names(agent, files, what)
    env = dict(os.environ)
    env.pop("CDR_BENCH_CHECKPOINT", None)
    py = sys.executable
    wall = 0.0
    if sub.checkpoint:
        _inside(root, sub.checkpoint, what, "checkpoint")
        env["CDR_BENCH_CHECKPOINT"] = sub.checkpoint
        ck_file = str((root / sub.checkpoint).resolve())
        conf = Confinement(view=str(root), files=(ck_file,), limits=limits)
        box = scratch / "safeload"
        box.mkdir(parents=True, exist_ok=True)
        safe = confined(
            [py, "-I", "-m", "cdr_bench.leaderboard.safeload", sub.checkpoint], conf, box
        )
        try:
            wall += run_child(
                safe.argv,
                what=f"{what}: checkpoint {sub.checkpoint}",
                cwd=root,
                log_dir=scratch / "safeload-log",
                wall_s=limits.wall_s,
                env=safe.env,
                limits=limits,
                pass_fds=safe.pass_fds,
            )
        finally:
            safe.close()
    # Confined (where it can be, :mod:`.scorer_box`), the scorer writes only into a scratch
    # folder of its own; what it wrote is moved to where the build expects it afterwards.
    sbox = scorer_box(env, root)
    work = sbox.scratch if sbox is not None else scratch
    out = result_path(out_dir, sub.name)
    out_w = result_path(work / "out", sub.name) if sbox is not None else out
    mm = [
        {
            "scenario": sc,
            "out": str((work / f"multimodal-{sc.replace('/', '_')}.json").resolve()),
        }
        for sc in sub.multimodality
    ]
    replays = (work / "replays.json").resolve()
    rerun_w = rerun
    if rerun is not None and sbox is not None:
        rerun_w = {**rerun, "out": str(work / "agreement.json")}
    spec = {
        "agent": sub.agent,
        "scenarios": [] if sub.suite else list(sub.scenarios),
        "suite": sub.suite,
        "episodes": episodes,
        "seed": BASE_SEED,
        "batch_size": DEFAULT_BATCH_SIZE,
        "workers": workers,
        "out": str(out_w.resolve()),
        "root": str(root.resolve()),
        "hidden": [str(lb_dir)],
        "limits": {"cpu_s": limits.cpu_s, "memory_mb": limits.memory_mb, "wall_s": limits.wall_s},
        "multimodality": mm,
        "multimodal": {"episodes": DEFAULT_EPISODES, "samples": DEFAULT_SAMPLES},
        "replays": {
            "scenarios": list(sub.replays),
            "episodes": REPLAY_EPISODES[sub.track],
            "out": str(replays),
        },
        "rerun": rerun_w,
        # the agent's reset seeds are derived with a secret drawn now (recorded in the result
        # when the run is over): they do not tell the agent which public episodes it flies
        "agent_key": secrets.token_hex(16) if rerun is None else "",
    }
    try:
        spec_file = work / "spec.json"
        spec_file.parent.mkdir(parents=True, exist_ok=True)
        spec_file.write_text(json.dumps(spec, indent=1), encoding="utf-8")
        # -I: isolated mode, nothing of the working directory (the repository root: relative
        # paths in the spec and in the result are relative to it) or of PYTHON* variables on
        # the path
        argv = [py, "-I", "-m", "cdr_bench.leaderboard.entry", str(spec_file.resolve())]
        wall += run_child(
            argv if sbox is None else [*sbox.prefix, *argv],
            what=what,
            cwd=root,
            log_dir=scratch / "entry-log",
            wall_s=limits.wall_s,
            env=env if sbox is None else sbox.env,
            cgroup=None if sbox is None else sbox.cgroup,
        )
        if sbox is not None:
            out_dir.mkdir(parents=True, exist_ok=True)
            for f in (out_w, out_w.with_suffix(".jsonl.xz")):
                if f.exists():
                    shutil.copyfile(f, out.with_name(f.name))
            if rerun is not None and rerun_w is not None and Path(rerun_w["out"]).exists():
                Path(rerun["out"]).parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(rerun_w["out"], rerun["out"])
        if rerun is None:
            try:
                result = read_result(out, metrics=False)
            except ValueError as e:
                raise SandboxError(f"{what}: the evaluation wrote no usable result ({e})") from None
            expected = current_identity(sub, root)["sha256"]
            if result["agent"]["sha256"] != expected:
                raise SandboxError(
                    f"{what}: the result names agent {result['agent']['sha256'][:12]}, the "
                    f"submission's files hash to {expected[:12]} (files changed during the run?)"
                )
        for m in mm:
            load_multimodal(Path(m["out"]))  # refuses garbage
            shutil.copyfile(m["out"], multimodal_path(out_dir, sub.name, m["scenario"]))
        if sub.replays:
            load_replays(replays, sub)  # refuses garbage
            shutil.copyfile(replays, replays_path(out_dir, sub.name))
    finally:
        if sbox is not None:
            sbox.close()
    return wall


def committed_episodes(results_dir: Path, subs: list[Submission]) -> dict[str, int]:
    """The episode count per scenario of the committed results of each track (one number for
    all the entries of a track; the track's full count where none is committed)."""
    return {t: _committed(results_dir, [s for s in subs if s.track == t], t) for t in TRACKS}


def _committed(results_dir: Path, subs: list[Submission], track: str) -> int:
    counts = set()
    for s in subs:
        p = result_path(results_dir, s.name)
        if p.exists():
            try:
                counts |= {sc["episodes"] for sc in read_result(p, metrics=False)["scenarios"]}
            except ValueError:
                continue
    if len(counts) > 1:
        raise UserError(
            f"{results_dir}: {track} results with different episode counts {sorted(counts)}"
        )
    return counts.pop() if counts else TRACK_EPISODES[track]


def untracked_agent_files(sub: Submission, root: Path) -> list[str]:
    """Files in the agent's identity that git does not track (a clean clone lacks them, so
    its ``--check`` would see other agent files); empty outside a git work tree."""
    import subprocess

    ck = root / sub.checkpoint if sub.checkpoint else None
    files = [p.resolve() for p in agent_files(root / sub.agent, ck)]
    if sub.checkpoint:
        files.append((root / sub.checkpoint).resolve())
    try:
        r = subprocess.run(
            ["git", "ls-files", "--others", "--exclude-standard", "-z", "--", sub.agent],
            cwd=root,
            capture_output=True,
            text=True,
            timeout=60,
        )
    except (OSError, subprocess.TimeoutExpired):
        return []
    if r.returncode != 0:
        return []
    untracked = {(root / p).resolve() for p in r.stdout.split("\0") if p}
    return sorted({str(f.relative_to(root.resolve())) for f in files if f in untracked})


def _evaluate_all(
    subs: list[Submission],
    opts: Options,
    root: Path,
    out_dir: Path,
    scratch: Path,
    n: dict[str, int],
    side_by_side: bool = False,
    reruns: dict[str, dict[str, Any]] | None = None,
) -> None:
    """Evaluate ``subs`` one after the other, each with ``opts.workers`` processes; or, with
    ``side_by_side`` (``--check``), ``opts.workers`` submissions at a time with one process
    each. Results do not depend on how batches are spread over processes; side by side keeps
    every core busy through each submission's serial parts (start-up, safe load,
    multimodality runs) but lets the submissions share the cores, so it is used only where no
    timing is kept (``--check`` compares no latency)."""
    for sub in subs:
        loose = untracked_agent_files(sub, root)
        if loose:
            log(
                f"warning: {sub.name}: files not tracked by git are part of the agent's identity "
                f"({', '.join(loose)}); commit them, or `--check` on a clean clone will fail"
            )
    _, iso = isolation()
    parallel = max(1, opts.workers) if side_by_side else 1
    per_sub = 1 if side_by_side else opts.workers
    how = (
        f"{parallel} submission(s) at a time, 1 worker each"
        if side_by_side
        else f"{opts.workers} worker(s)"
    )
    what = "re-running" if reruns is not None else "evaluating"
    per = (
        "sampled batches"
        if reruns is not None
        else " and ".join(
            f"{n[t]} episodes per scenario ({t})" for t in TRACKS if any(s.track == t for s in subs)
        )
    )
    log(
        f"{what} {len(subs)} submission(s), {per}, {how}; limits: "
        f"{opts.limits.cpu_s} CPU s and {opts.limits.memory_mb} MiB per agent process, "
        f"{opts.limits.wall_s:g} s wall per submission; agents {iso}; "
        f"{scorer_isolation(str(root.resolve()))[1]}"
    )
    t0 = time.perf_counter()

    def one(sub: Submission) -> None:
        rr = None if reruns is None else reruns[sub.name]
        wall = evaluate_submission(
            sub, root, out_dir, scratch / sub.name, n[sub.track], per_sub, opts.limits, rerun=rr
        )
        if rr is None:
            eps = n[sub.track] * len(sub.scenarios)
            log(f"  {sub.name}: {eps} episodes in {wall:.1f} s ({eps / max(wall, 1e-9):.0f} ep/s)")
        else:
            log(f"  {sub.name}: agent re-run in {wall:.1f} s")

    if parallel == 1:
        for sub in subs:
            one(sub)
    else:
        from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait

        with ThreadPoolExecutor(parallel) as pool:
            futures = [pool.submit(one, sub) for sub in subs]
            _, pending = wait(futures, return_when=FIRST_EXCEPTION)
            for f in pending:
                f.cancel()  # a failure stops the queue (running ones finish)
            for f in futures:
                exc = f.exception() if f.done() and not f.cancelled() else None
                if exc is not None:
                    raise exc
    log(f"evaluation finished in {time.perf_counter() - t0:.1f} s")


# ----------------------------------------------------------------------------------------------
# Staging and commit


@contextmanager
def staging(lb_dir: Path) -> Iterator[Path]:
    """A fresh staging folder ``.build-<pid>-*`` in ``lb_dir``, removed afterwards; those a
    build killed with ``kill -9`` left (their process is gone) are removed first."""
    lb_dir.mkdir(parents=True, exist_ok=True)
    remove_stale_scratch(lb_dir, ".build-")
    d = Path(tempfile.mkdtemp(prefix=f".build-{os.getpid()}-", dir=lb_dir))
    try:
        yield d
    finally:
        shutil.rmtree(d, ignore_errors=True)


def _swap_dir(new: Path, target: Path) -> None:
    """Replace folder ``target`` by ``new`` with renames only."""
    old = target.with_name(f".{target.name}.old")
    shutil.rmtree(old, ignore_errors=True)
    if target.exists():
        os.replace(target, old)
    os.replace(new, target)
    shutil.rmtree(old, ignore_errors=True)


def commit(lb_dir: Path, stage: Path, files: dict[str, bytes], new_results: Path | None) -> None:
    """Move everything produced in ``stage`` into ``lb_dir`` (renames only)."""
    plots = stage / "plots-new"
    plots.mkdir()
    for rel, data in files.items():
        if rel.startswith("plots/"):
            (plots / rel.removeprefix("plots/")).write_bytes(data)
    if new_results is not None:
        _swap_dir(new_results, lb_dir / "results")
    _swap_dir(plots, lb_dir / "plots")
    for rel in PAGES:
        atomic_write_text(lb_dir / rel, files[rel].decode())


def _copy_results(src: Path, dst: Path, subs: list[Submission]) -> None:
    dst.mkdir(parents=True, exist_ok=True)
    for s in subs:
        for p in sorted(src.glob(f"{s.name}.*")):
            if p.name.startswith(f"{s.name}.") and not p.name.endswith(".partial.jsonl"):
                shutil.copy2(p, dst / p.name)


# ----------------------------------------------------------------------------------------------
# Comparison (--check)


def _diff_text(name: str, old: str, new: str, limit: int = 40) -> str:
    lines = list(
        difflib.unified_diff(
            old.splitlines(), new.splitlines(), f"committed/{name}", f"now/{name}", lineterm="", n=1
        )
    )
    if len(lines) > limit:
        lines = lines[:limit] + [f"... ({len(lines) - limit} more diff lines)"]
    return "\n".join(lines)


def _short(line: str | None, width: int = 300) -> str:
    if line is None:
        return "(missing)"
    return line if len(line) <= width else line[:width] + " ..."


def compare_pages(lb_dir: Path, files: dict[str, bytes], notes: list[str]) -> list[str]:
    diffs = []
    html_path = lb_dir / "index.html"
    committed_mpl = None
    if html_path.exists():
        m = _MPL_META.search(html_path.read_text(encoding="utf-8", errors="replace"))
        committed_mpl = m.group(1) if m else None
    now = _MPL_META.search(files["index.html"].decode())
    now_mpl = now.group(1) if now else None
    same_mpl = committed_mpl == now_mpl
    if not same_mpl:
        notes.append(
            f"plots rendered with matplotlib {committed_mpl}, this machine has {now_mpl}: PNG "
            "bytes not compared (their data is, in leaderboard.json)"
        )
    expected = {rel for rel in files if rel in PAGES or rel.endswith(".png")}
    present = {"plots/" + p.name for p in (lb_dir / "plots").glob("*.png")} | {
        p for p in PAGES if (lb_dir / p).exists()
    }
    for rel in sorted(expected - present):
        diffs.append(f"{rel}: missing from the committed leaderboard")
    for rel in sorted(present - expected):
        diffs.append(f"{rel}: committed but no longer produced")
    for rel in sorted(expected & present):
        old = (lb_dir / rel).read_bytes()
        new = files[rel]
        if old == new:
            continue
        if rel.endswith(".png"):
            if same_mpl:
                diffs.append(f"{rel}: image differs ({len(old)} bytes committed, {len(new)} now)")
            continue
        old_t, new_t = old.decode("utf-8", errors="replace"), new.decode()
        if rel == "index.html":
            old_s, new_s = _MPL_META.sub("", old_t), _MPL_META.sub("", new_t)
            if old_s == new_s:  # only the matplotlib version it names differs
                continue
            old_t, new_t = old_s, new_s
        diffs.append(_diff_text(rel, old_t, new_t))
    return diffs


# ----------------------------------------------------------------------------------------------
# Entry point


def run(opts: Options) -> int:
    lb_dir = opts.leaderboard_dir
    root = lb_dir.resolve().parent
    results_dir = lb_dir / "results"
    published = load_published(lb_dir)
    subs = load_submissions(lb_dir, published.names)
    names = {s.name for s in subs}
    if opts.reference not in names:
        raise UserError(f"reference entry {opts.reference!r} has no submission in {lb_dir}")
    chosen = subs
    if opts.evaluate:
        unknown = sorted(set(opts.evaluate) - names)
        if unknown:
            raise UserError(f"--evaluate: no submission named {', '.join(unknown)}")
        chosen = [s for s in subs if s.name in opts.evaluate]
    if opts.episodes is not None and opts.episodes < 1:
        raise UserError(f"--episodes must be >= 1, got {opts.episodes}")

    if opts.check:
        return _check(opts, lb_dir, root, results_dir, subs, chosen)
    chosen = with_seeds(chosen)

    t0 = time.perf_counter()
    with staging(lb_dir) as stage:
        new_results = None
        source = results_dir
        if opts.evaluate is not None:
            n = (
                dict.fromkeys(TRACKS, opts.episodes)
                if opts.episodes
                else (
                    dict(TRACK_EPISODES)
                    if opts.evaluate == []
                    else committed_episodes(results_dir, subs)
                )
            )
            new_results = stage / "results"
            _copy_results(results_dir, new_results, [s for s in subs if s not in chosen])
            _evaluate_all(chosen, opts, root, new_results, stage / "scratch", n)
            source = new_results
        elif opts.episodes is not None:
            raise UserError("--episodes needs --evaluate or --check (plain build only renders)")
        drawn: list[str] = []
        files = render_all(lb_dir, source, opts.reference, reuse_plots=True, drawn=drawn)
        commit(lb_dir, stage, files, new_results)
    n_plots = sum(k.startswith("plots/") and k.endswith(".png") for k in files)
    log(
        f"wrote {lb_dir}/README.md, index.html, leaderboard.json and {n_plots} plots "
        f"({len(drawn)} drawn, {n_plots - len(drawn)} unchanged) in "
        f"{time.perf_counter() - t0:.1f} s"
    )
    return 0


def with_seeds(subs: list[Submission]) -> list[Submission]:
    """Each submission followed by its other seeds (:meth:`Submission.seed_views`)."""
    return [v for s in subs for v in (s, *s.seed_views())]


def sampled_seeds(subs: list[Submission], rng: random.Random) -> list[Submission]:
    """One run of each submission drawn with ``rng`` among its training seeds (the shown one
    included): the runs whose agent ``--check`` asks again (``--all-seeds``: every run). Every
    run is replayed whatever is drawn; over checks, every seed's agent is asked in turn."""
    out = []
    for s in subs:
        runs = [s, *s.seed_views()]
        out.append(runs[rng.randrange(len(runs))])
    return out


def rerun_sample(
    grid: list[tuple[str, int]], k: int, rng: random.Random, headline: str = "high"
) -> list[Any]:
    """``k`` batches of ``grid`` (``(scenario, batch)``) drawn at random: the first among the
    ``headline`` scenario's batches (what ranks an entry in its track) where it has any, the
    rest among all."""
    head = [g for g in grid if g[0] == headline] or grid
    first = rng.choice(head)
    rest = [g for g in grid if g != first]
    return sorted([first, *rng.sample(rest, min(k - 1, len(rest)))])


def replay_all(
    views: list[Submission],
    results_dir: Path,
    first: dict[str, int | None],
    workers: int,
) -> tuple[int, list[str]]:
    """Replay every committed episode of these runs (:func:`.verify.replay_result`, the first
    ``first[track]`` of each scenario when given), ``workers`` result files at a time. Returns
    the number of episodes replayed and the differences (readable; empty: all identical)."""
    from concurrent.futures import ProcessPoolExecutor

    from cdr_bench.leaderboard.verify import replay_result

    paths = [result_path(results_dir, v.name) for v in views]
    missing = [
        f"results/{p.name}: missing from the committed leaderboard" for p in paths if not p.exists()
    ]
    firsts = [first[v.track] for v, p in zip(views, paths, strict=True) if p.exists()]
    paths = [p for p in paths if p.exists()]
    total, diffs = 0, list(missing)
    if workers <= 1 or len(paths) <= 1:
        outcomes = [replay_result(p, f) for p, f in zip(paths, firsts, strict=True)]
    else:
        import multiprocessing

        ctx = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(min(workers, len(paths)), mp_context=ctx) as ex:
            outcomes = list(ex.map(replay_result, paths, firsts))
    for p, (n, d) in zip(paths, outcomes, strict=True):
        total += n
        if d:
            diffs.append(
                f"results/{p.name}: the per-episode log is not what its recorded decisions give "
                "(edited, or the simulator changed since the evaluation):\n  " + "\n  ".join(d)
            )
    return total, diffs


def identity_diffs(views: list[Submission], root: Path, results_dir: Path) -> list[str]:
    """Runs whose agent files (code, named checkpoint, declared files) changed since their
    committed result was scored."""
    diffs = []
    for v in views:
        p = result_path(results_dir, v.name)
        try:
            old = read_result(p, metrics=False)["agent"]
        except ValueError:
            continue  # reported by the replay
        new = current_identity(v, root)
        if old.get("sha256") == new["sha256"]:
            continue
        fa, fb = old.get("files", {}), new["files"]
        parts = [
            f"{label}: {', '.join(names)}"
            for label, names in (
                ("missing here", sorted(set(fa) - set(fb))),
                ("new", sorted(set(fb) - set(fa))),
                ("changed", sorted(k for k in set(fa) & set(fb) if fa[k] != fb[k])),
            )
            if names
        ]
        what = "; ".join(parts) or "the checkpoint"
        diffs.append(
            f"results/{p.name}: the agent's files changed since it was evaluated ({what}); "
            f"re-run `cdr-bench leaderboard build --evaluate {v.name}`"
        )
    return diffs


def _check(
    opts: Options,
    lb_dir: Path,
    root: Path,
    results_dir: Path,
    subs: list[Submission],
    chosen: list[Submission],
) -> int:
    t0 = time.perf_counter()
    committed_n = committed_episodes(results_dir, subs)
    tracks = [t for t in TRACKS if any(s.track == t for s in subs)]
    most = max(committed_n[t] for t in tracks)
    if opts.episodes is not None and opts.episodes > most:
        raise UserError(f"--episodes {opts.episodes}: the committed results have only {most}")
    # a partial check (--episodes) takes the first episodes of every track that has more
    n = {t: min(opts.episodes or committed_n[t], committed_n[t]) for t in TRACKS}
    partial = {t for t in tracks if n[t] != committed_n[t]}
    if partial and opts.episodes and opts.episodes % DEFAULT_BATCH_SIZE:
        raise UserError(
            f"--episodes {opts.episodes}: a partial check runs whole batches; use a multiple of "
            f"{DEFAULT_BATCH_SIZE} (or {most}, the committed count)"
        )
    diffs: list[str] = []
    notes: list[str] = []
    views = with_seeds(chosen)
    diffs += identity_diffs(views, root, results_dir)
    replayed, replay_diffs = replay_all(
        views, results_dir, {t: n[t] if t in partial else None for t in TRACKS}, opts.workers
    )
    diffs += replay_diffs
    hr_path = headroom_path(lb_dir)
    if hr_path.exists():
        n_hr, hr_diffs = replay_result(hr_path)
        replayed += n_hr
        if hr_diffs:
            diffs.append(
                f"{hr_path.relative_to(lb_dir)}: the planner's log is not what its recorded "
                "decisions give:\n  " + "\n  ".join(hr_diffs)
            )
    log(
        f"replayed {replayed} committed episodes of {len(views)} run(s) "
        f"({time.perf_counter() - t0:.1f} s): "
        + ("identical" if not replay_diffs else f"{len(replay_diffs)} file(s) differ")
    )
    sample_seed = opts.sample_seed if opts.sample_seed is not None else secrets.randbits(32)
    rng = random.Random(sample_seed)
    reruns: dict[str, dict[str, Any]] = {}
    chosen = views if opts.all_seeds else sampled_seeds(chosen, rng)
    with staging(lb_dir) as stage:
        fresh = stage / "results"
        fresh.mkdir()
        scratch = stage / "scratch"
        for sub in chosen:
            committed = result_path(results_dir, sub.name)
            try:
                result = read_result(committed, metrics=False)
            except ValueError:
                continue
            grid = list(batches_of(result))
            if sub.track in partial:
                grid = [(sc, k) for sc, k in grid if k * DEFAULT_BATCH_SIZE < n[sub.track]]
            headline = sub.headline_scenario
            reruns[sub.name] = {
                "result": str(committed.resolve()),
                "batches": rerun_sample(grid, opts.rerun_batches, rng, headline),
                "out": str((scratch / sub.name / "agreement.json").resolve()),
                "fresh": None,
            }
            if opts.fresh_episodes and any(s[0] == headline for s in grid):
                reruns[sub.name]["fresh"] = {
                    "scenario": headline,
                    "episodes": opts.fresh_episodes,
                    # unpredictable, and printed so that a failure can be looked into
                    "base_seed": secrets.randbits(62),
                    "agent_key": secrets.token_hex(16),
                }
        chosen = [s for s in chosen if s.name in reruns]
        log(
            f"agent re-run sample drawn with --sample-seed {sample_seed}: "
            f"{opts.rerun_batches} batch(es) of {DEFAULT_BATCH_SIZE} episodes per run, "
            f"tolerance {100 * MIN_AGREEMENT:g} % identical decisions; "
            + (
                f"{opts.fresh_episodes} fresh episodes of each track's headline scenario per "
                "entry from seeds "
                f"drawn now, Fisher exact test at p < {FRESH_ALPHA:g}"
                if opts.fresh_episodes
                else "no fresh-episode test (--fresh-episodes 0)"
            )
        )
        _evaluate_all(chosen, opts, root, fresh, scratch, n, side_by_side=True, reruns=reruns)
        for sub in chosen:
            got = json.loads(Path(reruns[sub.name]["out"]).read_text(encoding="utf-8"))
            text, ok = agreement_verdict(sub.name, got["batches"])
            log(text)
            bad = [d for b in got["batches"] for d in b["differences"]]
            if bad:
                diffs.append(
                    f"results/{sub.name}.json: re-run batches not reproduced:\n  "
                    + "\n  ".join(bad)
                )
            if not ok:
                diffs.append(f"results/{sub.name}.json: {text}")
            if got.get("fresh") is not None:
                own = committed_ownship(result_path(results_dir, sub.name), sub.headline_scenario)
                text, ok = fresh_verdict(sub.name, own, got["fresh"])
                log(text)
                if not ok:
                    diffs.append(f"results/{sub.name}.json: {text}")
            for sc in sub.multimodality:
                a_p, b_p = (
                    multimodal_path(results_dir, sub.name, sc),
                    multimodal_path(fresh, sub.name, sc),
                )
                a = load_multimodal(a_p) if a_p.exists() else None
                b = load_multimodal(b_p)
                if a != b:
                    diffs.append(
                        _diff_text(
                            f"results/{a_p.name}",
                            json.dumps(a, indent=1, sort_keys=True),
                            json.dumps(b, indent=1, sort_keys=True),
                        )
                    )
            if sub.replays:
                a_p, b_p = replays_path(results_dir, sub.name), replays_path(fresh, sub.name)
                if not a_p.exists():
                    diffs.append(f"results/{a_p.name}: missing from the committed leaderboard")
                elif a_p.read_bytes() != b_p.read_bytes():
                    diffs.append(
                        _diff_text(
                            f"results/{a_p.name}",
                            json.dumps(load_replays(a_p, sub), indent=1, sort_keys=True),
                            json.dumps(load_replays(b_p, sub), indent=1, sort_keys=True),
                        )
                    )
        try:
            files = render_all(lb_dir, results_dir, opts.reference)
        except UserError as e:
            diffs.append(f"the committed result files do not render: {e}")
            files = None
        if files is not None:
            diffs += compare_pages(lb_dir, files, notes)
    for note in notes:
        log(f"note: {note}")
    scope = "".join(
        f" (first {n[t]} of {committed_n[t]} episodes per {t} scenario)" for t in sorted(partial)
    )
    if diffs:
        print(
            f"leaderboard check FAILED{scope}: the committed leaderboard differs from what the "
            "code produces now (regenerate with `cdr-bench leaderboard build --evaluate`):\n",
            file=sys.stderr,
        )
        print("\n\n".join(diffs), file=sys.stderr)
        return 1
    log(
        f"check passed{scope}: {replayed} episodes replayed, {len(chosen)} agent(s) re-run, "
        "pages identical "
        f"({time.perf_counter() - t0:.1f} s)"
    )
    return 0
