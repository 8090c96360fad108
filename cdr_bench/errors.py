"""The exceptions every layer raises for a user's mistake (the bottom of the import graph).

A :class:`UserError` is a mistake in what the user gave (a file, a field, a flag, an agent): its
message is one line naming the file or field and what was expected. The command line catches
it, prints the message and exits with code 2, never a traceback. Lower layers raise it; only
``cdr_bench.cli`` catches it.
"""

from __future__ import annotations


class UserError(Exception):
    """A user error: printed as one line, exit code 2."""


class ScenarioError(UserError, ValueError):
    """A scenario file or mapping is invalid.

    The message names the source (file), the dotted field path and what was expected.
    """

    def __init__(self, source: str, path: str, message: str):
        self.source = source
        self.path = path
        self.message = message
        where = f"{source}: " if source else ""
        field_part = f"field '{path}': " if path else ""
        super().__init__(f"{where}{field_part}{message}")
