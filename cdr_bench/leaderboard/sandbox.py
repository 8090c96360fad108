"""Running untrusted submission code: one subprocess per submission, with limits.

* **CPU time and memory.** ``RLIMIT_CPU`` (per process, seconds) and ``RLIMIT_AS`` (address
  space, per process) are set in the child before it starts Python; evaluation workers inherit
  them. A wall-clock limit kills the child's whole process group (a hang at import time is
  caught too; the evaluator's own per-decision limit catches a hang inside ``act``).
* **No network** where the platform allows it: the child runs under ``unshare -rn`` (a new user
  and network namespace with only a down loopback). Where unprivileged user namespaces are not
  available the probe fails and the child runs with the network; every run says which.
* **No arbitrary unpickling.** ``TORCH_FORCE_WEIGHTS_ONLY_LOAD=1`` makes every ``torch.load`` in
  the child refuse pickled objects whatever the agent passes; a declared checkpoint is first
  opened with a safe loader in its own sandboxed process (:mod:`.safeload`); the agent's Python
  files are scanned for pickle-family loaders (:func:`scan_agent_code`) and refused if any.
* **A clean environment.** The child gets ``PATH``, a scratch ``HOME``, one thread per process
  and nothing else from the parent's environment.

This is defence in depth, not a jail: the child can still read and write files the user can.
Output of the child goes to log files (never parsed); on failure the message quotes its last
lines with control characters removed.
"""

from __future__ import annotations

import ast
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from cdr_bench.errors import UserError


class SandboxError(UserError):
    """A sandboxed run failed; the message says which submission, why, and its last output."""


@dataclass(frozen=True)
class Limits:
    cpu_s: int = 3600
    """CPU seconds per process (``RLIMIT_CPU``)."""
    memory_mb: int = 6144
    """Address space per process in MiB (``RLIMIT_AS``; importing torch maps ~1.5 GiB)."""
    wall_s: float = 3600.0
    """Wall-clock seconds for the whole run (then the process group is killed)."""


@lru_cache(maxsize=1)
def network_isolation() -> tuple[tuple[str, ...], str]:
    """``(argv prefix, description)``: ``unshare -rn`` when it works here, else no prefix and
    the reason."""
    exe = shutil.which("unshare")
    if exe is None:
        return (), "network NOT isolated: no `unshare` on this system"
    try:
        probe = subprocess.run(
            [exe, "-rn", sys.executable, "-c", "import socket"],
            capture_output=True,
            text=True,
            timeout=30,
        )
    except (OSError, subprocess.TimeoutExpired) as e:
        return (), f"network NOT isolated: `unshare -rn` failed ({e})"
    if probe.returncode != 0:
        why = _clean(probe.stderr, 1) or f"exit code {probe.returncode}"
        return (), f"network NOT isolated: `unshare -rn` is not permitted here ({why})"
    return (exe, "-rn"), "no network (unshare -rn)"


def child_env(scratch: Path, extra: dict[str, str] | None = None) -> dict[str, str]:
    """The whole environment of a sandboxed child."""
    env = {
        "PATH": os.environ.get("PATH", "/usr/bin:/bin"),
        "HOME": str(scratch),
        "TMPDIR": str(scratch),
        "LANG": "C.UTF-8",
        "PYTHONHASHSEED": "0",
        "PYTHONDONTWRITEBYTECODE": "1",
        "OMP_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
        "TORCH_FORCE_WEIGHTS_ONLY_LOAD": "1",
        "MPLBACKEND": "Agg",
    }
    env.update(extra or {})
    return env


def _set_limits(limits: Limits) -> None:  # runs in the child, between fork and exec
    import resource

    resource.setrlimit(resource.RLIMIT_CPU, (limits.cpu_s, limits.cpu_s + 5))
    mem = limits.memory_mb * 1024 * 1024
    resource.setrlimit(resource.RLIMIT_AS, (mem, mem))


_CONTROL = re.compile(r"[^\t\n\x20-\x7e\u00a0-\uffff]")


def _clean(text: str, lines: int = 12, width: int = 200) -> str:
    """The last ``lines`` lines of ``text``, control characters replaced, lines cut."""
    text = _CONTROL.sub("?", text.replace("\r", "\n"))
    rows = [r.rstrip()[:width] for r in text.splitlines() if r.strip()]
    return "\n".join(rows[-lines:])


def _tail(path: Path, max_bytes: int = 65536) -> str:
    try:
        with open(path, "rb") as f:
            f.seek(0, os.SEEK_END)
            f.seek(max(0, f.tell() - max_bytes))
            return f.read().decode("utf-8", errors="replace")
    except OSError:
        return ""


