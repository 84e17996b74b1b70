"""How the application layer refuses a request: one exception carrying the line the user reads and the exit code.

The commands print it (``rpf_fly/cli/errors.py``: one line on stderr, never a traceback); a test or a tool calling
the application layer gets the same line as a value.
"""

from __future__ import annotations


class UserError(Exception):
    """A request refused before or while it ran: ``str(err)`` is the one line to show, :attr:`code` the exit code
    (2: an invalid mission, option or file, the default; 1: the flight could not start, e.g. no mocap)."""

    def __init__(self, message: str, code: int = 2) -> None:
        super().__init__(message)
        self.code = code
