"""What the ``motioncapture`` package (libmotioncapture 1.1) accepts: its system types, each type's options, checks.

Why a table of our own: ``motioncapture.connect(type, {str: str})`` takes every option as text and forgives
everything. Unknown keys are ignored; ``getBool`` takes only ``"1"`` and ``"true"`` as true (so ``yes`` is false);
``getInt`` is ``std::stoi`` (``"15x"`` is 15); the mock's ``rigid_bodies`` parser stops at the first malformed entry
and copies each name into a 100-byte stack buffer (a longer name overflows it). A typo would fly with a default, so
the mission loader and ``rpf-fly mocap watch --option`` check every key and value against this table, read from
libmotioncapture 1.1's ``MotionCapture::connect`` (src/motioncapture.cpp), before anything starts the library.

The library cannot be asked which types it was compiled with without connecting, so the table lists every type
1.1 knows; ``in_wheel`` marks the five that the PyPI wheel of 1.1 has (checked by connecting each: the others answer
``Unknown motion capture type!``, which the source reports in one line when it starts).
"""

from __future__ import annotations

import difflib
import ipaddress
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field

from rpf_fly import install_hint

__all__ = [
    "LIBRARY_VERSION",
    "Option",
    "SystemType",
    "TYPES",
    "WHEEL_TYPES",
    "MISSING_LIBRARY",
    "system_type",
    "check_hostname",
    "check_option",
    "check_options",
    "parse_rigid_bodies",
    "MockBody",
]

LIBRARY_VERSION = "1.1"
"""The libmotioncapture release this table, the type list and docs/mocap.md's findings were checked against."""

MISSING_LIBRARY = f"the motioncapture package is not installed: install the extra with {install_hint('motioncapture')}"
"""The one line every entry point prints when the optional ``motioncapture`` package is missing."""

_HOST_NAME = re.compile(r"(?!-)[A-Za-z0-9-]{1,63}(?<!-)(\.(?!-)[A-Za-z0-9-]{1,63}(?<!-))*\.?")
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_MOCK_BODY = re.compile(rf"([^(;]+)\(\s*({_NUMBER})" + rf"\s*,\s*({_NUMBER})" * 6 + r"\s*\)")
_POINT = re.compile(rf"\s*({_NUMBER})\s*,\s*({_NUMBER})\s*,\s*({_NUMBER})\s*")
MOCK_NAME_MAX = 99
"""The mock copies a body name into ``char name[100]`` (sscanf ``%[^(]``): 99 characters and the terminator."""


@dataclass(frozen=True)
class Option:
    """One library option: what kind of value, the library's default (as text) and what it does."""

    kind: str
    """``bool``, ``int``, ``ipv4``, ``rigid_bodies`` or ``pointcloud``."""
    default: str
    meaning: str
    lo: int = 1
    hi: int = 65535


@dataclass(frozen=True)
class SystemType:
    """A ``connect()`` type of libmotioncapture 1.1."""

    name: str
    meaning: str
    in_wheel: bool
    hostname: str | None
    """How the library reads ``hostname``: ``ip`` (an IPv4 address: rpf_fly resolves a host name first, since
    the library's ``make_address`` takes only literals), ``host`` (a name or address), ``endpoint`` (``host`` or
    ``host:port``), or None (the type has no host)."""
    hostname_default: str = "localhost"
    options: Mapping[str, Option] = field(default_factory=dict)


