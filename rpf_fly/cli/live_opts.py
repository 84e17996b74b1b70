"""``rpf-fly fly --foxglove``: start the live view before the flight, say where it is, refuse in one line.

Kept apart from ``fly_cmd.py`` so the command only gains its options and two calls. The live view itself is
:class:`rpf_fly.log.live.LiveView` (docs/foxglove.md).

The options: typer (0.29) gives an option either always a value or never one, and an option with an optional
value would swallow whatever follows it (``--foxglove --dry-run`` takes ``--dry-run`` as the port, ``--foxglove
missions/lab-3.yaml`` the mission). So ``--foxglove`` is a flag, and ``--foxglove-port PORT`` /
``--foxglove-host HOST`` set where it listens (either of them turns it on too). The short form ``--foxglove
[PORT]`` works as well, through :func:`foxglove_port_argv` before typer parses the command line: ``--foxglove=PORT``,
and ``--foxglove PORT`` where the word after it is a port number (digits) that is not a file, are read as
``--foxglove-port PORT``; anything else after ``--foxglove`` stays what it was (the mission, another option).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import typer

from rpf_fly.cli.errors import fail

if TYPE_CHECKING:
    from rpf_fly.log.live import LiveView

LAYOUT = "docs/foxglove-layout.json"


def foxglove_port_argv(args: list[str]) -> list[str]:
    """``rpf-fly fly ... --foxglove [PORT]``: the command line with ``--foxglove=PORT`` and ``--foxglove PORT`` (a
    word of digits that names no file) written as ``--foxglove-port PORT``; other commands' and other words
    unchanged (see the module docstring)."""
    if not args or args[0] != "fly":
        return list(args)
    out: list[str] = []
    i = 0
    while i < len(args):
        word = args[i]
        if word.startswith("--foxglove="):
            out += ["--foxglove-port", word.split("=", 1)[1]]
        elif word == "--foxglove" and i + 1 < len(args) and args[i + 1].isdigit() and not Path(args[i + 1]).exists():
            out += ["--foxglove-port", args[i + 1]]
            i += 1
        else:
            out.append(word)
        i += 1
    return out


def start_live(enabled: bool, port: int | None, host: str | None) -> LiveView | None:
    """The started live view when asked for (``--foxglove``, or a port or host given), else None. Missing
    foxglove-sdk, a taken port or a bad address: one line on stderr, exit 2, before anything connects."""
    if not (enabled or port is not None or host is not None):
        return None
    from rpf_fly.log.live import DEFAULT_HOST, DEFAULT_PORT, LiveUnavailable, LiveView

    port = DEFAULT_PORT if port is None else port
    if not 0 <= port <= 65535:
        raise fail(f"--foxglove-port: expected a port 0..65535 (0: any free port), got {port}")
    try:
        live = LiveView(port, host or DEFAULT_HOST)
    except LiveUnavailable as err:
        raise fail(f"--foxglove: {err}") from err
    typer.echo(
        f"live: serving the flight on {live.url} (Foxglove: Open connection > Foxglove WebSocket; layout {LAYOUT})",
        err=True,
    )
    if live.host not in ("127.0.0.1", "localhost", "::1"):
        typer.echo(
            f"live: warning: listening on {live.host}: anyone who can reach this machine on port {live.port} "
            f"sees the flight (read only, no password; docs/foxglove.md); from elsewhere connect to "
            f"ws://<this machine's address>:{live.port}",
            err=True,
        )
    return live
