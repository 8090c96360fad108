"""The agent's own process: ``python -m cdr_bench.evaluate.agent_host AGENT_FILE``.

Started by :class:`cdr_bench.evaluate.remote.AgentProcess` (never by a user). It loads the agent,
then answers requests on its standard input with replies on its standard output, both binary
frames (:mod:`.remote` documents the format); the agent's own ``print`` goes to standard error.
It holds nothing but the agent: no simulator, no runner, no result file. Everything here runs
beside untrusted code, so the evaluator checks every reply again (:mod:`.remote`).

Requests: ``C`` construct an ``Agent`` for a space (handle, obs_dim, low, high), ``R`` reset
(handle, seed), ``A`` act (handle, n, observations, masks), ``L`` localise (as ``A``, after ``A``
raised: the first row that raises on its own), ``Q`` quit. Replies: ``K`` + payload, or ``E`` +
a JSON ``{"kind", "row", "message"}``.
"""

from __future__ import annotations

import itertools
import json
import numbers
import os
import struct
import sys
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

from cdr_bench.actions import N_ACTIONS

_HEAD = struct.Struct("<cI")


def _is_int(v: Any) -> bool:
    if isinstance(v, np.ndarray) and v.ndim == 0:
        v = v[()]
    return isinstance(v, numbers.Integral) and not isinstance(v, (bool, np.bool_))


def _describe(value: Any) -> str:
    text = repr(value)
    text = text if len(text) <= 80 else text[:77] + "..."
    return f"{text} ({type(value).__name__})"


def validate_actions(out: Any, n: int) -> tuple[NDArray[np.int64] | None, int, str]:
    """``(actions, -1, "")`` if ``out`` holds ``n`` integers in 0..26, else
    ``(None, row, what)`` naming the first bad row (-1: the shape is wrong) and the value.
    Never consumes more than ``n + 1`` items of an iterator."""
    if isinstance(out, np.ndarray):
        arr = out
    else:
        try:
            it = iter(out)
        except TypeError:
            return None, -1, f"expected {n} action indices, got {_describe(out)}"
        seq = list(itertools.islice(it, n + 1))
        if len(seq) != n:
            more = "more" if len(seq) > n else str(len(seq))
            return None, -1, f"expected {n} action indices, got {more}"
        for i, v in enumerate(seq):
            if not _is_int(v):
                return None, i, f"got {_describe(v)}, expected an integer in 0..{N_ACTIONS - 1}"
        try:
            arr = np.asarray(seq, dtype=np.int64) if seq else np.zeros(0, np.int64)
        except OverflowError:
            big = next(i for i, v in enumerate(seq) if not -(2**63) <= int(v) < 2**63)
            return None, big, f"got {_describe(seq[big])}, expected an integer in 0..26"
    if arr.shape != (n,):
        if arr.size == n and arr.ndim == 2 and arr.shape[1] == 1:
            arr = arr.reshape(n)
        else:
            return None, -1, f"expected {n} action indices, got an array of shape {arr.shape}"
    if arr.dtype == np.bool_ or not np.issubdtype(arr.dtype, np.integer):
        bad = 0
        if np.issubdtype(arr.dtype, np.floating):
            nan = np.flatnonzero(np.isnan(arr))
            bad = int(nan[0]) if nan.size else 0
        v = arr[bad].item() if arr.dtype != object else arr[bad]
        return None, bad, f"got {_describe(v)} (dtype {arr.dtype}), expected an integer in 0..26"
    out_of_range = np.flatnonzero((arr < 0) | (arr >= N_ACTIONS))
    if out_of_range.size:
        i = int(out_of_range[0])
        return None, i, f"got {int(arr[i])}, expected an integer in 0..{N_ACTIONS - 1}"
    return arr.astype(np.int64, copy=False), -1, ""


_PICKLE_MODULES = ("numba", "numpy", "llvmlite")
"""Packages whose globals numba's own compilation cache stores (types, signatures, arrays,
environments): the audit hook lets an unpickler look up globals of these, by plain name."""
_PICKLE_GLOBALS = {("builtins", "object"), ("copyreg", "_reconstructor")}


def _refuse_unpickling(event: str, args: tuple[Any, ...]) -> None:
    """Audit hook of a confined agent process, a convenience and not a boundary (a
    pure-Python unpickler never raises the event; the sandbox is the boundary): a global an
    unpickler looks up must be a plain name in numba's, numpy's or llvmlite's modules (what
    numba's cache of compiled kernels stores), or ``object`` and ``copyreg._reconstructor``;
    anything else (``os.system``, ``builtins.eval``, a class of the agent) is refused with a
    message that says how to load weights without pickle."""
    if event != "pickle.find_class":
        return
    module, name = str(args[0]), str(args[1])
    if (module, name) in _PICKLE_GLOBALS:
        return
    if "." not in name and module.split(".", 1)[0] in _PICKLE_MODULES:
        return
    raise RuntimeError(
        f"refused: unpickling {module[:60]}.{name[:60]} (pickle can run arbitrary code; load "
        "weights with torch.load(weights_only=True), safetensors or numpy without pickle)"
    )


def _seed_numba_cache() -> None:
    """Copy the read-only seed of numba's cache (``CDR_BENCH_NUMBA_SEED``, see
    :func:`cdr_bench.evaluate.sandbox.seed_numba_cache`) into the writable ``NUMBA_CACHE_DIR``
    before the agent is imported."""
    import shutil

    seed, cache = os.environ.get("CDR_BENCH_NUMBA_SEED"), os.environ.get("NUMBA_CACHE_DIR")
    if seed and cache and os.path.isdir(seed):
        try:
            shutil.copytree(seed, cache, dirs_exist_ok=True)
        except OSError:
            pass  # only costs compilation time


