"""One build step on top of pyproject.toml: ship the scenarios and the reference agents.

They are edited where the repository's layout puts them (``scenarios/``, ``agents/<name>/``);
the sdist lists them and the wheel gets a copy in ``cdr_bench/_data/`` (the patterns are
``cdr_bench._data.SHIPPED``), so an installed wheel needs no checkout. Editable installs copy
nothing: the package reads the checkout's files (``cdr_bench._data.data_dir``).
"""

from __future__ import annotations

import runpy
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent
DATA = "cdr_bench/_data"


def shipped_files(root: Path = ROOT) -> list[str]:
    """The shipped files, relative to ``root`` (POSIX paths, sorted); an error if a pattern of
    ``SHIPPED`` matches nothing (a wheel without its scenarios would be broken)."""
    patterns = runpy.run_path(str(root / DATA / "__init__.py"))["SHIPPED"]
    out: set[str] = set()
    for pattern in patterns:
        found = [p.relative_to(root).as_posix() for p in root.glob(pattern) if p.is_file()]
        if not found:
            raise FileNotFoundError(f"{pattern!r} (cdr_bench._data.SHIPPED) matches no file")
        out.update(found)
    return sorted(out)


class BuildPyShipped(build_py):
    """``build_py`` that also copies :func:`shipped_files` into ``cdr_bench/_data/``."""

    def _shipped(self) -> list[tuple[str, str]]:
        return [(rel, str(Path(self.build_lib, DATA, rel))) for rel in shipped_files()]

    def run(self) -> None:
        super().run()
        if self.editable_mode:
            return
        for rel, target in self._shipped():
            self.mkpath(str(Path(target).parent))
            self.copy_file(str(ROOT / rel), target, preserve_mode=False)

    def get_source_files(self) -> list[str]:  # what the sdist holds
        return [*super().get_source_files(), *shipped_files()]

    def get_outputs(self, include_bytecode: bool = True) -> list[str]:  # type: ignore[override]
        extra = [] if self.editable_mode else [t for _, t in self._shipped()]
        return [*super().get_outputs(include_bytecode), *extra]


if __name__ == "__main__":  # setuptools' build backend runs this file as __main__
    setup(cmdclass={"build_py": BuildPyShipped})