_PORT_COMMAND = Option("int", "1510", "the NatNet command port of Motive")
TYPES: dict[str, SystemType] = {
    t.name: t
    for t in (
        SystemType(
            "mock",
            "fixed rigid bodies from the `rigid_bodies` option, no hardware",
            True,
            None,
            "",
            {
                "rigid_bodies": Option("rigid_bodies", "", "bodies `name(x,y,z,qw,qx,qy,qz)` joined by `;` (qw first)"),
                "pointcloud": Option("pointcloud", "", "points `x,y,z` joined by `;`"),
                "frequency": Option("int", "100", "frames per second", 1, 1000),
            },
        ),
        SystemType(
            "optitrack",
            "OptiTrack Motive, NatNet parsed by libmotioncapture's own decoder",
            True,
            "ip",
            options={
                "interface_ip": Option("ipv4", "0.0.0.0", "the local interface multicast is joined on"),
                "port_command": _PORT_COMMAND,
            },
        ),
        SystemType(
            "vicon",
            "Vicon DataStream SDK",
            True,
            "endpoint",
            options={
                "enable_objects": Option("bool", "true", "stream rigid bodies (subjects)"),
                "enable_pointclout": Option("bool", "true", "stream unlabeled markers (the library's spelling)"),
            },
        ),
        SystemType(
            "qualisys",
            "Qualisys QTM real-time protocol",
            True,
            "host",
            options={
                "port": Option("int", "22222", "the QTM real-time port"),
                "enable_objects": Option("bool", "true", "stream 6DOF bodies"),
                "enable_pointcloud": Option("bool", "true", "stream 3D markers"),
            },
        ),
        SystemType("vrpn", "a VRPN server (trackers as rigid bodies)", True, "endpoint"),
        SystemType(
            "optitrack_closed_source",
            "OptiTrack through NaturalPoint's closed NatNet SDK",
            False,
            "ip",
            options={"port_command": _PORT_COMMAND},
        ),
        SystemType(
            "nokov",
            "NOKOV SDK",
            False,
            "host",
            options={
                "enableFrequency": Option("bool", "false", "apply `updateFrequency`"),
                "updateFrequency": Option("int", "100", "frames per second", 1, 10000),
            },
        ),
        SystemType("motionanalysis", "Motion Analysis Cortex SDK", False, "host"),
        SystemType(
            "fzmotion",
            "FZMotion",
            False,
            "host",
            "fzmotion",
            {
                "local_IP": Option("ipv4", "0.0.0.0", "the local interface"),
                "local_port": Option("int", "9762", "the local port"),
                "remote_port": Option("int", "9761", "the FZMotion server port"),
            },
        ),
    )
}
WHEEL_TYPES: tuple[str, ...] = tuple(sorted(n for n, t in TYPES.items() if t.in_wheel))
"""The types compiled into the PyPI wheel of motioncapture 1.1."""


@dataclass(frozen=True)
class MockBody:
    """One body of the mock's ``rigid_bodies`` option, quaternion reordered to (qx, qy, qz, qw)."""

    name: str
    position: tuple[float, float, float]
    quaternion: tuple[float, float, float, float]


