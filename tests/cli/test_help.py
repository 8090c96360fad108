"""Every ``--help`` of the CLI renders (a stray ``%`` in a help string is an argparse format
directive: ``cdr-bench --help`` once ended in a traceback on "95 % intervals")."""

from __future__ import annotations

import argparse
import subprocess
import sys

from cdr_bench.cli import build_parser


def _parsers(p: argparse.ArgumentParser, path: tuple[str, ...] = ()):
    yield path, p
    for a in p._actions:
        if isinstance(a, argparse._SubParsersAction):
            for name, sub in a.choices.items():
                yield from _parsers(sub, (*path, name))


def test_every_help_text_renders() -> None:
    seen = 0
    for path, p in _parsers(build_parser()):
        text = p.format_help()
        assert "usage:" in text, path
        seen += 1
    assert seen > 10


def test_top_level_help_exits_zero() -> None:
    """``python -m cdr_bench`` itself (its own process: the entry module, nothing on stderr)."""
    r = subprocess.run(
        [sys.executable, "-m", "cdr_bench", "--help"], capture_output=True, text=True, timeout=600
    )  # the timeout only guards against a hang: seconds here, a minute on a loaded machine
    assert r.returncode == 0 and "evaluate" in r.stdout and not r.stderr, r.stderr
