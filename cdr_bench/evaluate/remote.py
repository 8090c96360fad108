"""The evaluator's side of the process boundary: the agent runs in its own process.

:class:`AgentProcess` starts ``python -m cdr_bench.evaluate.agent_host AGENT_FILE`` (confined by
:mod:`.sandbox` when asked) and talks to it over two pipes. The agent process receives
observation and mask arrays and returns action arrays; it never holds the simulator, the runner
or a result file, so an agent cannot reach the scorer's memory (stack frames, monkeypatching)
and the evaluator's numbers are computed where the agent's code does not run.

Everything that comes back is untrusted: a reply must be exactly the frame the request expects
(status ``K`` with ``8 n`` bytes of little-endian int64 actions, each in 0..26, or status ``E``
with a small JSON error), otherwise the run stops with "broke the protocol". Time limits are
enforced here, from outside the agent's process, with ``select`` on the pipes: loading and
construction (``load_timeout_s``) and every decision (``decision_timeout_s``); a process that
exceeds one is killed with its whole process group, one that dies or exits is reported with its
exit status. Nothing the agent does (catching ``BaseException``, ignoring signals, an endless
generator, ``sys.exit``) can disable a limit.

Frames: request ``op (1 byte) | length (uint32 LE) | payload``; reply ``status | length |
payload``. Payloads: ``C`` handle, obs_dim (uint32) and the observation bounds (2 obs_dim
float32); ``R`` handle (uint32), seed (uint64); ``A``/``L`` handle, n (uint32), observations
(n obs_dim float32), masks (n 27 int8).
"""

from __future__ import annotations

import errno
import json
import math
import os
import select
import shutil
import signal
import struct
import subprocess
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cdr_bench.actions import N_ACTIONS
from cdr_bench.evaluate.loader import (
    CHECKPOINT_ENV,
    AgentError,
    agent_files,
    agent_name,
    resolve_agent_path,
)
from cdr_bench.evaluate.sandbox import (
    Cgroup,
    Confined,
    Confinement,
    Limits,
    child_setup,
    clean,
    confined,
    make_cgroup,
    make_scratch,
    nproc_limit,
    seed_numba_cache,
    tail,
)

DEFAULT_LOAD_TIMEOUT_S = 300.0
DEFAULT_DECISION_TIMEOUT_S = 10.0
MAX_TIMEOUT_S = 86400.0
_HEAD = struct.Struct("<cI")
_MAX_ERROR_BYTES = 16384
Rows = NDArray[Any]
"""One array per row of a decision (observations, masks, episode or aircraft index, actions)."""
SPIN_S = 0.001
"""How long each side polls its pipe before it sleeps in ``select``: a decision or a step that
takes less is picked up without the sleep and wake-up (0.1-0.4 ms per round trip here), at the
cost of at most this much CPU per call."""
ONE_THREAD = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
"""Thread counts of an agent's process unless the caller's environment sets them: one per
process (torch, MKL and OpenBLAS read them at import), as the sandbox's child has."""


def check_timeout(name: str, value: float) -> float:
    """``value`` if it is a usable time limit (finite, > 0, at most a day), else a UserError:
    a limit can be set but never disabled by a bad value."""
    if not isinstance(value, (int, float)) or not math.isfinite(value) or not value > 0:
        raise AgentError(f"{name}: expected a number of seconds > 0, got {value!r}")
    if value > MAX_TIMEOUT_S:
        raise AgentError(f"{name}: at most {MAX_TIMEOUT_S:g} s, got {value:g}")
    return float(value)


@dataclass(frozen=True)
class AgentOptions:
    """How the evaluator runs an agent (picklable: worker processes and Ray tasks get it)."""

    confinement: Confinement | None = None
    """``None``: own process only (plain ``evaluate``); else confined (:mod:`.sandbox`)."""
    limits: Limits | None = None
    """CPU and memory limits of the agent process (``None``: none)."""
    load_timeout_s: float = DEFAULT_LOAD_TIMEOUT_S
    decision_timeout_s: float = DEFAULT_DECISION_TIMEOUT_S