class Host:
    def __init__(self, rfile: BinaryIO, wfile: BinaryIO):
        self.rfile, self.wfile = rfile, wfile
        self.agents: dict[int, Any] = {}
        self.dims: dict[int, int] = {}

    # framing --------------------------------------------------------------------------------

    def read_exact(self, n: int) -> bytes:
        import select
        import time

        from cdr_bench.evaluate.remote import SPIN_S

        buf = bytearray()
        fd = self.rfile.fileno()
        spin_until = time.perf_counter() + SPIN_S
        while len(buf) < n:
            try:
                chunk = os.read(fd, n - len(buf))
            except BlockingIOError:  # poll briefly, then sleep until the next request
                if time.perf_counter() >= spin_until:
                    select.select([fd], [], [])
                continue
            if not chunk:
                raise EOFError
            buf += chunk
        return bytes(buf)

    def reply(self, status: bytes, payload: bytes = b"") -> None:
        self.wfile.write(_HEAD.pack(status, len(payload)) + payload)
        self.wfile.flush()

    def error(self, kind: str, message: str, row: int = -1) -> None:
        msg = message if len(message) <= 4000 else message[:3997] + "..."
        body = json.dumps({"kind": kind, "row": row, "message": msg}).encode()
        self.reply(b"E", body)

    # requests -------------------------------------------------------------------------------

    def serve(self, agent_file: str) -> None:
        from cdr_bench.evaluate.loader import AgentError, agent_error_line, load_module

        try:
            self.module = load_module(agent_file)
        except AgentError as e:
            self.error("load", str(e))
            return
        self.reply(b"K")
        self.agent_error_line = agent_error_line
        while True:
            try:
                op, size = _HEAD.unpack(self.read_exact(_HEAD.size))
                payload = self.read_exact(size)
            except EOFError:
                return
            if op == b"Q":
                return
            if op == b"C":
                self.construct(payload)
            elif op == b"R":
                handle, seed = struct.unpack("<IQ", payload)
                try:
                    self.agents[handle].reset(seed)
                except Exception as e:  # noqa: BLE001 - the agent's own error, reported
                    self.error("raised", self.agent_error_line(e, self.agents[handle].path))
                else:
                    self.reply(b"K")
            elif op in (b"A", b"L", b"J"):
                self.act(op, payload)
            else:
                self.error("protocol", f"unknown request {op!r}")

    def construct(self, payload: bytes) -> None:
        from gymnasium import spaces

        from cdr_bench.evaluate.loader import AgentError, construct

        handle, dim = struct.unpack_from("<II", payload)
        bounds = np.frombuffer(payload, np.float32, 2 * dim, offset=8)
        obs_space = spaces.Dict(
            {
                "observation": spaces.Box(bounds[:dim], bounds[dim:], dtype=np.float32),
                "action_mask": spaces.Box(0, 1, (N_ACTIONS,), dtype=np.int8),
            }
        )
        try:
            self.agents[handle] = construct(self.module, obs_space, spaces.Discrete(N_ACTIONS))
        except AgentError as e:
            self.error("load", str(e))
            return
        self.dims[handle] = dim
        self.reply(b"K", b"\x01" if self.agents[handle].joint else b"\x00")

    def act(self, op: bytes, payload: bytes) -> None:
        handle, n = struct.unpack_from("<II", payload)
        dim = self.dims[handle]
        agent = self.agents[handle]
        obs = np.frombuffer(payload, np.float32, n * dim, offset=8).reshape(n, dim).copy()
        masks = np.frombuffer(payload, np.int8, n * N_ACTIONS, offset=8 + 4 * n * dim)
        masks = masks.reshape(n, N_ACTIONS).copy()
        if op == b"J":  # then the episode and the aircraft of each row
            at = 8 + 4 * n * dim + n * N_ACTIONS
            rows = np.frombuffer(payload, "<i4", 2 * n, offset=at).astype(np.int64)
            episodes, aircraft = rows[:n].copy(), rows[n:].copy()
        if op == b"L":
            for i in range(n):
                try:
                    agent.act_batch(obs[i : i + 1], masks[i : i + 1])
                except Exception as e:  # noqa: BLE001
                    self.error("raised", self.agent_error_line(e, agent.path), i)
                    return
            self.reply(b"K")
            return
        try:
            if op == b"J":
                out = agent.act_joint(obs, masks, episodes, aircraft)
            else:
                out = agent.act_batch(obs, masks)
            actions, row, what = validate_actions(out, n)
        except Exception as e:  # noqa: BLE001 - the agent's own error (also from a generator)
            self.error("raised", self.agent_error_line(e, agent.path))
            return
        if actions is None:
            how = "act_joint" if op == b"J" else "act_batch" if agent.has_act_batch else "act"
            self.error("invalid", f"invalid action from {how}: {what}", row)
            return
        self.reply(b"K", actions.astype("<i8").tobytes())


def main() -> int:
    if len(sys.argv) != 2:
        print("usage: python -m cdr_bench.evaluate.agent_host AGENT_FILE", file=sys.stderr)
        return 2
    # The protocol owns the original stdin/stdout; the agent's prints go to stderr.
    rfile = os.fdopen(os.dup(0), "rb", buffering=0)
    os.set_blocking(rfile.fileno(), False)
    wfile = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)
    devnull = os.open(os.devnull, os.O_RDONLY)
    os.dup2(devnull, 0)
    sys.stdout = sys.stderr
    if os.environ.get("CDR_BENCH_CONFINED") == "1":
        _seed_numba_cache()
        sys.addaudithook(_refuse_unpickling)
    Host(rfile, wfile).serve(sys.argv[1])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
