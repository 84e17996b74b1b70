"""Opening a flight's Zenoh session from the mission's ``runtime.zenoh`` and the command line (docs/distributed.md).

Defaults: the coordinator a router listening on 127.0.0.1 only, its workers and logger clients connecting to it
(measured with zenoh 1.10.2: peers that do not listen themselves get nothing from each other through a peer, a
router routes between everyone connected to it), multicast scouting off (nothing on the lab network hears of the
flight, and nothing there is joined by chance). The link lease is
1 s (keep-alive every 250 ms), so a worker whose host vanishes without closing its socket is noticed within about
1 s too (a killed process is seen at once: its kernel closes the socket).
"""

from __future__ import annotations

import json
import socket
from collections.abc import Sequence
from typing import Any

from rpf_fly.mission.model import ZenohSettings

LEASE_MS = 1000
KEEP_ALIVE = 4
DEFAULT_PORT = 7447


class ZenohUnavailable(ConnectionError):
    """The session could not open (no endpoint reachable, a port taken): one line for the user."""


class StartError(RuntimeError):
    """A process of the flight (the logger, the mocap relay) did not come up: one line for the user, exit 2,
    nothing armed."""


def free_loopback_endpoint() -> str:
    """``tcp/127.0.0.1:<a free port>`` (the coordinator's default when no remote worker must find it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{s.getsockname()[1]}"


def endpoint_host(endpoint: str) -> str | None:
    """The host of a Zenoh endpoint such as ``tcp/10.0.0.5:7447`` or ``tls/[::1]:7447`` (metadata and settings
    after ``?`` or ``#`` ignored); None for one without a host and port (a Unix socket)."""
    proto, sep, rest = endpoint.partition("/")
    address = rest.split("?", 1)[0].split("#", 1)[0]
    if not sep or proto not in ("tcp", "udp", "tls", "quic", "ws") or ":" not in address:
        return None
    host = address.rsplit(":", 1)[0]
    return host[1:-1] if host.startswith("[") and host.endswith("]") else host


def rig_host(listen: Sequence[str]) -> str:
    """The IPv4 address a dry run's simulated drones (their fake-radio server and NatNet emulator) bind, from the
    coordinator's Zenoh listen endpoints: the first endpoint's host, so a worker that reaches the coordinator
    reaches the drones at the same address. ``127.0.0.1`` when it is loopback or names none (the default: nothing
    opened to the network); ``0.0.0.0`` (every interface) for ``0.0.0.0`` or ``[::]``: the rig then advertises
    ``0.0.0.0`` and each worker takes the host it reached the coordinator at (its ``--connect``); a host name is
    resolved to its IPv4 address. ValueError (one line) for an IPv6 address: the simulated drones serve IPv4."""
    host = endpoint_host(listen[0]) if listen else None
    if host is None or host in ("localhost", "::1"):
        return "127.0.0.1"
    if host in ("0.0.0.0", "::", ""):
        return "0.0.0.0"
    if ":" in host:
        raise ValueError(
            f"--listen {listen[0]}: a dry run's simulated drones serve IPv4 only: listen on an IPv4 "
            "address (or 0.0.0.0) first"
        )
    try:
        return socket.gethostbyname(host)
    except OSError as err:
        raise ValueError(f"--listen {listen[0]}: cannot resolve {host!r} to an IPv4 address ({err})") from None


def rig_address(advertised: str, connect: Sequence[str]) -> str:
    """Where a worker reaches the rig the coordinator advertised: that address, or for ``0.0.0.0`` (every
    interface) the host the worker reached the coordinator at (its first ``connect`` endpoint; loopback without)."""
    if advertised not in ("0.0.0.0", ""):
        return advertised
    host = endpoint_host(connect[0]) if connect else None
    return "127.0.0.1" if host is None or host in ("0.0.0.0", "::", "", "localhost", "::1") else host


def zenoh_config(
    settings: ZenohSettings, *, connect: Sequence[str] = (), listen: Sequence[str] = (), mode: str | None = None
) -> Any:
    """A ``zenoh.Config``: the mission's config file when it names one (TLS, access control: untouched), then the
    mission's settings on top, with the command line's endpoints replacing its own."""
    import zenoh

    config = zenoh.Config.from_file(str(settings.config)) if settings.config is not None else zenoh.Config()
    config.insert_json5("mode", json.dumps(mode or settings.mode))
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("transport/link/tx/lease", str(LEASE_MS))
    config.insert_json5("transport/link/tx/keep_alive", str(KEEP_ALIVE))
    connect = list(connect) or list(settings.connect)
    listen = list(listen) or list(settings.listen)
    config.insert_json5("connect/endpoints", json.dumps(connect))
    config.insert_json5("listen/endpoints", json.dumps(listen))
    if connect:  # a worker must reach its coordinator: fail at start instead of retrying for ever
        config.insert_json5("connect/timeout_ms", "2000")
        config.insert_json5("connect/exit_on_failure", "true")
    return config


def open_session(
    settings: ZenohSettings, *, connect: Sequence[str] = (), listen: Sequence[str] = (), mode: str | None = None
) -> Any:
    """Open the session; :class:`ZenohUnavailable` with one line if it cannot (nothing has been armed)."""
    import zenoh

    try:
        return zenoh.open(zenoh_config(settings, connect=connect, listen=listen, mode=mode))
    except zenoh.ZError as err:
        where = ", ".join(list(connect) or list(settings.connect) or list(listen) or list(settings.listen))
        first = str(err).split(" at /")[0].strip()
        raise ZenohUnavailable(f"zenoh: cannot open a session ({where or 'no endpoint'}): {first}") from None