class AgentFault(Exception):
    """The agent misbehaved during a request: ``kind`` is ``raised``, ``invalid``, ``timeout``,
    ``died`` or ``protocol``; ``row`` the row of the batch it concerns (-1: unknown)."""

    def __init__(self, kind: str, message: str, row: int = -1):
        super().__init__(message)
        self.kind, self.message, self.row = kind, message, row


class AgentProcess:
    """One agent process. :meth:`instance` constructs an ``Agent`` for a scenario's spaces."""

    def __init__(self, agent_path: str | os.PathLike[str], options: AgentOptions):
        self.path = resolve_agent_path(agent_path)
        self.name = agent_name(agent_path)
        self.options = options
        self.log: Path | None = None
        self._scratch: Path | None = None
        self._handles: dict[tuple[int, bytes], RemoteAgent] = {}
        # -P: no folder of the caller (the current folder, a json.py there) on the import path
        argv = [sys.executable, "-P", "-m", "cdr_bench.evaluate.agent_host", str(self.path)]
        self._scratch = make_scratch()
        self._cgroup: Cgroup | None = None
        # One thread per agent process (the evaluator runs one per worker), as in the sandbox;
        # a thread count the caller sets in the environment wins.
        env: dict[str, str] = {**ONE_THREAD, **os.environ, "TMPDIR": str(self._scratch)}
        stderr: Any = None  # plain evaluate: the agent's output goes to the terminal
        box: Confined | None = None
        nproc = None
        if options.confinement is not None:
            self.log = self._scratch / "agent-output.log"
            seed = self._scratch / "numba-seed"
            seed_numba_cache(seed)
            ck = os.environ.get(CHECKPOINT_ENV)
            extra = {CHECKPOINT_ENV: ck} if ck else {}
            files = [str(f) for f in agent_files(self.path, ck or None)]
            files += [ck] if ck else []
            conf = replace(options.confinement, files=tuple(files))
            home = self._scratch / "home"  # a size-capped tmpfs in the sandbox
            home.mkdir()
            box = confined(argv, conf, home, extra, numba_seed=seed)
            argv, env = box.argv, box.env
            stderr = open(self.log, "wb")  # noqa: SIM115 - closed right after the start
            nproc = nproc_limit()
            self._cgroup = make_cgroup(options.limits)
        try:
            self.proc = subprocess.Popen(
                argv,
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=stderr,
                env=env,
                start_new_session=True,
                pass_fds=box.pass_fds if box is not None else (),
                preexec_fn=child_setup(options.limits, nproc, self._cgroup),
            )
        except OSError as e:
            self._cleanup()
            raise AgentError(f"agent {self.name}: cannot start its process ({e})") from None
        finally:
            if stderr is not None:
                stderr.close()
            if box is not None:
                box.close()
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self._w, self._r = self.proc.stdin.fileno(), self.proc.stdout.fileno()
        os.set_blocking(self._w, False)
        os.set_blocking(self._r, False)
        try:
            self._request(b"", b"", 0, options.load_timeout_s, "loading")
        except AgentFault as f:
            self.close()
            raise AgentError(self._load_message(f)) from None

    # ------------------------------------------------------------------------------------------

    def instance(self, obs_low: NDArray[np.float32], obs_high: NDArray[np.float32]) -> RemoteAgent:
        """The agent constructed for observations bounded by ``obs_low``/``obs_high`` (one
        instance per distinct space, as the evaluator always did)."""
        low = np.ascontiguousarray(obs_low, dtype="<f4")
        high = np.ascontiguousarray(obs_high, dtype="<f4")
        key = (low.size, low.tobytes() + high.tobytes())
        if key not in self._handles:
            handle = len(self._handles)
            payload = struct.pack("<II", handle, low.size) + key[1]
            try:
                flags = self._request(b"C", payload, 1, self.options.load_timeout_s, "construction")
            except AgentFault as f:
                self.close()
                raise AgentError(self._load_message(f)) from None
            self._handles[key] = RemoteAgent(self, handle, low.size, joint=flags == b"\x01")
        return self._handles[key]

    def _load_message(self, f: AgentFault) -> str:
        if f.kind == "load":
            return f.message
        if f.kind == "timeout":
            return (
                f"agent {self.name}: loading did not finish within {self.options.load_timeout_s:g} "
                f"s (killed; --load-timeout sets the limit){self.output()}"
            )
        return f"agent {self.name}: {f.message} while loading{self.output()}"

    def output(self) -> str:
        """The last lines the confined agent printed, for a message ('' when not captured)."""
        if self.log is None:
            return ""
        text = clean(tail(self.log), 8)
        return "\n  last output of the agent:\n    " + text.replace("\n", "\n    ") if text else ""

    # ------------------------------------------------------------------------------------------

    def _request(
        self, op: bytes, payload: bytes, reply_len: int, timeout: float, what: str
    ) -> bytes:
        """Send a request (``op`` empty: none, wait for the greeting) and return the payload of
        a ``K`` reply of exactly ``reply_len`` bytes. Raises :class:`AgentFault`."""
        if self.proc.poll() is not None and not op == b"":
            raise AgentFault("died", self._death())
        deadline = time.monotonic() + timeout
        if op:
            self._send(_HEAD.pack(op, len(payload)) + payload, deadline, what)
        status, size = _HEAD.unpack(self._recv(_HEAD.size, deadline, what))
        if status == b"K":
            if size != reply_len:
                raise AgentFault(
                    "protocol",
                    f"the agent process broke the protocol ({size} bytes, expected {reply_len})",
                )
            return self._recv(size, deadline, what)
        if status == b"E" and size <= _MAX_ERROR_BYTES:
            body = self._recv(size, deadline, what)
            try:
                err = json.loads(body.decode("utf-8"))
                kind, row, message = str(err["kind"]), int(err["row"]), str(err["message"])
            except (ValueError, KeyError, TypeError, UnicodeDecodeError):
                raise AgentFault("protocol", "the agent process broke the protocol") from None
            if kind not in ("load", "raised", "invalid"):
                kind = "protocol"
            return self._raise(kind, clean(message, 6, 400), row)
        raise AgentFault("protocol", "the agent process broke the protocol (bad reply header)")

    @staticmethod
    def _raise(kind: str, message: str, row: int) -> bytes:
        raise AgentFault(kind, message, row)

    def _send(self, data: bytes, deadline: float, what: str) -> None:
        view = memoryview(data)
        while view:
            left = deadline - time.monotonic()
            if left <= 0:
                self._timeout(what)
            _, writable, _ = select.select([], [self._w], [], left)
            if not writable:
                continue
            try:
                n = os.write(self._w, view)
            except BlockingIOError:
                continue
            except OSError as e:
                if e.errno in (errno.EPIPE, errno.EBADF):
                    raise AgentFault("died", self._death()) from None
                raise
            view = view[n:]

    def _recv(self, n: int, deadline: float, what: str) -> bytes:
        buf = bytearray()
        spin_until = time.perf_counter() + SPIN_S
        while len(buf) < n:
            left = deadline - time.monotonic()
            if left <= 0:
                self._timeout(what)
            try:
                chunk = os.read(self._r, n - len(buf))
            except BlockingIOError:
                if time.perf_counter() < spin_until:
                    continue  # a short decision: answered before a sleep and wake-up would be
                select.select([self._r], [], [], left)
                continue
            if not chunk:
                raise AgentFault("died", self._death())
            buf += chunk
        return bytes(buf)

    def _timeout(self, what: str) -> None:
        self._kill()
        raise AgentFault("timeout", f"{what} exceeded the time limit (killed)")

    def _death(self) -> str:
        try:
            code = self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self._kill()
            return "the agent process closed its output (killed)"
        self._kill()  # whatever it started
        confined = self.options.confinement is not None
        if code < 0 or (confined and code > 128):
            sig = -code if code < 0 else code - 128
            try:
                name = signal.Signals(sig).name
            except ValueError:
                name = f"signal {sig}"
            why = {
                "SIGXCPU": "the CPU time limit",
                "SIGKILL": "SIGKILL: out of memory, or the CPU hard limit",
                "SIGSEGV": "a crash in native code",
            }.get(name, name)
            return f"the agent process was killed ({why}){self.output()}"
        if code == 0:
            why = "exit code 0: sys.exit or os._exit in the agent"
            return f"the agent process exited ({why}){self.output()}"
        return f"the agent process exited with code {code}{self.output()}"

    def _kill(self) -> None:
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:  # pragma: no cover - SIGKILL does not fail
            pass

    def close(self) -> None:
        """Stop the agent process and everything it started."""
        if self.proc.poll() is None:
            try:
                os.set_blocking(self._w, True)
                os.write(self._w, _HEAD.pack(b"Q", 0))
            except OSError:
                pass
        for f in (self.proc.stdin, self.proc.stdout):
            try:
                if f is not None:
                    f.close()
            except OSError:
                pass
        try:  # no need to wait for a graceful exit (interpreter teardown takes ~1 s with torch)
            self.proc.wait(timeout=0.05)
        except subprocess.TimeoutExpired:
            pass
        self._kill()
        self._cleanup()

    def _cleanup(self) -> None:
        if self._cgroup is not None:
            self._cgroup.close()
            self._cgroup = None
        if self._scratch is not None:
            shutil.rmtree(self._scratch, ignore_errors=True)
            self._scratch = None


