"""Confinement of untrusted agent code: the command line that starts a confined process.

An agent always runs in its own process (:mod:`.remote`); ``--sandbox`` (and every leaderboard
run) also confines that process with `bubblewrap <https://github.com/containers/bubblewrap>`_
(``bwrap`` ≥ 0.8, the Debian package ``bubblewrap``; no daemon, no root).

What is defended, and how:

* **Filesystem: only what the identity hashes.** A fresh root holding read-only binds of the
  system (``/usr`` and the ``/bin``, ``/lib*`` links, the dynamic linker's configuration in
  ``/etc``), of the Python installation, the virtual environment and the ``cdr_bench`` package
  (the runtime), and of exactly the agent's files: those
  :func:`~cdr_bench.evaluate.loader.agent_files` lists plus the checkpoint named by
  ``CDR_BENCH_CHECKPOINT``, each bound read-only at its own path (:attr:`Confinement.files`).
  These are the files :func:`~cdr_bench.evaluate.loader.agent_identity` hashes, so an agent can
  read nothing that its identity does not cover (no ``.dat`` file, no code under its
  ``results/`` folder, no other agent, no ``leaderboard/`` folder, no home folder, no
  ``/etc/passwd``). The working directory is the repository root (for ``evaluate --sandbox``
  the current folder), an empty folder apart from those binds.
* **Nothing writable but capped RAM.** The root and ``/dev`` are remounted read-only (device
  nodes such as ``/dev/null`` stay usable); the only writable places are size-capped tmpfs
  mounts: the scratch folder (``HOME``, ``TMPDIR``, numba's cache; :data:`SCRATCH_MB`),
  ``/tmp`` (:data:`TMP_MB`) and ``/dev/shm`` (:data:`SHM_MB`). Together at most
  :func:`tmpfs_budget_mb` MiB of RAM per agent process tree, whatever ``RLIMIT_AS`` says (tmpfs
  pages are not part of any process's address space). The host-side scratch folder only holds
  the agent's captured output and a read-only copy of numba's cache.
* **No network** (``--unshare-net``: only a down loopback), new user, PID, IPC, UTS and cgroup
  namespaces, every capability dropped, a new session (no terminal injection).
* **An unprivileged user**: uid and gid 65534 (``nobody``) inside the sandbox.
* **No nested namespaces**: ``--disable-userns`` (the kernel refuses new user namespaces
  inside) and a seccomp filter (:func:`seccomp_filter`, x86-64 and AArch64) that refuses what
  an agent never needs with ``EPERM``: ``unshare``, ``setns``, ``clone`` with a namespace
  flag (``clone3`` answers ``ENOSYS`` so that the C library falls back to ``clone``), every
  mount call (``mount``, ``umount2``, ``pivot_root``, ``chroot``, the new mount API),
  ``ptrace``, ``process_vm_readv``/``writev``, ``kcmp``, ``pidfd_getfd``, kernel modules,
  ``kexec``, ``reboot``, ``swapon``/``off``, ``acct``, ``quotactl``, ``syslog``, the clock
  setters, ``iopl``/``ioperm``, ``keyctl``/``add_key``/``request_key``, ``bpf``,
  ``perf_event_open``, ``userfaultfd``, ``io_uring``, ``open_by_handle_at``,
  ``name_to_handle_at``, ``lookup_dcookie``, ``vhangup``, and ``socket`` for ``AF_PACKET`` or
  any ``SOCK_RAW`` other than netlink; system calls of another ABI (x32, i386 ``int 0x80``) are
  refused altogether.
* **Every process killed at the end**: the agent is PID 1's child in its own PID namespace and
  ``--die-with-parent`` ties the namespace to ``bwrap``, which itself gets ``SIGKILL`` when the
  evaluator dies (``PR_SET_PDEATHSIG``, :func:`child_setup`), ``kill -9`` included; when the
  evaluator closes the agent (or dies), the kernel kills every process the agent started,
  ``setsid`` children included. Scratch folders carry the owner's PID
  (``cdr-bench-agent-<pid>-``); the next run removes those whose owner is dead
  (:func:`remove_stale_scratch`).
* **Limits**: CPU seconds and address space per process (``RLIMIT_CPU``, ``RLIMIT_AS``); the
  time of loading and of every decision is enforced by the evaluator from outside
  (:mod:`.remote`). **The whole tree** (:func:`make_cgroup`): where a control group can be
  written (root on cgroup v1, or a delegated cgroup v2 group), bwrap and everything it starts
  are in their own group, capped at :data:`PIDS_MAX` tasks (``pids.max``) and at the memory
  limit plus :func:`tmpfs_budget_mb` (``memory.limit_in_bytes`` / ``memory.max``; tmpfs pages
  are charged to the group that wrote them, so RAM-backed files count); the group is removed
  with the tree. **Processes** otherwise: ``RLIMIT_NPROC`` is per *host* user and counts every
  process of that user, so it is set to the user's current count plus :data:`NPROC_HEADROOM`
  (a fork bomb stops there); it is not enforced for a host root user (the kernel exempts uid 0
  even inside a user namespace), which is why the control group matters there.
* **A clean environment**: ``PATH``, the scratch ``HOME``, one thread per process, and the
  variables the caller names (``CDR_BENCH_CHECKPOINT``); nothing else.
* **Conveniences, not boundaries**: ``TORCH_FORCE_WEIGHTS_ONLY_LOAD=1`` and an audit hook in
  the agent process (:mod:`.agent_host`) that refuses pickle lookups of globals outside
  numba's and numpy's own (a clear message for an agent that unpickles by mistake). A
  pure-Python unpickler bypasses the hook; what the agent could do with it is what it can do
  anyway, inside the sandbox.

What it does not defend:

* it is not a VM: a kernel exploit through an allowed system call escapes it;
* the agent can read the system files listed above, the whole Python environment and the
  ``cdr_bench`` package, hence the simulator and the public scenario definitions (whether it
  can use them to know the evaluation episodes is the leaderboard check's business, not the
  sandbox's);
* it can use all the CPU time and memory its limits allow, and the wall time the evaluator
  allows; without a writable control group, memory is capped per process only (several
  processes, plus the tmpfs budget, may hold more) and, for root, processes are not capped;
* run by root, uid 65534 in the sandbox is host uid 0 outside it (bubblewrap maps the
  sandbox user to the caller): it has no capability and sees only read-only binds, but files
  it creates on a writable bind would be root's (there is none);
* the seccomp filter exists only for x86-64 and AArch64; elsewhere the sandbox runs without
  it (and says so in :func:`isolation`'s description).

Where ``bwrap`` is missing or cannot create namespaces, the fallback is **weaker** and says so
in every message: no network where ``unshare -rn`` works, the limits, a scratch ``HOME``, the
process group killed at the end and the parent-death signal on the agent's own process, but
the agent can read and write every file the user can; what it starts with ``setsid`` may
outlive an evaluator killed with ``kill -9``. The same holds for plain ``evaluate`` (no
``--sandbox``): the agent runs in its own process, as the user, with the user's files; its
``TMPDIR`` is a private scratch folder (removed afterwards), its working directory and ``HOME``
are the user's; the evaluator alone writes the result, but nothing stops the agent (or a
process it detached, which can outlive the evaluator) from writing files, that one included,
or ``--resume`` keys in the user's cache folder.
"""

