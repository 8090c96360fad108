"""The scorer's own confinement: defence in depth around the trusted scorer of the build.

The scorer (:mod:`.entry`) runs only this package's code (``python -I``: neither the repository
nor any ``PYTHON*`` variable is on its import path), but it reads files that a submission
placed (result files, checkpoints it hashes, the agent's declared files) and talks to the
agent. Where bubblewrap runs, it is confined too, so that a flaw in it, or in a library it
uses on a submitted file, cannot reach the host:

* **the whole file system read-only**; writable only the scorer's own scratch folder (its
  result files are written there and moved into the staging folder by the build afterwards;
  it is also its ``TMPDIR``, where it makes its agents' scratch folders), a private,
  size-capped ``/dev/shm`` (:data:`SHM_MB`), and the control-group tree (below);
* **no network**, its own user, IPC and UTS namespaces, a new session;
* **no capability**: uid and gid 65534 inside its user namespace (bubblewrap maps them to the
  caller), so it cannot remount anything writable;
* **its agents confined exactly as before**: the scorer makes each agent's bubblewrap sandbox
  and control group (:mod:`cdr_bench.evaluate.sandbox`) from inside. Run by root on cgroup
  v1, the build makes a group for the scorer in which the scorer makes its agents' groups;
  the numba kernels come from a copy of the package's cache in the scratch folder.

What it does not defend: the scorer keeps the host's PID namespace and ``/proc`` (bubblewrap
cannot mount a fresh ``/proc`` for the agent's sandbox inside a sandbox that hides part of it or
has its own PID namespace), and outside its namespace it is the caller's user: it can see the
host's processes and signal the caller's, and, run by root, write the root-writable files of
``/proc/sys`` (a root-run scorer cannot become another user: the Python it runs may lie in a
folder only root can read). Its working directory stays the repository root (read-only here,
and not on its import path), because the relative paths of a submission and of the result
files are relative to it.

:func:`scorer_isolation` probes once per build that a scorer confined this way still confines
its agents as an unconfined one would (same isolation kind, same control-group support).
Where it does not (no bubblewrap, a cgroup v2 host without delegation), the scorer runs as
before, unconfined in isolated mode, and the build says so.
"""

from __future__ import annotations

import itertools
import os
import shutil
import subprocess
import sys
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from cdr_bench.evaluate.sandbox import (
    CGROUP_PREFIX,
    SANDBOX_UID,
    SHM_MB,
    Cgroup,
    _own_groups,
    cgroup_support,
    child_setup,
    clean,
    isolation,
    remove_stale_scratch,
    seed_numba_cache,
)

_PROBE = (
    "import os; from cdr_bench.evaluate.sandbox import cgroup_support, isolation; "
    "print(isolation()[0], cgroup_support()"
)


@dataclass
class ScorerBox:
    """How to start one confined scorer: ``prefix`` before its command line, ``env`` its whole
    environment and ``cgroup`` the group to enter;
    :meth:`close` once it has ended and its outputs are read (removes its scratch folder)."""

    prefix: list[str]
    env: dict[str, str]
    cgroup: Cgroup | None
    scratch: Path

    def close(self) -> None:
        if self.cgroup is not None:
            self.cgroup.close()
        shutil.rmtree(self.scratch, ignore_errors=True)


def _delegated_cgroup() -> Cgroup | None:
    """A group per cgroup v1 hierarchy (``pids``, ``memory``) for the scorer's tree, in which the
    scorer, without capabilities, can make its agents' groups (the top folders of a hierarchy
    need ``CAP_DAC_OVERRIDE``); no limit of its own: those are the agents'. None where this
    process cannot make one (cgroup v2: its agents' groups would need the scorer's group to
    hold no process)."""
    own = _own_groups()
    if "pids" not in own or "memory" not in own:
        return None
    name = f"{CGROUP_PREFIX}{os.getpid()}-scorer-{next(_SEQ)}"
    made: list[Path] = []
    try:
        for c in ("pids", "memory"):
            d = own[c] / name
            d.mkdir()
            made.append(d)
    except OSError:
        Cgroup(tuple(made)).close()
        return None
    return Cgroup(tuple(made))


