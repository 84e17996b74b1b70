"""How commands report a user error: one line on stderr and exit code 2, never a traceback."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import typer

if TYPE_CHECKING:
    from rpf_fly.log.reader import LogData


def fail(message: str, code: int = 2) -> "typer.Exit":
    """Print ``message`` as one line on stderr and return the Exit to raise."""
    typer.echo(" ".join(str(message).split("\n")), err=True)
    return typer.Exit(code)


def read_log_or_fail(log: Path) -> "LogData":
    """The flight log at ``log``, read; an unreadable or malformed file is a one-line user error naming it."""
    from rpf_fly.log.reader import LogError, read_log

    try:
        return read_log(log)
    except LogError as err:
        raise fail(f"{log}: {err}")
    except OSError as err:
        raise fail(f"{log}: {err.strerror or err}")
