"""Crazyflie radio URIs as a mission names them: ``radio://DONGLE/CHANNEL/RATE/ADDRESS[?key=value]`` (or ``fake://``
with the same path), parsed stricter than cflib. Why apart: the URI's form is the radio's, read by the mission's
drones and formation alike, and needs nothing of YAML.
"""

from __future__ import annotations

import re
from typing import NamedTuple

URI_RATES = ("250K", "1M", "2M")
MAX_CHANNEL = 125
URI_FORM = (
    "radio://DONGLE/CHANNEL/RATE/ADDRESS[?key=value] (e.g. radio://0/80/2M/E7E7E7E701, or fake:// with the same path)"
)


class RadioUri(NamedTuple):
    """A parsed Crazyflie URI. ``address`` is upper-case hex; ``query`` is the text after ``?`` (or empty)."""

    scheme: str
    dongle: int
    channel: int
    rate: str
    address: str
    query: str

    @property
    def link(self) -> tuple[int, str]:
        """What identifies the Crazyflie on the air: two URIs with the same channel and address reach one drone."""
        return self.channel, self.address


_QUERY = re.compile(r"[A-Za-z_][A-Za-z0-9_]*=[^&=\s]*(?:&[A-Za-z_][A-Za-z0-9_]*=[^&=\s]*)*")


def parse_uri(uri: str) -> RadioUri:
    """Parse ``radio://DONGLE/CHANNEL/RATE/ADDRESS[?key=value&...]`` or ``fake://`` with the same path.

    Stricter than cflib on purpose: cflib silently falls back to 2M for an unknown rate (``2m``) and pads short
    addresses with zeros. Raises ``ValueError`` with a message that says what form was expected.
    """
    scheme, sep, rest = uri.partition("://")
    if not sep or scheme not in ("radio", "fake"):
        raise ValueError(f"expected {URI_FORM}, got {uri!r}")
    path, has_query, query = rest.partition("?")
    parts = path.split("/")
    if len(parts) != 4:
        raise ValueError(f"expected {URI_FORM}, got {uri!r} ({len(parts)} path parts instead of 4)")
    dongle, channel, rate, address = parts
    if not re.fullmatch(r"[0-9]+", dongle):
        raise ValueError(f"dongle {dongle!r} in {uri!r} must be a dongle number (expected {URI_FORM})")
    if not re.fullmatch(r"[0-9]+", channel) or int(channel) > MAX_CHANNEL:
        raise ValueError(f"channel {channel!r} in {uri!r} must be an integer 0-{MAX_CHANNEL}")
    if rate not in URI_RATES:
        raise ValueError(f"data rate {rate!r} in {uri!r} must be one of {', '.join(URI_RATES)}")
    if not re.fullmatch(r"[0-9A-Fa-f]{10}", address):
        raise ValueError(f"address {address!r} in {uri!r} must be 10 hex digits (e.g. E7E7E7E701)")
    if has_query and not _QUERY.fullmatch(query):
        raise ValueError(f"query {query!r} in {uri!r} must be key=value pairs joined by '&'")
    for pair in query.split("&") if has_query else ():
        key, _, value = pair.partition("=")
        if key == "rate_limit" and not re.fullmatch(r"[1-9][0-9]*", value):
            raise ValueError(
                f"rate_limit {value!r} in {uri!r} must be a whole number of transactions a second "
                "(cflib's ?rate_limit=N, at least 1)"
            )
    return RadioUri(scheme, int(dongle), int(channel), rate, address.upper(), query)
