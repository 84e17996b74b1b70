"""How commands report a user error: one line on stderr and exit code 2, never a traceback."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from rpf_fly.app.errors import UserError

if TYPE_CHECKING:
    from rpf_fly.log.reader import LogData


def fail(message: str, code: int = 2) -> typer.Exit:
    """Print ``message`` as one line on stderr and return the Exit to raise."""
    typer.echo(" ".join(str(message).split("\n")), err=True)
    return typer.Exit(code)


def read_log_or_fail(log: Path) -> LogData:
    """The flight log at ``log``, read; an unreadable or malformed file is a one-line user error naming it."""
    from rpf_fly.log.reader import LogError, read_log

    try:
        return read_log(log)
    except LogError as err:
        raise fail(f"{log}: {err}") from err
    except OSError as err:
        raise fail(f"{log}: {err.strerror or err}") from err


@contextmanager
def refused() -> Iterator[None]:
    """What the application layer refuses inside (:class:`~rpf_fly.app.errors.UserError`): its one line on stderr
    and its exit code."""
    try:
        yield
    except UserError as err:
        raise fail(str(err), err.code) from None