from __future__ import annotations

import errno
import os
import re
import shutil
import struct
import subprocess
import sys
import sysconfig
import tempfile
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

from cdr_bench.errors import UserError


class SandboxError(UserError):
    """A confined run failed; the message says what ran, why, and its last output."""


SCRATCH_MB = 256
"""Size cap of the confined process's scratch folder (``HOME``, ``TMPDIR``, numba's cache)."""
TMP_MB = 64
"""Size cap of the confined ``/tmp``."""
SHM_MB = 64
"""Size cap of the confined ``/dev/shm`` (POSIX shared memory, semaphores)."""
SANDBOX_UID = 65534
"""The user and group id of a confined process (``nobody``)."""
NPROC_HEADROOM = 256
"""Processes (threads count) a confined agent may add to its host user's current count."""
SCRATCH_PREFIX = "cdr-bench-agent-"
"""Scratch folders are ``<tempdir>/cdr-bench-agent-<owner pid>-<random>``."""
NUMBA_SEED = "/run/cdr-bench/numba-seed"
"""Where a confined process finds the read-only seed of numba's cache
(:func:`seed_numba_cache`); the agent host copies it into the writable cache at start."""


def tmpfs_budget_mb() -> int:
    """RAM the writable mounts of one confined process tree may hold at most, in MiB."""
    return SCRATCH_MB + TMP_MB + SHM_MB


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
    """The working directory of the confined process (the repository root, or the current
    folder of ``evaluate --sandbox``)."""
    hidden: tuple[str, ...] = ()
    """Folders inside ``view`` covered by an empty read-only tmpfs (only where ``files`` is
    ``None``)."""
    limits: Limits = Limits()
    files: tuple[str, ...] | None = None
    """``None``: the whole ``view`` folder is visible read-only (the checkpoint loader's box);
    else exactly these files, each bound read-only at its own path, and nothing else of
    ``view``. :class:`~cdr_bench.evaluate.remote.AgentProcess` sets the agent's identity files
    here."""