def _suggest(word: str, choices: list[str]) -> str:
    for c in choices:
        if c.lower() == word.lower():
            return f" (did you mean {c!r}?)"
    close = difflib.get_close_matches(word, choices, n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


def system_type(name: str) -> SystemType:
    """The type called ``name``; ``ValueError`` naming the known ones otherwise."""
    if name in TYPES:
        return TYPES[name]
    names = list(TYPES)
    raise ValueError(f"unknown motioncapture type {name!r}{_suggest(name, names)}; known: {', '.join(names)}")


def _host(text: str) -> bool:
    try:
        ipaddress.ip_address(text)
        return True
    except ValueError:
        pass
    return not re.fullmatch(r"[0-9.]+", text) and len(text) <= 253 and bool(_HOST_NAME.fullmatch(text))


def check_hostname(system: str, text: object) -> str:
    """``text`` as the ``hostname`` of ``system``, or ``ValueError`` saying what that type expects."""
    t = system_type(system)
    if t.hostname is None:
        raise ValueError(f"type {system!r} has no host (it needs no hardware); remove hostname")
    if not isinstance(text, str) or not text.strip():
        raise ValueError(f"expected a host name or IP address, got {text!r}")
    if t.hostname == "endpoint":
        host, colon, port = text.rpartition(":") if text.count(":") == 1 else (text, "", "")
        if colon and not (port.isdigit() and 1 <= int(port) <= 65535):
            raise ValueError(f"expected host or host:port (port 1-65535), got {text!r}")
        if not _host(host):
            raise ValueError(f"expected host or host:port, got {text!r}")
        return text
    if not _host(text):
        raise ValueError(f"expected a host name or IP address, got {text!r}")
    return text


def parse_rigid_bodies(text: str) -> list[MockBody]:
    """The mock's ``rigid_bodies`` text, ``name(x,y,z,qw,qx,qy,qz);...``, parsed as strictly as the library should.

    The library's loop stops at the first entry its ``sscanf`` cannot read and keeps the earlier ones; this refuses
    the whole text instead, and also a name of more than 99 characters (its stack buffer), a duplicate name (its
    map would keep the first), a name with surrounding spaces (kept by ``%[^(]``, so ``; cf2`` names " cf2"),
    non-finite numbers and a quaternion that is not a unit one (the library does not normalise it)."""
    entries = text[:-1].split(";") if text.endswith(";") else text.split(";")
    bodies: list[MockBody] = []
    for entry in entries:
        match = _MOCK_BODY.fullmatch(entry)
        if match is None:
            raise ValueError(f"expected bodies name(x,y,z,qw,qx,qy,qz) joined by ';', got {entry!r}")
        name = match.group(1)
        if name != name.strip():
            raise ValueError(f"body name {name!r} has surrounding spaces (the library keeps them)")
        if len(name) > MOCK_NAME_MAX:
            raise ValueError(f"body name of {len(name)} characters: the library takes at most {MOCK_NAME_MAX}")
        if any(b.name == name for b in bodies):
            raise ValueError(f"duplicate body {name!r}")
        x, y, z, qw, qx, qy, qz = (float(v) for v in match.groups()[1:])
        if not all(map(math.isfinite, (x, y, z, qw, qx, qy, qz))):
            raise ValueError(f"body {name!r}: numbers must be finite")
        norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)
        if abs(norm - 1.0) > 1e-3:
            raise ValueError(f"body {name!r}: quaternion (qw,qx,qy,qz) has norm {norm:.4g}, expected a unit one")
        bodies.append(MockBody(name, (x, y, z), (qx, qy, qz, qw)))
    return bodies


def check_option(system: str, key: str, value: object) -> str:
    """``value`` (a YAML scalar, or text from the command line) of option ``key`` of ``system`` as the text the
    library gets; ``ValueError`` with what was expected otherwise."""
    t = system_type(system)
    if key == "hostname":
        raise ValueError("give the host as mocap.hostname (or --host), not as an option")
    if key not in t.options:
        names = list(t.options)
        known = f"; {system} takes {', '.join(names)}" if names else f"; {system} takes no options"
        raise ValueError(f"unknown option {key!r} of type {system!r}{_suggest(key, names)}{known}")
    option = t.options[key]
    if option.kind == "bool":
        if isinstance(value, bool):
            return "true" if value else "false"
        if isinstance(value, str) and value in ("true", "false"):
            return value
        raise ValueError(f"expected true or false, got {value!r}")
    if option.kind == "int":
        if isinstance(value, str) and re.fullmatch(r"[-+]?\d+", value.strip()):
            value = int(value)
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"expected an integer, got {value!r}")
        if not option.lo <= value <= option.hi:
            raise ValueError(f"must be {option.lo}-{option.hi}, got {value}")
        return str(value)
    if not isinstance(value, str):
        raise ValueError(f"expected text, got {value!r}")
    if option.kind == "ipv4":
        try:
            ipaddress.IPv4Address(value)
        except ValueError:
            raise ValueError(f"expected an IPv4 address, got {value!r}") from None
        return value
    if option.kind == "rigid_bodies":
        parse_rigid_bodies(value)
        return value
    if option.kind == "pointcloud":
        points = value[:-1].split(";") if value.endswith(";") else value.split(";")
        for point in points:
            if not _POINT.fullmatch(point) or not all(math.isfinite(float(v)) for v in point.split(",")):
                raise ValueError(f"expected points x,y,z joined by ';', got {point!r}")
        return value
    raise AssertionError(f"option kind {option.kind!r}")  # pragma: no cover - the table above is closed


def check_options(system: str, options: Mapping[str, object]) -> dict[str, str]:
    """Every option of ``options`` checked with :func:`check_option` (the first problem raises, key first)."""
    out: dict[str, str] = {}
    for key, value in options.items():
        try:
            out[key] = check_option(system, key, value)
        except ValueError as err:
            raise ValueError(f"{key}: {err}") from None
    return out
