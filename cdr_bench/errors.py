"""The exceptions every layer raises for a user's mistake (the bottom of the import graph).

A :class:`UserError` is a mistake in what the user gave (a file, a field, a flag, an agent): its
message is one line naming the file or field and what was expected. The command line catches
it, prints the message and exits with code 2, never a traceback. Lower layers raise it; only
``cdr_bench.cli`` catches it. Values quoted in a message go through :func:`short_repr`, so a
message stays short whatever the value (a huge number, a deeply nested list, a long string).
"""

from __future__ import annotations

import re
import reprlib
from collections.abc import Sequence
from typing import Any

MAX_QUOTED_CHARS = 80
"""A value quoted in an error message is cut to this many characters."""

MAX_LISTED_PROBLEMS = 20
"""A :class:`ScenarioError` with more problems lists this many and counts the rest."""


class UserError(Exception):
    """A user error: printed as one line, exit code 2."""


class ScenarioError(UserError, ValueError):
    """A scenario file or mapping is invalid.

    The message names the source (file), the dotted field path and what was expected. A file
    with several problems gives them all (``problems``: (field path, message) pairs), one per
    line after a first line ``SOURCE: N errors:``.
    """

    def __init__(
        self,
        source: str,
        path: str,
        message: str,
        *,
        more: Sequence[tuple[str, str]] = (),
    ):
        self.source = source
        self.path = path
        self.message = message
        self.problems: list[tuple[str, str]] = [(path, message), *more]
        where = f"{source}: " if source else ""
        if len(self.problems) == 1:
            super().__init__(f"{where}{_field_part(path)}{message}")
            return
        lines = [f"{where}{len(self.problems)} errors:"]
        lines += [f"  {_field_part(p)}{m}" for p, m in self.problems[:MAX_LISTED_PROBLEMS]]
        if len(self.problems) > MAX_LISTED_PROBLEMS:
            lines.append(f"  ... and {len(self.problems) - MAX_LISTED_PROBLEMS} more")
        super().__init__("\n".join(lines))

    @classmethod
    def of(cls, source: str, problems: Sequence[tuple[str, str]]) -> ScenarioError:
        """One error carrying every (field path, message) problem of ``source``."""
        (path, message), *more = problems
        return cls(source, path, message, more=more)


class ArgumentError(UserError, ValueError):
    """An argument of an environment call (constructor, ``reset``, ``step``) is invalid; the
    message names the argument, what was expected and (shortened) what was given."""


class ActionError(ArgumentError):
    """An action given to an environment's ``step`` is invalid: an unknown agent, a missing
    action, or a value that is not an integer in 0..26. The message names the agent and the
    value."""


class ResetNeeded(UserError, RuntimeError):
    """An environment was stepped (or its episodes ended) before ``reset`` started them: its
    state would be zeros, not an episode."""


def _field_part(path: str) -> str:
    return f"field '{path}': " if path else ""


class _ShortRepr(reprlib.Repr):
    """``reprlib`` with bounded work for every value: it never converts a huge integer to
    text (Python refuses beyond 4300 digits) and looks at a few items of each container only
    (so a structure built from YAML aliases is never expanded)."""

    def __init__(self) -> None:
        super().__init__()
        self.maxlevel = 3
        self.maxlist = self.maxtuple = self.maxset = self.maxfrozenset = self.maxdict = 4
        self.maxstring = MAX_QUOTED_CHARS
        self.maxother = MAX_QUOTED_CHARS

    def repr_int(self, x: int, level: int) -> str:
        if x.bit_length() > 128:
            return f"<an integer of about {int(x.bit_length() * 0.30103) + 1} digits>"
        return repr(x)

    def repr_str(self, x: str, level: int) -> str:
        return repr(x) if len(x) <= self.maxstring else repr(x[: self.maxstring]) + "..."


_SHORT = _ShortRepr()


def short_repr(value: Any, limit: int = MAX_QUOTED_CHARS) -> str:
    """A ``repr`` of ``value`` for an error message: at most ``limit`` characters, computed
    without expanding ``value`` (see :class:`_ShortRepr`); never raises."""
    try:
        text = _SHORT.repr(value)
    except Exception:  # a value whose __repr__ fails still gets a message
        text = f"<{type(value).__name__}>"
    text = re.sub(r"\s*\n\s*", " ", text)  # some reprs (numpy arrays) span lines
    return text if len(text) <= limit else text[: limit - 3] + "..."
