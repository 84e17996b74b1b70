"""The coordinator's commands, signed with the flight's secret (docs/distributed.md, "Who may command").

A Zenoh endpoint is open to anyone who reaches it; a worker obeys only commands signed by its own flight's
coordinator. Each flight draws a fresh 256-bit secret; the coordinator hands it to its local workers in their
environment (``RPF_FLY_SECRET``, not their command line: ``ps`` shows command lines to every user) and prints how
to give it to a remote one. A command is a JSON object ``{"command", "seq", "reason", "t_ns", "flight"}`` (a ``go``
and a ``takeoff`` also ``"grounded"``: the drones that stay on the ground, signed with the rest) whose attachment is the
HMAC-SHA256 of its bytes under the secret (hex). The secret itself never crosses the network, so a subscriber on
``rpf_fly/**`` cannot learn it; a replayed command is refused by its sequence number (each coordinator counts up
from 1; a worker takes each number once, in order).
"""

from __future__ import annotations

import hashlib
import hmac
import json
import secrets
import time
from dataclasses import dataclass

SECRET_ENV = "RPF_FLY_SECRET"
COMMANDS = ("go", "takeoff", "abort", "finish", "land", "emergency_stop")
"""go: arm (every worker passed its preflight); takeoff: every worker armed, take off (the drones that stay down
named); abort: land or stay down before take-off; finish: the mission is over (every drone at its goal), land
normally; land: the operator's first Ctrl-C; emergency_stop: motors off."""
GROUNDED_ON = ("go", "takeoff")
"""The commands that may name drones staying on the ground (``safety.on_preflight_failure: ground``)."""


def new_secret() -> str:
    return secrets.token_hex(32)


@dataclass(frozen=True)
class Command:
    command: str
    seq: int
    reason: str = ""
    grounded: tuple[str, ...] = ()
    """A ``go`` or ``takeoff``: every drone of the swarm that stays on the ground (failed its preflight or its arming,
    or kept down by one that did); each worker keeps down its own drones that could not take off or land beside
    them (FlightLoop)."""


def mac(key: bytes, payload: bytes) -> bytes:
    """The signature of ``payload`` under the flight's secret (``secret.encode()``): HMAC-SHA256, hex."""
    return hmac.new(key, payload, hashlib.sha256).hexdigest().encode()


def signed_by(key: bytes, payload: bytes, attachment: bytes | None) -> bool:
    """Whether ``attachment`` is ``payload``'s signature under ``key`` (compared in constant time)."""
    return attachment is not None and len(attachment) > 0 and hmac.compare_digest(mac(key, payload), bytes(attachment))


def sign(
    secret: str, flight: str, command: str, seq: int, reason: str = "", grounded: tuple[str, ...] = ()
) -> tuple[bytes, bytes]:
    """The payload and its signature (the sample's attachment) of one command."""
    body = {"command": command, "seq": int(seq), "reason": reason, "t_ns": time.time_ns(), "flight": flight}
    if grounded:
        body["grounded"] = sorted(grounded)
    payload = json.dumps(body, separators=(",", ":")).encode()
    return payload, mac(secret.encode(), payload)


class CommandVerifier:
    """Checks commands for one flight: signature, flight, known command, sequence number. Not thread-safe (one
    subscriber callback at a time)."""

    def __init__(self, secret: str, flight: str):
        self._key = secret.encode()
        self._flight = flight
        self._last_seq = 0

    def verify(self, payload: bytes, attachment: bytes | None) -> tuple[Command | None, str]:
        """(the command, "") if it is the coordinator's, else (None, why it is refused)."""
        if not attachment:
            return None, "unsigned command (no signature)"
        if not signed_by(self._key, payload, attachment):
            return None, "command with a wrong signature (not this flight's secret)"
        try:
            body = json.loads(payload)
            command, seq, reason, flight = (
                body["command"],
                int(body["seq"]),
                str(body.get("reason", "")),
                body["flight"],
            )
            grounded = body.get("grounded", [])
            if not isinstance(grounded, list) or not all(isinstance(n, str) for n in grounded):
                raise TypeError("grounded")
        except (ValueError, KeyError, TypeError):
            return None, "malformed command"
        if flight != self._flight or command not in COMMANDS or (grounded and command not in GROUNDED_ON):
            return None, f"command {command!r} for flight {flight!r} refused"
        if seq <= self._last_seq:
            return None, f"replayed command {command!r} (sequence {seq} after {self._last_seq})"
        self._last_seq = seq
        return Command(command, seq, reason, tuple(grounded)), ""
