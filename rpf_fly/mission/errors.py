"""The one exception a mission file can raise: where it is wrong, and what is wrong there."""

from __future__ import annotations

from pathlib import Path


class MissionError(Exception):
    """A mission file (or a command-line override of it) is invalid.

    ``file`` is the path as given (``<string>`` for text without a file), ``line`` is 1-based (0 when the problem
    is not on a line of the file, e.g. an unreadable file or a ``--planner`` option), ``field`` is a dotted path
    such as ``drones[2].start``, ``planner.kind``, ``(file)`` for the file as a whole, or a command-line option such
    as ``--planner``. ``str(err)`` is the single line ``FILE:LINE: FIELD: message``.
    """

    def __init__(self, file: str | Path, line: int, field: str, message: str):
        super().__init__(str(file), line, field, message)
        self.file = str(file)
        self.line = int(line)
        self.field = field
        self.message = " ".join(str(message).split("\n"))

    def __str__(self) -> str:
        return f"{self.file}:{self.line}: {self.field}: {self.message}"