_SEQ = itertools.count(1)


SCRATCH_PREFIX = "cdr-bench-scorer-"
"""A confined scorer's scratch folder is ``<tmp>/cdr-bench-scorer-<build pid>-*``."""


def scorer_box(
    env: dict[str, str], root: str | Path = ".", probe: bool = False
) -> ScorerBox | None:
    """The confinement of one scorer of the repository ``root``, with a new scratch folder (its
    only writable folder, in the temporary folder) and ``env`` as the basis of its environment;
    None where the scorer runs unconfined (:func:`scorer_isolation`)."""
    if not probe and not scorer_isolation(str(Path(root).resolve()))[0]:
        return None
    exe = shutil.which("bwrap")
    if exe is None:
        return None
    import tempfile

    remove_stale_scratch(prefix=SCRATCH_PREFIX)
    scratch = Path(tempfile.mkdtemp(prefix=f"{SCRATCH_PREFIX}{os.getpid()}-")).resolve()
    home, tmp = scratch / "home", scratch / "tmp"
    home.mkdir()
    tmp.mkdir()
    cache = scratch / "numba-cache"
    seed_numba_cache(cache)
    cgroup = _delegated_cgroup() if cgroup_support() is not None and os.geteuid() == 0 else None
    mb = 1024 * 1024
    prefix = [exe, "--ro-bind", "/", "/", "--dev", "/dev", "--bind", "/proc", "/proc"]
    prefix += ["--size", str(SHM_MB * mb), "--tmpfs", "/dev/shm"]
    prefix += ["--bind", str(scratch), str(scratch)]
    if cgroup_support() is not None:
        prefix += ["--bind", "/sys/fs/cgroup", "/sys/fs/cgroup"]
    prefix += ["--unshare-user", "--uid", str(SANDBOX_UID), "--gid", str(SANDBOX_UID)]
    prefix += ["--unshare-net", "--unshare-ipc", "--unshare-uts"]
    prefix += ["--die-with-parent", "--new-session"]
    box_env = {
        **env,
        "HOME": str(home),
        "TMPDIR": str(tmp),
        "NUMBA_CACHE_DIR": str(cache),
        "PYTHONDONTWRITEBYTECODE": "1",
        "MPLCONFIGDIR": str(home),
    }
    return ScorerBox(prefix, box_env, cgroup, scratch)


@lru_cache(maxsize=4)
def scorer_isolation(root: str = ".") -> tuple[bool, str]:
    """``(confined, description)``: whether the scorer runs confined here, i.e. a probe scorer
    started as :func:`scorer_box` says reports the same agent isolation and control-group
    support as this process has, and can read the repository ``root``."""
    if isolation()[0] != "bwrap":
        return False, "scorer NOT confined (isolated mode only): bubblewrap cannot start here"
    want = f"bwrap {cgroup_support()} True"
    box = scorer_box({"PATH": os.environ.get("PATH", "/usr/bin:/bin")}, root, probe=True)
    if box is None:
        return False, "scorer NOT confined (isolated mode only): bubblewrap is not installed"
    code = f"{_PROBE}, os.access({str(Path(root).resolve())!r}, os.R_OK | os.X_OK))"
    try:
        r = subprocess.run(
            [*box.prefix, sys.executable, "-I", "-c", code],
            capture_output=True,
            text=True,
            timeout=120,
            env=box.env,
            preexec_fn=child_setup(None, cgroup=box.cgroup),
        )
        got, why = r.stdout.strip(), clean(r.stderr, 1) or r.stdout.strip()
    except (OSError, subprocess.TimeoutExpired) as e:
        got, why = "", str(e)
    finally:
        box.close()
    if got == want:
        return True, (
            "scorer confined (bubblewrap: everything read-only but its scratch folder, no "
            "network, no capability, its agents confined as said)"
        )
    return False, (
        "scorer NOT confined (isolated mode only): a confined scorer would not confine its "
        f"agents the same way here or cannot read the repository ({why or 'no answer'})"
    )