# ----------------------------------------------------------------------------------------------
# What the child does between fork and exec


def _count_user_tasks(uid: int) -> int:
    """Threads of every process of host user ``uid`` (what ``RLIMIT_NPROC`` counts)."""
    n = 0
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            with open(f"/proc/{pid}/status", "rb") as f:
                status = f.read().decode("ascii", "replace")
        except OSError:
            continue
        uid_line = re.search(r"^Uid:\s+(\d+)", status, re.M)
        threads = re.search(r"^Threads:\s+(\d+)", status, re.M)
        if uid_line and int(uid_line.group(1)) == uid:
            n += int(threads.group(1)) if threads else 1
    return n


def nproc_limit() -> int | None:
    """The ``RLIMIT_NPROC`` for a confined process tree: the host user's current count plus
    :data:`NPROC_HEADROOM`, within the hard limit (``None`` for root: not enforced)."""
    import resource

    uid = os.getuid()
    if uid == 0:
        return None
    _, hard = resource.getrlimit(resource.RLIMIT_NPROC)
    want = _count_user_tasks(uid) + NPROC_HEADROOM
    return want if hard == resource.RLIM_INFINITY else min(want, hard)


def set_limits(limits: Limits, nproc: int | None = None) -> None:
    """Apply ``limits`` (and a process cap ``nproc``) to this process (called in the child
    between fork and exec)."""
    import resource

    resource.setrlimit(resource.RLIMIT_CPU, (limits.cpu_s, limits.cpu_s + 5))
    mem = limits.memory_mb * 1024 * 1024
    resource.setrlimit(resource.RLIMIT_AS, (mem, mem))
    if nproc is not None:
        resource.setrlimit(resource.RLIMIT_NPROC, (nproc, nproc))


_PR_SET_PDEATHSIG = 1


