"""Files the package ships: the scenario registry and the built-in reference agents.

They are edited in the repository, in ``scenarios/`` and ``agents/<name>/agent.py``. Building an
sdist or a wheel copies them into the package as ``cdr_bench/_data/scenarios/`` and
``cdr_bench/_data/agents/<name>/agent.py`` (``setup.py`` reads :data:`SHIPPED`): an installed
wheel reads its own copies; a source checkout (an editable install, or ``python -m cdr_bench``
run in it) reads the repository's files where they are edited. This module imports only the
standard library (``setup.py`` runs it before any dependency is installed).
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

BUILTIN_AGENTS = ("direct", "mvp", "random")
"""Reference agents shipped in the package, named without a path (``cdr-bench evaluate mvp``):
the repository's ``agents/<name>/agent.py``, byte for byte (same agent identity hash)."""

SHIPPED = ("scenarios/**/*.yaml", *(f"agents/{name}/agent.py" for name in BUILTIN_AGENTS))
"""What ``setup.py`` puts in the sdist and copies into ``cdr_bench/_data/`` of the wheel: glob
patterns relative to the repository root; each file keeps its path below ``_data``
(``scenarios/high.yaml`` is ``cdr_bench/_data/scenarios/high.yaml`` in the wheel)."""

_CHECKOUT = Path(__file__).resolve().parent.parent.parent


def data_dir(name: str) -> Path:
    """The shipped folder ``name`` (``scenarios``, ``agents``): the package's copy in an
    installed wheel, else the repository's folder beside the package (a source checkout)."""
    packaged = files(__name__) / name
    if isinstance(packaged, Path) and packaged.is_dir():
        return packaged
    checkout = _CHECKOUT / name
    return checkout if checkout.is_dir() else Path(str(packaged))