def run_sandboxed(
    argv: list[str],
    *,
    what: str,
    cwd: Path,
    scratch: Path,
    limits: Limits,
    env_extra: dict[str, str] | None = None,
) -> float:
    """Run ``argv`` (a Python command line) sandboxed; returns the wall time in seconds.

    Raises :class:`SandboxError` naming ``what`` when the child exits non-zero, is killed by
    a limit or signal, or outlives ``limits.wall_s``.
    """
    scratch.mkdir(parents=True, exist_ok=True)
    prefix, _ = network_isolation()
    out_log, err_log = scratch / "stdout.log", scratch / "stderr.log"
    t0 = time.perf_counter()
    with open(out_log, "wb") as out, open(err_log, "wb") as err:
        proc = subprocess.Popen(
            [*prefix, *argv],
            cwd=cwd,
            env=child_env(scratch, env_extra),
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=err,
            start_new_session=True,
            preexec_fn=lambda: _set_limits(limits),
        )
        try:
            code = proc.wait(timeout=limits.wall_s)
        except subprocess.TimeoutExpired:
            _kill_group(proc)
            raise SandboxError(
                f"{what}: did not finish within the wall-clock limit of {limits.wall_s:g} s "
                f"(killed){_last_output(err_log, out_log)}"
            ) from None
        except BaseException:
            _kill_group(proc)
            raise
    _kill_group(proc)  # workers left behind by a child that exited
    wall = time.perf_counter() - t0
    if code == 0:
        return wall
    if code < 0:
        sig = -code
        if sig in (signal.SIGXCPU, signal.SIGKILL) and wall < limits.wall_s:
            why = (
                f"killed by {signal.Signals(sig).name}: the CPU time limit is {limits.cpu_s} s per "
                "process"
                if sig == signal.SIGXCPU
                else "killed by SIGKILL (out of memory or CPU hard limit)"
            )
        else:
            why = f"killed by signal {signal.Signals(sig).name}"
    else:
        why = f"exit code {code}"
    raise SandboxError(f"{what}: failed ({why}){_last_output(err_log, out_log)}")


def _last_output(err_log: Path, out_log: Path) -> str:
    text = _clean(_tail(err_log)) or _clean(_tail(out_log))
    if not text:
        return ""
    return "\n  last output:\n    " + text.replace("\n", "\n    ")


def _kill_group(proc: subprocess.Popen[bytes]) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:  # pragma: no cover - SIGKILL does not fail
        pass


# ----------------------------------------------------------------------------------------------
# Static guard against pickle-family loaders in the agent's own code

_UNSAFE_MODULES = {"pickle", "cPickle", "_pickle", "dill", "cloudpickle", "joblib", "shelve"}
_UNSAFE_FUNCS = {"load", "loads", "Unpickler", "open"}


def scan_agent_code(files: list[Path]) -> list[str]:
    """``file:line: what`` for every pickle-family load, ``weights_only=False`` and
    ``allow_pickle=True`` in the given Python files."""
    problems = []
    for f in files:
        if f.suffix != ".py":
            continue
        try:
            tree = ast.parse(f.read_text(encoding="utf-8"), filename=str(f))
        except (SyntaxError, UnicodeDecodeError, OSError):
            continue  # the evaluator reports syntax errors with the agent's line
        for node in ast.walk(tree):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                mod = node.module if isinstance(node, ast.ImportFrom) else None
                names = [a.name.split(".")[0] for a in node.names]
                if (mod and mod.split(".")[0] in _UNSAFE_MODULES) or (
                    mod is None and set(names) & _UNSAFE_MODULES
                ):
                    problems.append(f"{f.name}:{node.lineno}: imports a pickle-family module")
            if not isinstance(node, ast.Call):
                continue
            for kw in node.keywords:
                if (
                    kw.arg in ("weights_only", "allow_pickle")
                    and isinstance(kw.value, ast.Constant)
                    and kw.value.value is (kw.arg == "allow_pickle")
                ):
                    problems.append(f"{f.name}:{node.lineno}: {kw.arg}={kw.value.value}")
            func = node.func
            if (
                isinstance(func, ast.Attribute)
                and func.attr in _UNSAFE_FUNCS
                and isinstance(func.value, ast.Name)
                and func.value.id in _UNSAFE_MODULES
            ):
                problems.append(f"{f.name}:{node.lineno}: {func.value.id}.{func.attr}(...)")
    return problems