def die_with_parent(parent: int) -> None:
    """Ask the kernel to ``SIGKILL`` this process when its parent (the thread that started it)
    dies, ``kill -9`` included; exit at once if ``parent`` is already gone (Linux; elsewhere
    nothing)."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes
    import signal

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
    except (OSError, AttributeError):  # pragma: no cover - every Linux C library has prctl
        return
    if os.getppid() != parent:
        os._exit(1)  # the parent died before the signal was armed


def child_setup(  # type: ignore[no-untyped-def]
    limits: Limits | None, nproc: int | None = None, cgroup: Cgroup | None = None
):
    """A ``preexec_fn``: parent-death signal, then ``limits`` (when given), then entry into
    ``cgroup`` (when given). Build it in the parent (it captures the parent's PID)."""
    parent = os.getpid()

    def setup() -> None:
        die_with_parent(parent)
        if limits is not None:
            set_limits(limits, nproc)
        if cgroup is not None:
            cgroup.enter()

    return setup


# ----------------------------------------------------------------------------------------------
# Control groups: a process cap and a memory cap for the whole confined tree, where offered

CGROUP_ROOT = Path("/sys/fs/cgroup")
"""Where the control-group file systems are mounted."""
CGROUP_PREFIX = "cdr-bench-agent-"
"""A confined agent's groups are ``<its evaluator's group>/cdr-bench-agent-<owner pid>-<n>``."""
PIDS_MAX = NPROC_HEADROOM
"""Processes and threads a confined agent's tree may hold at once (its group's ``pids.max``)."""


@dataclass
class Cgroup:
    """The control groups of one confined process tree (one per hierarchy: cgroup v1 has one
    for ``pids`` and one for ``memory``, v2 one for both): the child enters them between fork
    and exec (:meth:`enter`), so every process it starts, the agent's included, is counted;
    :meth:`close` removes them once the tree is gone."""

    dirs: tuple[Path, ...]

    def enter(self) -> None:
        pid = str(os.getpid()).encode()
        for d in self.dirs:
            fd = os.open(d / "cgroup.procs", os.O_WRONLY)
            try:
                os.write(fd, pid)
            finally:
                os.close(fd)

    def close(self) -> None:
        """Remove the groups (waiting up to three seconds for the killed tree's last tasks to be
        reaped); one still busy then is removed by a later run (:func:`remove_stale_cgroups`)."""
        import time

        left = list(self.dirs)
        for _ in range(150):
            for d in list(left):
                try:
                    d.rmdir()
                    left.remove(d)
                except FileNotFoundError:
                    left.remove(d)
                except OSError:
                    pass
            if not left:
                return
            time.sleep(0.02)


def _own_groups() -> dict[str, Path]:
    """This process's group folder per controller (``pids``, ``memory``; ``""`` for cgroup v2),
    where that hierarchy is mounted at the usual place."""
    out: dict[str, Path] = {}
    try:
        lines = Path("/proc/self/cgroup").read_text().splitlines()
    except OSError:
        return out
    for line in lines:
        _, controllers, path = line.split(":", 2)
        for c in controllers.split(",") if controllers else [""]:
            mount = CGROUP_ROOT / c if c else CGROUP_ROOT
            if c == "" and not (mount / "cgroup.controllers").exists():
                mount = CGROUP_ROOT / "unified"
            if c in ("pids", "memory", ""):
                out[c] = mount / path.lstrip("/")
    return out


def _write(path: Path, value: str) -> None:
    path.write_text(value)


def remove_stale_cgroups() -> None:
    """Remove the groups (:data:`CGROUP_PREFIX`) whose owner process is dead (a crash or
    ``kill -9`` of the evaluator left them; empty by then, as their processes died with it)."""
    for parent in _own_groups().values():
        try:
            entries = list(os.scandir(parent))
        except OSError:
            continue
        for e in entries:
            owner = e.name[len(CGROUP_PREFIX) :].split("-", 1)[0]
            if e.name.startswith(CGROUP_PREFIX) and owner.isdigit() and not pid_alive(int(owner)):
                try:
                    os.rmdir(e.path)
                except OSError:
                    pass


_CGROUP_SEQ = [0]


@lru_cache(maxsize=1)
def cgroup_support() -> str | None:
    """Which hierarchies can cap a confined tree here (``"v1"``, ``"v2"``; None: none, e.g. an
    unprivileged user without a delegated group): a probe group is created and removed."""
    cg = make_cgroup(Limits(), probe=True)
    if cg is None:
        return None
    cg.close()
    return "v2" if cg.dirs and cg.dirs[0].parent == _own_groups().get("") else "v1"


def make_cgroup(limits: Limits | None, probe: bool = False) -> Cgroup | None:
    """New groups capping a confined tree at :data:`PIDS_MAX` tasks and at ``limits``'s memory
    plus the tmpfs budget (:func:`tmpfs_budget_mb`: the kernel charges tmpfs pages to the group
    that wrote them, so RAM-backed files count), or None where no hierarchy can be written
    (then the tree has ``RLIMIT_NPROC`` and ``RLIMIT_AS`` only, see the module docstring)."""
    if not sys.platform.startswith("linux"):
        return None
    if not probe:
        remove_stale_cgroups()
    own = _own_groups()
    memory_mb = (limits.memory_mb if limits is not None else Limits().memory_mb) + tmpfs_budget_mb()
    _CGROUP_SEQ[0] += 1
    name = f"{CGROUP_PREFIX}{os.getpid()}-{_CGROUP_SEQ[0]}"
    made: list[Path] = []
    try:
        if "pids" in own and "memory" in own:  # cgroup v1
            pids, mem = own["pids"] / name, own["memory"] / name
            pids.mkdir()
            made.append(pids)
            mem.mkdir()
            made.append(mem)
            _write(pids / "pids.max", str(PIDS_MAX))
            _write(mem / "memory.limit_in_bytes", str(memory_mb * 1024 * 1024))
        elif "" in own:  # cgroup v2: needs both controllers delegated to this group
            d = own[""] / name
            d.mkdir()
            made.append(d)
            _write(d / "pids.max", str(PIDS_MAX))
            _write(d / "memory.max", str(memory_mb * 1024 * 1024))
        else:
            return None
    except OSError:
        for d in reversed(made):
            try:
                d.rmdir()
            except OSError:
                pass
        return None
    return Cgroup(tuple(made))


# ----------------------------------------------------------------------------------------------
# Scratch folders


def make_scratch() -> Path:
    """A new private scratch folder named after this process (see :func:`remove_stale_scratch`),
    after removing those that dead evaluators left."""
    remove_stale_scratch()
    return Path(tempfile.mkdtemp(prefix=f"{SCRATCH_PREFIX}{os.getpid()}-"))


def pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_scratch(where: Path | None = None, prefix: str = SCRATCH_PREFIX) -> list[Path]:
    """Remove the folders ``<where>/<prefix><pid>-*`` of this user whose owner ``pid`` is dead
    (a crash or ``kill -9`` left them); returns them."""
    where = Path(tempfile.gettempdir()) if where is None else where
    gone: list[Path] = []
    try:
        entries = list(os.scandir(where))
    except OSError:
        return gone
    uid = os.getuid()
    for e in entries:
        if not e.name.startswith(prefix):
            continue
        pid = e.name[len(prefix) :].split("-", 1)[0]
        try:
            if not pid.isdigit() or not e.is_dir(follow_symlinks=False):
                continue
            if e.stat(follow_symlinks=False).st_uid != uid or pid_alive(int(pid)):
                continue
        except OSError:
            continue
        shutil.rmtree(e.path, ignore_errors=True)
        gone.append(Path(e.path))
    return gone


def seed_numba_cache(cache_dir: Path) -> None:
    """Copy the compiled-kernel cache of this package's numba functions (``__pycache__/*.nbi``,
    ``*.nbc`` beside the sources, written by this package's own runs) into ``cache_dir`` in the
    layout numba uses for ``NUMBA_CACHE_DIR``, so that a confined agent that calls
    :mod:`cdr_bench.inference` loads the kernels instead of compiling them (~20 s). A confined
    process sees this folder read-only at :data:`NUMBA_SEED` and copies it into its own
    writable cache: nothing one agent writes there reaches another. A missing or stale cache
    only costs time (numba checks each entry against its source file)."""
    import hashlib

    import cdr_bench

    pkg = Path(cdr_bench.__file__).resolve().parent
    cache_dir.mkdir(parents=True, exist_ok=True)
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


# ----------------------------------------------------------------------------------------------
# Seccomp


_DENIED_SYSCALLS = (
    "unshare setns mount umount2 pivot_root chroot open_tree move_mount fsopen fsconfig fsmount "
    "fspick mount_setattr ptrace process_vm_readv process_vm_writev kcmp pidfd_getfd "
    "init_module finit_module delete_module kexec_load kexec_file_load reboot swapon swapoff "
    "acct quotactl syslog settimeofday clock_settime adjtimex clock_adjtime iopl ioperm keyctl "
    "add_key request_key bpf perf_event_open userfaultfd io_uring_setup io_uring_enter "
    "io_uring_register open_by_handle_at name_to_handle_at lookup_dcookie vhangup"
).split()
"""System calls a confined agent never needs; refused with ``EPERM`` (module docstring)."""

# System call numbers from the kernel's unistd headers: "name x86_64 aarch64" ("-": none there).
_SYSCALL_TABLE = (
    (
        "unshare 272 97 / setns 308 268 / mount 165 40 / "
        "umount2 166 39 / pivot_root 155 41 / chroot 161 51 / "
        "open_tree 428 428 / move_mount 429 429 / fsopen 430 430 / "
        "fsconfig 431 431 / fsmount 432 432 / fspick 433 433 / "
        "mount_setattr 442 442 / ptrace 101 117 / process_vm_readv 310 270 / "
        "process_vm_writev 311 271 / kcmp 312 272 / pidfd_getfd 438 438 / "
        "init_module 175 105 / finit_module 313 273 / delete_module 176 106 / "
        "kexec_load 246 104 / kexec_file_load 320 294 / reboot 169 142 / "
        "swapon 167 224 / swapoff 168 225 / acct 163 89 / "
        "quotactl 179 60 / syslog 103 116 / settimeofday 164 170 / "
        "clock_settime 227 112 / adjtimex 159 171 / clock_adjtime 305 266 / "
        "iopl 172 - / ioperm 173 - / keyctl 250 219 / "
        "add_key 248 217 / request_key 249 218 / bpf 321 280 / "
        "perf_event_open 298 241 / userfaultfd 323 282 / io_uring_setup 425 425 / "
        "io_uring_enter 426 426 / io_uring_register 427 427 / open_by_handle_at 304 265 / "
        "name_to_handle_at 303 264 / lookup_dcookie 212 18 / vhangup 153 58 / "
        "clone 56 220 / clone3 435 435 / socket 41 198 / "
    )
    .strip(" /")
    .split(" / ")
)
_ARCHES = {"x86_64": (0xC000003E, 1), "aarch64": (0xC00000B7, 2)}
"""``platform.machine()`` -> (its AUDIT_ARCH value, its column in :data:`_SYSCALL_TABLE`)."""
_SYSCALLS: dict[str, tuple[int, dict[str, int]]] = {
    machine: (arch, {f[0]: int(f[col]) for f in map(str.split, _SYSCALL_TABLE) if f[col] != "-"})
    for machine, (arch, col) in _ARCHES.items()
}
"""Per machine: its AUDIT_ARCH value and the numbers of the system calls the filter names."""
_CLONE_NAMESPACES = 0x7E020080
"""CLONE_NEWNS | NEWCGROUP | NEWUTS | NEWIPC | NEWUSER | NEWPID | NEWNET | NEWTIME."""
_AF_NETLINK, _AF_PACKET, _SOCK_RAW = 16, 17, 3

# classic BPF
_LD_W_ABS, _JEQ_K, _JGE_K, _JSET_K, _AND_K, _RET_K = 0x20, 0x15, 0x35, 0x45, 0x54, 0x06
_ALLOW = 0x7FFF0000
_ERRNO = 0x00050000


def _insn(code: int, k: int, jt: int = 0, jf: int = 0) -> bytes:
    return struct.pack("<HBBI", code, jt, jf, k & 0xFFFFFFFF)


def seccomp_filter(machine: str | None = None) -> bytes | None:
    """The seccomp program (classic BPF, as ``bwrap --seccomp`` reads it) refusing the system
    calls the module docstring lists, for this machine's architecture (``None`` where there
    is no table: x86-64 and AArch64 only). Offsets in ``struct seccomp_data``: nr 0, arch 4,
    args 16 + 8 i (the low 32 bits first on these little-endian machines)."""
    import platform

    machine = (machine or platform.machine()).lower()
    machine = {"amd64": "x86_64", "arm64": "aarch64"}.get(machine, machine)
    if machine not in _SYSCALLS:
        return None
    arch, nr = _SYSCALLS[machine]
    eperm, enosys = _ERRNO | errno.EPERM, _ERRNO | errno.ENOSYS
    p = [
        _insn(_LD_W_ABS, 4),
        _insn(_JEQ_K, arch, 1, 0),
        _insn(_RET_K, enosys),  # another ABI (i386 int 0x80 on x86-64)
        _insn(_LD_W_ABS, 0),
    ]
    if machine == "x86_64":
        p += [_insn(_JGE_K, 0x40000000, 0, 1), _insn(_RET_K, enosys)]  # the x32 ABI
    for name in _DENIED_SYSCALLS:
        if name in nr:
            p += [_insn(_JEQ_K, nr[name], 0, 1), _insn(_RET_K, eperm)]
    p += [_insn(_JEQ_K, nr["clone3"], 0, 1), _insn(_RET_K, enosys)]
    p += [  # clone: flags are the first argument on both
        _insn(_JEQ_K, nr["clone"], 0, 4),
        _insn(_LD_W_ABS, 16),
        _insn(_JSET_K, _CLONE_NAMESPACES, 0, 1),
        _insn(_RET_K, eperm),
        _insn(_RET_K, _ALLOW),
    ]
    p += [  # socket(family, type, protocol)
        _insn(_JEQ_K, nr["socket"], 0, 8),
        _insn(_LD_W_ABS, 16),
        _insn(_JEQ_K, _AF_PACKET, 4, 0),
        _insn(_JEQ_K, _AF_NETLINK, 4, 0),
        _insn(_LD_W_ABS, 24),
        _insn(_AND_K, 0xF),
        _insn(_JEQ_K, _SOCK_RAW, 0, 1),
        _insn(_RET_K, eperm),
        _insn(_RET_K, _ALLOW),
    ]
    p.append(_insn(_RET_K, _ALLOW))
    return b"".join(p)


# ----------------------------------------------------------------------------------------------
# The bwrap command line


def _python_dirs() -> list[Path]:
    """Folders the interpreter needs: its installation, the virtual environment, the
    ``sys.path`` entries inside them (site-packages) and the ``cdr_bench`` package (an
    editable install points into the source tree: only the package folder is bound, never the
    repository around it)."""
    roots = {Path(sys.base_prefix).resolve(), Path(sys.prefix).resolve()}
    dirs = set(roots)
    dirs |= {Path(p).resolve() for p in sysconfig.get_paths().values() if p}
    dirs.add(Path(sys.executable).resolve().parent)
    for p in sys.path:
        if p and ("site-packages" in p or "dist-packages" in p) and Path(p).exists():
            dirs.add(Path(p).resolve())
    import cdr_bench

    dirs.add(Path(cdr_bench.__file__).resolve().parent)
    # keep only the outermost folders (bwrap binds a folder with everything below it)
    out: list[Path] = []
    for d in sorted(dirs, key=lambda p: len(p.parts)):
        if d.is_dir() and not any(d.is_relative_to(o) for o in out):
            out.append(d)
    return out


@lru_cache(maxsize=1)
def _bwrap_has(option: str) -> bool:
    exe = shutil.which("bwrap")
    if exe is None:
        return False
    try:
        r = subprocess.run([exe, "--help"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return option in r.stdout + r.stderr


def _files_binds(files: tuple[str, ...]) -> list[str]:
    """``--ro-bind`` of each file at its own path (and at its resolved path, where a link)."""
    args: list[str] = []
    seen: set[str] = set()
    for f in files:
        p = Path(f).absolute()
        real = p.resolve()
        if not real.is_file():
            continue
        for dest in (str(p), str(real)):
            if dest not in seen:
                seen.add(dest)
                args += ["--ro-bind", str(real), dest]
    return args


def bwrap_prefix(
    conf: Confinement,
    scratch: Path,
    env: dict[str, str],
    seccomp_fd: int | None = None,
    numba_seed: Path | None = None,
) -> list[str]:
    """The ``bwrap`` command line (up to the confined program) for ``conf``. ``scratch`` is the
    path of the confined scratch folder (a size-capped tmpfs there; nothing of the host's
    folder of that name is visible); ``numba_seed`` a host folder bound read-only at
    :data:`NUMBA_SEED`; ``seccomp_fd`` an inherited descriptor holding
    :func:`seccomp_filter`."""
    exe = shutil.which("bwrap")
    assert exe is not None
    args = [exe, "--unshare-all", "--unshare-user"]
    if _bwrap_has("--disable-userns"):
        args.append("--disable-userns")
    args += [
        "--uid",
        str(SANDBOX_UID),
        "--gid",
        str(SANDBOX_UID),
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
    mb = 1024 * 1024
    args += ["--proc", "/proc", "--dev", "/dev"]
    args += ["--size", str(SHM_MB * mb), "--tmpfs", "/dev/shm"]
    args += ["--size", str(TMP_MB * mb), "--tmpfs", "/tmp"]
    for d in _python_dirs():
        if not d.is_relative_to("/usr"):
            args += ["--ro-bind", str(d), str(d)]
    view = str(Path(conf.view).resolve())
    ro_tmpfs: list[str] = []
    if conf.files is None:
        args += ["--ro-bind", view, view]
        for h in conf.hidden:
            hp = Path(h).resolve()
            if hp.is_dir():
                args += ["--size", str(mb), "--tmpfs", str(hp)]
                ro_tmpfs.append(str(hp))
    else:
        args += ["--dir", view, *_files_binds(conf.files)]
    args += ["--size", str(SCRATCH_MB * mb), "--tmpfs", str(scratch)]
    if numba_seed is not None:
        args += ["--ro-bind", str(numba_seed), NUMBA_SEED]
    for ro in [*ro_tmpfs, "/dev", "/"]:
        args += ["--remount-ro", ro]
    if seccomp_fd is not None:
        args += ["--seccomp", str(seccomp_fd)]
    args += ["--chdir", view, "--clearenv"]
    for k, v in env.items():
        args += ["--setenv", k, v]
    return args


@lru_cache(maxsize=1)
def isolation() -> tuple[str, str]:
    """``(kind, description)``: ``bwrap`` when a bubblewrap sandbox starts here, else
    ``unshare`` (network only) or ``none``, with the reason."""
    if shutil.which("bwrap") is not None:
        conf = Confinement(view=str(Path.cwd()), files=())
        scratch = Path(tempfile.gettempdir()) / "cdr-bench-probe"
        filt = seccomp_filter()
        box = Confined([sys.executable, "-c", ""], {"PATH": "/usr/bin:/bin"})
        try:
            fd = _seccomp_fd(filt) if filt is not None else None
            box.pass_fds = () if fd is None else (fd,)
            argv = [*bwrap_prefix(conf, scratch, box.env, fd), *box.argv]
            probe = subprocess.run(
                argv, capture_output=True, text=True, timeout=60, pass_fds=box.pass_fds
            )
        except (OSError, subprocess.TimeoutExpired) as e:
            why = str(e)
        else:
            if probe.returncode == 0:
                filtered = "seccomp filter" if filt is not None else "NO seccomp filter here"
                capped = (
                    f"; the process tree in its own control group: {PIDS_MAX} tasks, memory "
                    "limit plus tmpfs"
                    if cgroup_support() is not None
                    else ""
                )
                return "bwrap", (
                    "confined (bubblewrap: only the agent's files visible, read-only, no "
                    f"network, own PIDs, uid {SANDBOX_UID}, {filtered}{capped})"
                )
            why = clean(probe.stderr, 1) or f"exit code {probe.returncode}"
        finally:
            box.close()
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


def _seccomp_fd(program: bytes) -> int:
    """A descriptor (inheritable, at offset 0) of an unlinked file holding ``program``."""
    with tempfile.TemporaryFile() as f:
        f.write(program)
        f.flush()
        fd = os.dup(f.fileno())
    os.lseek(fd, 0, os.SEEK_SET)
    os.set_inheritable(fd, True)
    return fd


@dataclass
class Confined:
    """A confined command: start it with ``pass_fds=pass_fds`` (the seccomp program bwrap
    reads), then :meth:`close` (the parent's copies of those descriptors)."""

    argv: list[str]
    env: dict[str, str]
    pass_fds: tuple[int, ...] = field(default_factory=tuple)

    def close(self) -> None:
        for fd in self.pass_fds:
            try:
                os.close(fd)
            except OSError:
                pass
        self.pass_fds = ()


def confined(
    argv: list[str],
    conf: Confinement,
    scratch: Path,
    env_extra: dict[str, str] | None = None,
    numba_seed: Path | None = None,
) -> Confined:
    """``argv`` confined by ``conf`` (or by the weaker fallback, see :func:`isolation`), with
    ``scratch`` as its private scratch folder. The program runs with ``python -P`` semantics
    where it is this Python (no folder of the caller on its import path)."""
    kind, _ = isolation()
    scratch = Path(scratch).resolve()  # a relative path would name another folder inside
    extra = dict(env_extra or {})
    if numba_seed is not None:
        extra["CDR_BENCH_NUMBA_SEED"] = NUMBA_SEED if kind == "bwrap" else str(numba_seed)
    env = child_env(scratch, extra)
    if kind == "bwrap":
        filt = seccomp_filter()
        fd = _seccomp_fd(filt) if filt is not None else None
        fds = () if fd is None else (fd,)
        prefix = bwrap_prefix(conf, scratch, env, fd, numba_seed)
        return Confined([*prefix, *argv], env, fds)
    if kind == "unshare":
        return Confined(["unshare", "-rn", *argv], env)
    return Confined(list(argv), env)


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
