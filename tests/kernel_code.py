"""The machine code of the numba kernels: no fused multiply-add, no call of a libm function.

A fused multiply-add rounds once where the source rounds twice, and libm's transcendental
functions differ between CPUs and glibc versions: either would make the simulator's or the
inference path's bits depend on the CPU (docs/model.md §12). numba compiles without fastmath, so
LLVM may not fuse; this reads the code actually generated on this machine. numba can show only
code it compiled in this process (not code loaded from its cache), so the caller compiles the
kernels afresh first (an empty ``NUMBA_CACHE_DIR``, or a fresh clone as in CI).

Used by ``tests/sim/test_kernels.py``, ``tests/leaderboard/test_cpu_independence.py`` and
``.ci/warm_kernels.py`` (which compiles every kernel afresh on CI's fresh clone anyway and
inspects them there; CI then tells the two tests, which would compile them a second time for
the same inspection, that it is done: :data:`INSPECTED_ENV`).
"""

from __future__ import annotations

import re
import warnings
from types import ModuleType

FMA = re.compile(r"\bv?fn?m(add|sub)[0-9a-z]*\b")
LIBM_CALL = re.compile(r"call.*\b(sin|cos|tan|exp|log|atan2?|pow)\b")
INSPECTED_ENV = "CDR_BENCH_KERNELS_INSPECTED_BY"
"""Set (by ``.ci/run``) when ``.ci/warm_kernels.py`` has inspected the machine code of every
kernel it compiled: the tests skip their own inspection, which would compile them again."""


class CachedCode(Exception):
    """A kernel was loaded from numba's cache: its machine code cannot be inspected."""


def inspect_module(module: ModuleType) -> dict[str, list[str]]:
    """``{kernel and signature: problems}`` for every kernel of ``module`` compiled in this
    process (problems: fused multiply-adds, libm calls; empty list: clean). Raises
    :class:`CachedCode` if one was loaded from the cache."""
    from numba.core.registry import CPUDispatcher

    out: dict[str, list[str]] = {}
    for name, obj in sorted(vars(module).items()):
        if not isinstance(obj, CPUDispatcher):
            continue
        for sig in obj.signatures:
            with warnings.catch_warnings():
                warnings.simplefilter("error")  # "inspection disabled for cached code"
                try:
                    asm = obj.inspect_asm(sig)
                except Warning as e:
                    raise CachedCode(f"{module.__name__}.{name}{sig}: {e}") from None
            problems = [f"fused multiply-add {m.group(0)}" for m in FMA.finditer(asm)]
            problems += [f"libm call {m.group(1)}" for m in LIBM_CALL.finditer(asm)]
            out[f"{module.__name__}.{name}{sig}"] = problems
    return out
