"""Checks of what a user gives a command: the one argparse ``type`` of every numeric flag
(:func:`ranged`, with the caps below), and the reading of an input file (:func:`read_input`:
a regular file, at most so many bytes). Every failure is one line naming the flag or the file
and what was expected; nothing here waits on a pipe or reads an unbounded stream.

A flag's value is checked when the flags are parsed (argparse prints ``argument --flag:
expected a value in [1, 100000], got 0`` and exits with code 2), so a command never starts on
a value it cannot use: NaN, an infinity where the range is finite, a negative count, or a size
that would exhaust memory before the first result.
"""

from __future__ import annotations

import argparse
import math
import os
import stat
from collections.abc import Callable
from pathlib import Path

from cdr_bench.errors import UserError

_INF = math.inf

MAX_EPISODES = 100_000
"""Episodes per scenario a command runs (100 times the paper's 1000): every episode's record is
kept in memory and in the per-episode log (about 1 KB each)."""
MAX_BATCH_SIZE = 10_000
"""Episodes stepped in lock-step in one batch (about 35 KB of simulator state each)."""
MAX_SEED = 2**63 - 1
"""Largest base seed (seeds are integers in 0..2**63-1)."""
MAX_WORKERS = 512
"""Most worker processes a command starts."""
MAX_STEPS = 1_000_000
"""Largest step or frame count a flag may give."""

MAX_RESULT_BYTES = 64 << 20
"""Largest result JSON read (the committed ones are a few tens of KB)."""
MAX_EPISODE_LOG_BYTES = 1 << 30
"""Largest per-episode log read, uncompressed (1000 episodes of six scenarios: about 6 MB)."""
MAX_CONFIG_BYTES = 1 << 20
"""Largest sweep file read (as a scenario file)."""


def _num(x: float) -> str:
    if x in (_INF, -_INF):
        return "inf" if x > 0 else "-inf"
    if isinstance(x, int) or (float(x).is_integer() and abs(x) < 1e18):
        return str(int(x))
    return f"{x:g}"


def ranged(
    kind: type,
    low: float = -_INF,
    high: float = _INF,
    *,
    low_in: bool = True,
    inf_ok: bool = False,
) -> Callable[[str], int | float]:
    """The argparse ``type`` of a numeric flag: the text as ``kind`` (``int`` or ``float``),
    then a value in ``low..high`` (``low`` itself only with ``low_in``); NaN is never accepted,
    an infinity only with ``inf_ok``. Otherwise argparse's one-line error, with the range::

        p.add_argument("--episodes", type=ranged(int, 1, MAX_EPISODES))
        p.add_argument("--timeout", type=ranged(float, 0, 86400, low_in=False))
    """

    def parse(text: str) -> int | float:
        try:
            v = kind(text)
        except (ValueError, OverflowError):
            what = "a whole number" if kind is int else "a number"
            raise argparse.ArgumentTypeError(f"expected {what}, got {text[:40]!r}") from None
        ok = v == v and (v > low if not low_in else v >= low) and v <= high
        if kind is float and not inf_ok and abs(v) == _INF:
            ok = False
        if not ok:
            lo_b = "[" if low_in else "("
            hi_b = "]" if high != _INF or inf_ok else ")"
            raise argparse.ArgumentTypeError(
                f"expected a value in {lo_b}{_num(low)}, {_num(high)}{hi_b}, got {text[:40]}"
            )
        return v

    parse.__name__ = kind.__name__  # argparse names the type in its "invalid ..." message
    return parse


def int_list(low: int, high: int) -> Callable[[str], list[int]]:
    """The argparse ``type`` of a comma-separated list of whole numbers in ``low..high``
    (``--batch-sizes 1,8,64``)."""
    one = ranged(int, low, high)

    def parse(text: str) -> list[int]:
        items = text.split(",")
        if not text or len(items) > 100:
            raise argparse.ArgumentTypeError(
                f"expected 1 to 100 whole numbers separated by commas, got {text[:40]!r}"
            )
        return [int(one(x.strip())) for x in items]

    parse.__name__ = "list of integers"
    return parse


def file_kind(mode: int) -> str | None:
    """``None`` for a regular file's ``st_mode``, else what it is (``a folder``, ...)."""
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISFIFO(mode):
        return "a named pipe (FIFO)"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def read_input(path: str | os.PathLike[str], cap: int, what: str = "file") -> bytes:
    """The bytes of the input file ``path``: a regular file (a device, a pipe, a folder or a
    socket is refused before it is opened, so nothing blocks) of at most ``cap`` bytes. A
    :class:`UserError` naming ``path`` otherwise (``what`` says what the file should be)."""
    p = Path(path)
    try:
        st = p.stat()
    except FileNotFoundError:
        raise UserError(f"{p}: no such {what}") from None
    except OSError as e:
        raise UserError(f"{p}: cannot read it ({e.strerror or e})") from None
    kind = file_kind(st.st_mode)
    if kind is not None:
        raise UserError(f"{p}: is {kind}, not a {what}")
    if st.st_size > cap:
        raise UserError(f"{p}: {st.st_size} bytes, larger than a {what} may be ({cap} bytes)")
    try:
        fd = os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0))
        with os.fdopen(fd, "rb") as f:
            if file_kind(os.fstat(f.fileno()).st_mode) is not None:  # replaced since the stat
                raise UserError(f"{p}: not a regular file, not a {what}")
            data = f.read(cap + 1)
    except OSError as e:
        raise UserError(f"{p}: cannot read it ({e.strerror or e})") from None
    if len(data) > cap:
        raise UserError(f"{p}: larger than a {what} may be ({cap} bytes)")
    return data
