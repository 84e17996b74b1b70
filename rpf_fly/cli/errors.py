"""How commands report a user error: one line on stderr and exit code 2, never a traceback."""

from __future__ import annotations

import typer


def fail(message: str, code: int = 2) -> "typer.Exit":
    """Print ``message`` as one line on stderr and return the Exit to raise."""
    typer.echo(" ".join(str(message).split("\n")), err=True)
    return typer.Exit(code)