class RemoteAgent:
    """One ``Agent`` instance inside an :class:`AgentProcess`: the surface the runner and the
    analyses use (``act_batch``, ``reset``; :class:`AgentFault` on misbehaviour)."""

    def __init__(self, process: AgentProcess, handle: int, obs_dim: int, joint: bool = False):
        self.process, self.handle, self.obs_dim = process, handle, obs_dim
        self.name, self.path = process.name, process.path
        self.joint = joint
        """the agent defines ``act_joint``: the evaluator asks it for the aircraft of each
        episode together (:meth:`act_joint`) instead of row by row"""

    def reset(self, seed: int) -> None:
        p = self.process
        p._request(
            b"R",
            struct.pack("<IQ", self.handle, int(seed)),
            0,
            p.options.decision_timeout_s,
            "reset(seed)",
        )

    def _payload(self, obs: NDArray[np.float32], masks: NDArray[np.int8]) -> bytes:
        n = obs.shape[0]
        return (
            struct.pack("<II", self.handle, n)
            + np.ascontiguousarray(obs, dtype="<f4").tobytes()
            + np.ascontiguousarray(masks, dtype=np.int8).tobytes()
        )

    def act_batch(self, obs: NDArray[np.float32], masks: NDArray[np.int8]) -> NDArray[np.int64]:
        """(n,) actions in 0..26 for (n, F) observations and (n, 27) masks."""
        n = obs.shape[0]
        p = self.process
        data = p._request(
            b"A", self._payload(obs, masks), 8 * n, p.options.decision_timeout_s, "a decision"
        )
        actions = np.frombuffer(data, "<i8").astype(np.int64)
        bad = np.flatnonzero((actions < 0) | (actions >= N_ACTIONS))
        if bad.size:
            raise AgentFault(
                "protocol", "the agent process broke the protocol (action out of range)"
            )
        return actions

    def act_joint(self, obs: Rows, masks: Rows, episodes: Rows, aircraft: Rows) -> Rows:
        """(n,) actions for the rows of whole episodes: ``episodes`` (n,) says which episode of
        the call each row belongs to (rows of an episode together), ``aircraft`` (n,) which of
        its controlled aircraft it is (0: the ownship)."""
        n = obs.shape[0]
        p = self.process
        rows = np.concatenate([episodes, aircraft]).astype("<i4").tobytes()
        data = p._request(
            b"J", self._payload(obs, masks) + rows, 8 * n, p.options.decision_timeout_s,
            "a joint decision",
        )  # fmt: skip
        actions = np.frombuffer(data, "<i8").astype(np.int64)
        if ((actions < 0) | (actions >= N_ACTIONS)).any():
            raise AgentFault(
                "protocol", "the agent process broke the protocol (action out of range)"
            )
        return actions

    def localise(self, obs: NDArray[np.float32], masks: NDArray[np.int8]) -> AgentFault | None:
        """After ``act_batch`` raised on a batch: the fault of the first row that raises on its
        own (``None`` if none does, or if finding it fails)."""
        p = self.process
        try:
            p._request(
                b"L", self._payload(obs, masks), 0, p.options.decision_timeout_s, "localising"
            )
        except AgentFault as f:
            return f if f.kind == "raised" else None
        return None
