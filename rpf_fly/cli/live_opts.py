"""``rpf-fly fly --foxglove``: start the live view before the flight, say where it is, refuse in one line.

Kept apart from ``fly_cmd.py`` so the command only gains its options and two calls. The live view itself is
:class:`rpf_fly.log.live.LiveView` (docs/foxglove.md).

Why a flag and two options, not ``--foxglove [PORT]``: typer (0.29, no click underneath) gives an option either
always a value or never one, and an option with an optional value would swallow whatever follows it
(``--foxglove --dry-run`` takes ``--dry-run`` as the port). So ``--foxglove`` turns the live view on, and
``--foxglove-port PORT`` / ``--foxglove-host HOST`` set where it listens (either of them turns it on too).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Optional

import typer

from rpf_fly.cli.errors import fail

if TYPE_CHECKING:
    from rpf_fly.log.live import LiveView

LAYOUT = "docs/foxglove-layout.json"


def start_live(enabled: bool, port: Optional[int], host: Optional[str]) -> Optional["LiveView"]:
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
        raise fail(f"--foxglove: {err}")
    typer.echo(f"live: serving the flight on {live.url} (Foxglove: Open connection > Foxglove WebSocket; "
               f"layout {LAYOUT})", err=True)
    if live.host not in ("127.0.0.1", "localhost", "::1"):
        typer.echo(f"live: warning: listening on {live.host}: anyone who can reach this machine on port {live.port} "
                   f"sees the flight (read only, no password; docs/foxglove.md); from elsewhere connect to "
                   f"ws://<this machine's address>:{live.port}", err=True)
    return live
