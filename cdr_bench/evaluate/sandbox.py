"""Confinement of untrusted agent code: the command line that starts a confined process.

An agent always runs in its own process (:mod:`.remote`); ``--sandbox`` (and every leaderboard
run) also confines that process with `bubblewrap <https://github.com/containers/bubblewrap>`_
(``bwrap``, the Debian package ``bubblewrap``; no daemon, no root):

* **Filesystem.** A fresh root holding read-only binds of the system (``/usr`` and the
  ``/bin``, ``/lib*`` links, the dynamic linker's configuration in ``/etc``), of the Python
  installation and virtual environment, and of one folder, the *view* (the repository for a
  leaderboard entry, the current folder for ``evaluate --sandbox``). Nothing else of the host is
  visible: no home folder, no other checkout, no ``/etc/passwd``. Folders listed as *hidden*
  (the leaderboard folder: results and staging) are covered by an empty ``tmpfs``. The only
  writable places are a private scratch folder (``HOME``, ``TMPDIR``; deleted afterwards) and an
  empty ``/tmp``.
* **No network** (``--unshare-net``: only a down loopback), new user, PID, IPC, UTS and cgroup
  namespaces, every capability dropped, a new session (no terminal injection).
* **Every process killed at the end**: the agent is PID 1's child in its own PID namespace and
  ``--die-with-parent`` ties the namespace to the evaluator; when the evaluator closes the agent
  (or dies), the kernel kills every process the agent started, ``setsid`` children included.
* **Limits**: CPU seconds and address space per process (``RLIMIT_CPU``, ``RLIMIT_AS``); the
  time of loading and of every decision is enforced by the evaluator from outside (:mod:`.remote`).
* **No arbitrary unpickling**: ``TORCH_FORCE_WEIGHTS_ONLY_LOAD=1`` and an audit hook in the
  agent process that refuses every pickle lookup of a global (``pickle.find_class``), however
  the unpickler was reached (``importlib``, ``getattr``, a library).
* **A clean environment**: ``PATH``, the scratch ``HOME``, one thread per process, and the
  variables the caller names (``CDR_BENCH_CHECKPOINT``); nothing else.

What it does not guarantee: it is not a VM (a kernel exploit escapes it); the number of
processes and the disk use of the scratch folder are not capped; an agent can read the system
files listed above and the Python packages installed in the environment.

Where ``bwrap`` is missing or cannot create namespaces, the fallback is **weaker** and says so
in every message: no network where ``unshare -rn`` works, the limits, a scratch ``HOME``, and
the process group killed at the end, but the agent can read and write every file the user can.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import sysconfig
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from cdr_bench.errors import UserError


class SandboxError(UserError):
    """A confined run failed; the message says what ran, why, and its last output."""


@dataclass(frozen=True)
class Limits:
    cpu_s: int = 3600
    """CPU seconds per process (``RLIMIT_CPU``)."""
    memory_mb: int = 6144
    """Address space per process in MiB (``RLIMIT_AS``; importing torch maps ~1.5 GiB)."""
    wall_s: float = 3600.0
    """Wall-clock seconds for a whole run (a leaderboard entry's evaluation)."""


@dataclass(frozen=True)
class Confinement:
    """How to confine an agent process (see the module docstring)."""

    view: str
    """The one folder of the host the agent may read (read-only)."""
    hidden: tuple[str, ...] = ()
    """Folders inside ``view`` covered by an empty tmpfs."""
    limits: Limits = Limits()


def set_limits(limits: Limits) -> None:
    """Apply ``limits`` to this process (called in the child between fork and exec)."""
    import resource

    resource.setrlimit(resource.RLIMIT_CPU, (limits.cpu_s, limits.cpu_s + 5))
    mem = limits.memory_mb * 1024 * 1024
    resource.setrlimit(resource.RLIMIT_AS, (mem, mem))


def seed_numba_cache(cache_dir: Path) -> None:
    """Copy the compiled-kernel cache of this package's numba functions (``__pycache__/*.nbi``,
    ``*.nbc`` beside the sources, written by this package's own runs) into ``cache_dir`` in the
    layout numba uses for ``NUMBA_CACHE_DIR``, so that a confined agent that calls
    :mod:`cdr_bench.inference` loads the kernels instead of compiling them (~20 s). Each agent
    process gets its own copy: nothing one agent writes there reaches another. A missing or
    stale cache only costs time (numba checks each entry against its source file)."""
    import hashlib

    import cdr_bench

    pkg = Path(cdr_bench.__file__).resolve().parent
    for pycache in pkg.rglob("__pycache__"):
        files = [f for f in pycache.iterdir() if f.suffix in (".nbi", ".nbc")]
        if not files:
            continue
        src_dir = str(pycache.parent)
        sub = "_".join([os.path.split(src_dir)[-1], hashlib.sha1(src_dir.encode()).hexdigest()])
        dest = cache_dir / sub
        dest.mkdir(parents=True, exist_ok=True)
        for f in files:
            shutil.copyfile(f, dest / f.name)


CPU_KNOBS = (
    "ATEN_CPU_CAPABILITY",
    "NPY_DISABLE_CPU_FEATURES",
    "NPY_ENABLE_CPU_FEATURES",
    "OPENBLAS_CORETYPE",
    "MKL_ENABLE_INSTRUCTIONS",
    "MKL_CBWR",
    "ONEDNN_MAX_CPU_ISA",
    "DNNL_MAX_CPU_ISA",
    "NUMBA_CPU_NAME",
    "NUMBA_CPU_FEATURES",
    "GLIBC_TUNABLES",
)
"""The scorer's own kernel settings (which SIMD kernels numpy, torch, BLAS and numba choose),
passed on to a confined child when set: they describe the machine, and setting them is how a
test makes one CPU compute like another."""


def child_env(scratch: Path, extra: dict[str, str] | None = None) -> dict[str, str]:
    """The whole environment of a confined child."""
    env = {k: os.environ[k] for k in CPU_KNOBS if k in os.environ}
    env |= {
        "PATH": os.environ.get("PATH", "/usr/bin:/bin"),
        "HOME": str(scratch),
        "TMPDIR": str(scratch),
        "USER": "agent",
        "LOGNAME": "agent",
        "LANG": "C.UTF-8",
        "PYTHONHASHSEED": "0",
        "PYTHONDONTWRITEBYTECODE": "1",
        "OMP_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
        "NUMBA_CACHE_DIR": str(scratch / "numba-cache"),
        "TORCH_FORCE_WEIGHTS_ONLY_LOAD": "1",
        "MPLBACKEND": "Agg",
        "CDR_BENCH_CONFINED": "1",
    }
    env.update(extra or {})
    return env


def _python_dirs() -> list[Path]:
    """Folders the interpreter needs: its installation, the virtual environment and every
    existing ``sys.path`` entry (editable installs point into the source tree)."""
    dirs = {Path(sys.base_prefix).resolve(), Path(sys.prefix).resolve()}
    dirs |= {Path(p).resolve() for p in sysconfig.get_paths().values() if p}
    dirs.add(Path(sys.executable).resolve().parent)
    for p in sys.path:
        if p and Path(p).exists():
            dirs.add(Path(p).resolve())
    import cdr_bench

    dirs.add(Path(cdr_bench.__file__).resolve().parent)
    # keep only the outermost folders (bwrap binds a folder with everything below it)
    out: list[Path] = []
    for d in sorted(dirs, key=lambda p: len(p.parts)):
        if d.is_dir() and not any(d.is_relative_to(o) for o in out):
            out.append(d)
    return out


def bwrap_prefix(conf: Confinement, scratch: Path, env: dict[str, str]) -> list[str]:
    """The ``bwrap`` command line (up to the confined program) for ``conf``."""
    exe = shutil.which("bwrap")
    assert exe is not None
    args = [
        exe,
        "--unshare-all",
        "--die-with-parent",
        "--new-session",
        "--cap-drop",
        "ALL",
        "--ro-bind",
        "/usr",
        "/usr",
    ]
    for name in ("bin", "sbin", "lib", "lib32", "lib64", "libx32"):
        p = Path("/") / name
        if p.is_symlink():
            args += ["--symlink", os.readlink(p), str(p)]
        elif p.is_dir():
            args += ["--ro-bind", str(p), str(p)]
    for etc in ("/etc/ld.so.cache", "/etc/ld.so.conf", "/etc/ld.so.conf.d", "/etc/alternatives"):
        if os.path.exists(etc):
            args += ["--ro-bind", etc, etc]
    args += ["--proc", "/proc", "--dev", "/dev", "--tmpfs", "/tmp"]
    for d in _python_dirs():
        if not d.is_relative_to("/usr"):
            args += ["--ro-bind", str(d), str(d)]
    view = str(Path(conf.view).resolve())
    args += ["--ro-bind", view, view]
    for h in conf.hidden:
        hp = Path(h).resolve()
        if hp.is_dir():
            args += ["--tmpfs", str(hp)]
    args += ["--bind", str(scratch), str(scratch), "--chdir", view, "--clearenv"]
    for k, v in env.items():
        args += ["--setenv", k, v]
    return args


@lru_cache(maxsize=1)
def isolation() -> tuple[str, str]:
    """``(kind, description)``: ``bwrap`` when a bubblewrap sandbox starts here, else
    ``unshare`` (network only) or ``none``, with the reason."""
    if shutil.which("bwrap") is not None:
        conf = Confinement(view=str(Path.cwd()))
        scratch = Path(os.environ.get("TMPDIR", "/tmp"))
        argv = [*bwrap_prefix(conf, scratch, {"PATH": "/usr/bin:/bin"}), sys.executable, "-c", ""]
        try:
            probe = subprocess.run(argv, capture_output=True, text=True, timeout=60)
        except (OSError, subprocess.TimeoutExpired) as e:
            why = str(e)
        else:
            if probe.returncode == 0:
                return "bwrap", "confined (bubblewrap: read-only view, no network, own PIDs)"
            why = clean(probe.stderr, 1) or f"exit code {probe.returncode}"
        weaker = f"bubblewrap cannot start here ({why})"
    else:
        weaker = "bubblewrap (`bwrap`, Debian package `bubblewrap`) is not installed"
    exe = shutil.which("unshare")
    if exe is not None:
        try:
            un = subprocess.run(
                [exe, "-rn", sys.executable, "-c", ""], capture_output=True, timeout=60
            )
            if un.returncode == 0:
                return "unshare", (
                    f"NOT confined: {weaker}; the agent has no network but CAN read and write "
                    "your files"
                )
        except (OSError, subprocess.TimeoutExpired):
            pass
    return "none", (
        f"NOT confined: {weaker} and `unshare -rn` is not permitted; the agent has the network "
        "and CAN read and write your files"
    )


def confined_argv(
    argv: list[str], conf: Confinement, scratch: Path, env_extra: dict[str, str] | None = None
) -> tuple[list[str], dict[str, str]]:
    """``(command line, environment)`` running ``argv`` confined by ``conf`` (or by the
    weaker fallback, see :func:`isolation`)."""
    env = child_env(scratch, env_extra)
    kind, _ = isolation()
    if kind == "bwrap":
        return [*bwrap_prefix(conf, scratch, env), *argv], env
    if kind == "unshare":
        return ["unshare", "-rn", *argv], env
    return list(argv), env


_CONTROL = re.compile(r"[^\t\n\x20-\x7e\u00a0-\uffff]")


def clean(text: str, lines: int = 12, width: int = 200) -> str:
    """The last ``lines`` lines of ``text``, control characters replaced, lines cut."""
    text = _CONTROL.sub("?", text.replace("\r", "\n"))
    rows = [r.rstrip()[:width] for r in text.splitlines() if r.strip()]
    return "\n".join(rows[-lines:])


def tail(path: Path, max_bytes: int = 65536) -> str:
    """The last ``max_bytes`` of a log file as text ('' if unreadable)."""
    try:
        with open(path, "rb") as f:
            f.seek(0, os.SEEK_END)
            f.seek(max(0, f.tell() - max_bytes))
            return f.read().decode("utf-8", errors="replace")
    except OSError:
        return ""
