"""Load a mission YAML file into validated :mod:`rpf_fly.mission.model` dataclasses.

Validation is strict: a mission that would arm a drone must be exactly what its author meant. Every problem raises
:class:`~rpf_fly.mission.errors.MissionError` as ``FILE:LINE: FIELD: message``, where the line is that of the
offending value (of the mapping when a required key is missing; of the formation for drones it generated). Checks
run in two stages: each section's shape, types and ranges (in document order; within a mapping, its keys before
its values; speeds, rates and drone-scale lengths within what the firmware allows, so that a value written in the
wrong unit says so), then the layout of the whole mission (starts and goals against the arena, the obstacles and
each other; the flight height and circles against the arena; the mocap rate against the pose timeout). The format
and every check are described in docs/mission-format.md.
"""

from __future__ import annotations

import dataclasses
import difflib
import ipaddress
import math
import os
import re
from pathlib import Path
from typing import Any, Callable, Iterable, NamedTuple, Optional, Sequence

import numpy as np

from . import model as m
from .errors import MissionError
from .yaml_nodes import ROOT, YNode, child_path, compose, describe

STRING_SOURCE = "<string>"
"""The file name in errors for text parsed without a source path."""

NAME_PATTERN = re.compile(r"[A-Za-z][A-Za-z0-9_-]*")
"""Drone names (and the formation's name prefix): usable as MCAP topic segments."""

URI_RATES = ("250K", "1M", "2M")
MAX_CHANNEL = 125
URI_FORM = ("radio://DONGLE/CHANNEL/RATE/ADDRESS[?key=value] (e.g. radio://0/80/2M/E7E7E7E701, "
            "or fake:// with the same path)")
DEFAULT_POLICY = "policies/{kind}.onnx"
"""Where a policy kind looks for its policy when the mission names none (resolved like ``planner.policy``)."""

TOP_KEYS = ("name", "arena", "flight", "planner", "mocap", "radio", "sim", "safety", "obstacles", "drones", "formation",
            "runtime", "dry_run")
DRONE_KEYS = ("name", "uri", "rigid_body", "start", "goal")
FORMATION_KEYS = ("kind", "count", "radius", "center", "uri_base", "name_prefix", "phase_deg")
FORMATION_KINDS = ("circle_swap",)
MAX_FORMATION_COUNT = 255
OBSTACLE_KEYS = {"circle": ("shape", "center", "radius"), "box": ("shape", "min", "max")}


# ---------------------------------------------------------------------------------------------------- radio URIs

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
            raise ValueError(f"rate_limit {value!r} in {uri!r} must be a whole number of transactions a second "
                             "(cflib's ?rate_limit=N, at least 1)")
    return RadioUri(scheme, int(dongle), int(channel), rate, address.upper(), query)


# ---------------------------------------------------------------------------------------------- value checks

_HOST_NAME = re.compile(r"(?!-)[A-Za-z0-9-]{1,63}(?<!-)(\.(?!-)[A-Za-z0-9-]{1,63}(?<!-))*\.?")
"""A host name: dot-separated labels of letters, digits and hyphens, no label starting or ending with a hyphen."""

class _Bound(NamedTuple):
    text: str
    ok: Callable[[float], bool]


POSITIVE = _Bound("positive", lambda x: x > 0)
NON_NEGATIVE = _Bound("non-negative", lambda x: x >= 0)
FRACTION = _Bound("in [0, 1)", lambda x: 0 <= x < 1)


def _g(x: float) -> str:
    return f"{x:.6g}"


def _pt(p: Sequence[float]) -> str:
    return f"({_g(p[0])}, {_g(p[1])})"


def _suggest(word: str, choices: Iterable[str]) -> str:
    choices = list(choices)
    for c in choices:
        if c.lower() == word.lower():
            return f" (did you mean {c!r}?)"
    close = difflib.get_close_matches(word, choices, n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _options(choices: Iterable[str]) -> str:
    return ", ".join(repr(c) for c in choices)


PROJECT_POLICIES = Path(__file__).resolve().parents[2] / "policies"
"""The project's shipped policies: the ``policies/`` folder beside the ``rpf_fly`` package (a source checkout or an
editable install). A relative policy path inside a ``policies/`` folder falls back to it by file name, so a mission
copied out of ``missions/`` keeps its ``../policies/rpf.onnx`` (docs/mission-format.md, *Policy paths*)."""


INSTALLED_POLICIES = Path("share") / "rpf_fly" / "policies"
"""Where a wheel puts the shipped policies, under its install prefix (``[tool.setuptools.data-files]`` in
pyproject.toml): a ``pip install`` that is not editable has no ``policies/`` beside the package."""


def shipped_policy_dirs() -> list[Path]:
    """The folders holding the shipped policies: :data:`PROJECT_POLICIES` (a checkout or an editable install), then
    :data:`INSTALLED_POLICIES` under the install prefix the package lies in (a venv, ``--prefix``, ``--user`` or the
    system: the prefix is a parent of ``<prefix>/lib/pythonX.Y/site-packages/rpf_fly``). Only those that exist."""
    here = Path(__file__).resolve()
    dirs = [PROJECT_POLICIES] + [parent / INSTALLED_POLICIES for parent in here.parents[2:]]
    return [d for d in dict.fromkeys(dirs) if d.is_dir()]


def _search_dirs(base_dir: Optional[Path], cwd_first: bool = False) -> list[Path]:
    dirs = [d for d in (base_dir, Path.cwd()) if d is not None]
    return dirs[::-1] if cwd_first else dirs


def _find_file(raw: str, dirs: Sequence[Path]) -> tuple[Optional[Path], list[Path]]:
    """The first existing file among ``raw`` (absolute) or ``raw`` under each of ``dirs``, then, for a path inside
    a ``policies/`` folder, the shipped policies (`shipped_policy_dirs`) by file name; and every place it looked,
    each once (absolute, ``..`` folded)."""
    path = Path(raw).expanduser()
    candidates = [path] if path.is_absolute() else [d / path for d in dirs]
    if not path.is_absolute() and path.parent.name == "policies":
        candidates += [shipped / path.name for shipped in shipped_policy_dirs()]
    places = list(dict.fromkeys(Path(os.path.abspath(c)) for c in candidates))
    for place in places:
        if place.is_file():
            return place.resolve(), places
    return None, places


def _looked(candidates: Sequence[Path]) -> str:
    return "looked in " + ", ".join(str(c) for c in candidates)


class _Checker:
    """Typed reads of :class:`YNode` values that raise a precise :class:`MissionError`."""

    def __init__(self, file: str):
        self.file = file

    def error(self, where: YNode | int, field: str, message: str) -> MissionError:
        line = where if isinstance(where, int) else where.line
        return MissionError(self.file, line, field, message)

    def bad(self, node: YNode, expected: str) -> MissionError:
        return self.error(node, node.path, f"expected {expected}, got {describe(node)}")

    def mapping(self, node: YNode, keys: Sequence[str], required: Sequence[str] = (),
                what: str = "a mapping") -> dict[str, YNode]:
        """The entries of a mapping with only ``keys`` and all of ``required``."""
        if not node.is_map:
            raise self.bad(node, what)
        entries: dict[str, YNode] = node.value  # type: ignore[assignment]
        for key, value in entries.items():
            if key not in keys:
                hint = _suggest(key, keys) or f"; expected one of {_options(keys)}"
                raise self.error(value.key_line, value.path, f"unknown key{hint}")
        for key in required:
            if key not in entries:
                raise self.error(node.key_line, child_path(node.path, key), "missing required key")
        return entries

    def number(self, node: YNode, bound: Optional[_Bound] = None) -> float:
        v = node.value
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.bad(node, "a number")
        if not math.isfinite(v):
            raise self.error(node, node.path, f"expected a finite number, got {node.raw or v}")
        if bound is not None and not bound.ok(v):
            raise self.error(node, node.path, f"must be {bound.text}, got {node.raw or _g(v)}")
        return float(v)

    def integer(self, node: YNode, lo: Optional[int] = None, hi: Optional[int] = None) -> int:
        v = node.value
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.bad(node, "an integer")
        if lo is not None and v < lo:
            raise self.error(node, node.path, f"must be at least {lo}, got {v}" if lo != 1
                             else f"must be positive, got {v}")
        if hi is not None and v > hi:
            raise self.error(node, node.path, f"must be at most {hi}, got {v}")
        return v

    def string(self, node: YNode) -> str:
        if not isinstance(node.value, str):
            error = self.bad(node, "a string")
            if node.raw and not (node.is_map or node.is_seq):  # e.g. `name: no` or `rigid_body: 7`
                error = self.error(node, node.path, f"{error.message} (quote it to make it text: '{node.raw}')")
            raise error
        if not node.value.strip():
            raise self.error(node, node.path, "must not be empty")
        if any(ord(ch) < 32 for ch in node.value):
            raise self.error(node, node.path, f"must be one line of text, got {node.value!r}")
        return node.value

    def boolean(self, node: YNode) -> bool:
        if not isinstance(node.value, bool):
            raise self.bad(node, "true or false")
        return node.value

    def choice(self, node: YNode, choices: Sequence[str], what: str = "") -> str:
        if not isinstance(node.value, str):
            raise self.bad(node, f"one of {_options(choices)}")
        if node.value not in choices:
            label = (f"unknown {what} {node.value!r}" if what
                     else f"expected one of {_options(choices)}, got {node.value!r}")
            hint = _suggest(node.value, choices)
            known = f"; known: {', '.join(choices)}" if what else ""
            raise self.error(node, node.path, f"{label}{hint}{known}")
        return node.value

    def vec2(self, node: YNode, labels: str = "x, y") -> m.Vec2:
        if not node.is_seq or len(node.value) != 2:  # type: ignore[arg-type]
            raise self.bad(node, f"a list of 2 numbers [{labels}]")
        a, b = node.value  # type: ignore[misc]
        return self.number(a), self.number(b)

    def span(self, node: YNode) -> m.Vec2:
        lo, hi = self.vec2(node, "lo, hi")
        if not lo < hi:
            raise self.error(node, node.path, f"inverted range [{_g(lo)}, {_g(hi)}]: expected [lo, hi] with lo < hi")
        return lo, hi

    def host(self, node: YNode) -> str:
        """An IP address or a syntactically valid host name (RFC 1123). Dotted numbers must be a whole IPv4
        address: ``192.168.1.1000`` and ``192.168.1`` are typos, not host names. Whether a name resolves is
        checked when a command needs the server (``rpf-fly fly`` and ``check``), not here: ``sim`` needs none."""
        text = self.string(node)
        expected = f"expected a host name or IP address, got {text!r}"
        try:
            ipaddress.ip_address(text)
            return text
        except ValueError:
            pass
        if re.fullmatch(r"[0-9.]+", text):
            raise self.error(node, node.path, f"{expected}: not an IPv4 address (four numbers 0-255 joined by dots)")
        if len(text) > 253 or not _HOST_NAME.fullmatch(text):
            raise self.error(node, node.path, expected)
        return text

    def ip(self, node: YNode, multicast: bool = False) -> str:
        text = self.string(node)
        try:
            address = ipaddress.ip_address(text)
        except ValueError:
            raise self.error(node, node.path, f"expected an IP address, got {text!r}") from None
        if multicast and not address.is_multicast:
            raise self.error(node, node.path, f"expected a multicast address (224.0.0.0/4), got {text!r}")
        return text


# ------------------------------------------------------------------------------------------- section specs

Reader = Callable[[_Checker, YNode], Any]


def _num(bound: Optional[_Bound] = None) -> Reader:
    return lambda c, n: c.number(n, bound)


def _choice(choices: Sequence[str]) -> Reader:
    return lambda c, n: c.choice(n, choices)


def _port(c: _Checker, n: YNode) -> int:
    return c.integer(n, 1, 65535)


def _planner_kind(c: _Checker, n: YNode) -> str:
    return c.choice(n, m.PLANNER_KINDS, what="planner kind")


def _mocap_kind(c: _Checker, n: YNode) -> str:
    """`natnet`, `sim` or `motioncapture`; a system the motioncapture package knows (`kind: vicon`) is pointed there."""
    from rpf_fly.mocap.motioncapture_options import TYPES

    kinds = ("natnet", "sim", "motioncapture")
    if isinstance(n.value, str) and n.value in TYPES:
        raise c.error(n, n.path, f"expected one of {_options(kinds)}, got {n.value!r} ({n.value} is a type of the "
                      f"motioncapture package: kind: motioncapture, type: {n.value})")
    return c.choice(n, kinds)


# ------------------------------------------------------------------------------- plausible ranges (unit slips)

FIRMWARE_VELOCITY_LIMIT_M_S = 1.0
"""``posCtlPid.xVelMax`` (and ``yVelMax``), 1 m/s by default (crazyflie-firmware platform_defaults_cf2.h
``PID_POS_VEL_X_MAX``): the firmware's position controller clamps the velocity it asks of the drone at this (times
an overhead of 1.1, position_controller_pid.c), so a setpoint moving faster than ``flight.speed`` allows runs away
from its drone. The bound of ``flight.speed``."""

FIRMWARE_POSITION_RATE_HZ = 100.0
"""The firmware's position and velocity loops run at 100 Hz (stabilizer_types.h ``POSITION_RATE``): a setpoint
stream faster than that is never acted on, and every setpoint costs a radio packet. The bound of ``flight.rate_hz``."""

FIRMWARE_MAIN_LOOP_HZ = 1000.0
"""The Crazyflie's main (stabilizer) loop rate (stabilizer_types.h ``RATE_MAIN_LOOP``): no drone uses poses faster.
The bound of ``mocap.rate_hz``."""

MAX_DRONE_LENGTH_M = 1.0
"""The largest plausible ``planner.safety_radius``, ``planner.margin``, ``planner.capture_radius`` and
``flight.goal_tolerance``: a Crazyflie 2.x is 92 mm across and the defaults are 0.05-0.3 m, so a value above 1 m is
a length written in centimetres (``safety_radius: 10``) rather than a drone kept 2 m from every other."""


def _slip(v: float, unit: str, fits: Callable[[float], bool]) -> str:
    """`` (40 cm/s is 0.4 m/s)``: ``v`` read as centimetres (or millimetres) when that value ``fits``; else ''."""
    for prefix, scale in (("c", 100.0), ("m", 1000.0)):
        if fits(v / scale):
            return f" ({_g(v)} {prefix}{unit} is {_g(v / scale)} {unit})"
    return ""


def _period_slip(v: float, fits: Callable[[float], bool]) -> str:
    """`` (a period of 0.1 s is 10 Hz)``: ``v`` read as a period in seconds when its rate ``fits``; else ''."""
    return f" (a period of {_g(v)} s is {_g(1.0 / v)} Hz)" if v > 0 and fits(1.0 / v) else ""


def _speed(c: _Checker, n: YNode) -> float:
    v = c.number(n, POSITIVE)
    limit = FIRMWARE_VELOCITY_LIMIT_M_S
    if v > limit:
        raise c.error(n, n.path, f"{_g(v)} m/s: above the firmware's {_g(limit)} m/s velocity limit "
                      f"(posCtlPid.xVelMax); speeds are in m/s{_slip(v, 'm/s', lambda x: 0.05 <= x <= limit)}")
    return v


def _drone_length(what: str, default: float, bound: _Bound = POSITIVE) -> Reader:
    """A length at the scale of a drone (at most :data:`MAX_DRONE_LENGTH_M`): ``what`` says what it is."""
    def read(c: _Checker, n: YNode) -> float:
        v = c.number(n, bound)
        top = MAX_DRONE_LENGTH_M
        if v > top:
            hint = _slip(v, "m", lambda x: default / 5 <= x <= top)
            raise c.error(n, n.path, f"{_g(v)} m: above {_g(top)} m, implausible for {what} (the default is "
                          f"{_g(default)} m; a Crazyflie 2.x is 92 mm across); lengths are in m{hint}")
        return v
    return read


def _flight_rate(c: _Checker, n: YNode) -> float:
    v = c.number(n)
    top = FIRMWARE_POSITION_RATE_HZ
    if v < m.MIN_RATE_HZ:
        hint = _period_slip(v, lambda x: m.MIN_RATE_HZ <= x <= top)
        raise c.error(n, n.path, f"must be {RATE_HZ.text}, got {n.raw or _g(v)}{hint}")
    if v > top:
        raise c.error(n, n.path, f"{_g(v)} Hz: above the firmware's {_g(top)} Hz position loop (POSITION_RATE), "
                      f"which never acts on a faster stream; rates are in Hz")
    return v


def _mocap_rate(c: _Checker, n: YNode) -> float:
    v = c.number(n, POSITIVE)
    top = FIRMWARE_MAIN_LOOP_HZ
    if v > top:
        raise c.error(n, n.path, f"{_g(v)} Hz: above the Crazyflie's {_g(top)} Hz main loop (RATE_MAIN_LOOP), "
                      f"which could use no faster poses; rates are in Hz")
    return v


# YAML key -> (dataclass field, reader)
RATE_HZ = _Bound(
    f"at least {m.MIN_RATE_HZ:g} Hz, so the loop watchdog acts before the Crazyflie's "
    f"{m.FIRMWARE_SETPOINT_WATCHDOG_S:g} s setpoint watchdog levels the drones out",
    lambda x: x >= m.MIN_RATE_HZ)
FLIGHT_SPEC: dict[str, tuple[str, Reader]] = {
    k: (k, _num(POSITIVE)) for k in ("height", "speed", "rate_hz", "goal_tolerance", "takeoff_s", "land_s", "timeout_s")
}
FLIGHT_SPEC["speed"] = ("speed", _speed)
FLIGHT_SPEC["rate_hz"] = ("rate_hz", _flight_rate)
FLIGHT_SPEC["goal_tolerance"] = ("goal_tolerance", _drone_length("a goal tolerance", 0.1))
PLANNER_SPEC: dict[str, tuple[str, Reader]] = {
    "kind": ("kind", _planner_kind),
    "policy": ("policy", lambda c, n: c.string(n)),  # resolved to a file afterwards
    "sensing_range": ("sensing_range", _num(POSITIVE)),
    "safety_radius": ("safety_radius", _drone_length("a drone's radius", 0.1)),
    "influence_range": ("influence_range", _num(POSITIVE)),
    "wall_following": ("wall_following", lambda c, n: c.boolean(n)),
    "wall_threshold": ("wall_threshold", _num(NON_NEGATIVE)),
    "preset": ("preset", _choice(("robust", "paper"))),
    "neighbour_aggregate": ("neighbour_aggregate", _choice(("sum", "mean"))),
    "eta": ("eta", _num(NON_NEGATIVE)),
    "lambda": ("lam", _num(NON_NEGATIVE)),
    "guidance": ("guidance", _choice(m.GUIDANCE_MODES)),
    "margin": ("margin", _drone_length("a clearance beyond contact", m.PRODUCT_MARGIN_M, NON_NEGATIVE)),
    "capture_radius": ("capture_radius", _drone_length("the capture radius", m.CAPTURE_RADIUS_M, NON_NEGATIVE)),
}
MOCAP_SPEC: dict[str, tuple[str, Reader]] = {
    "kind": ("kind", lambda c, n: _mocap_kind(c, n)),
    "server": ("server", lambda c, n: c.host(n)),
    "local_ip": ("local_ip", lambda c, n: c.ip(n)),
    "multicast": ("multicast", lambda c, n: c.boolean(n)),
    "multicast_group": ("multicast_group", lambda c, n: c.ip(n, multicast=True)),
    "command_port": ("command_port", _port),
    "data_port": ("data_port", _port),
    "up_axis": ("up_axis", _choice(("y", "z"))),
    "noise_m": ("noise_m", _num(NON_NEGATIVE)),
    "latency_s": ("latency_s", _num(NON_NEGATIVE)),
    "rate_hz": ("rate_hz", _mocap_rate),
    "dropout": ("dropout", _num(FRACTION)),
    "timeout_s": ("timeout_s", _num(POSITIVE)),
    # kind motioncapture: read as they are here, checked against the library's table in _MissionParser.mocap
    "type": ("system", lambda c, n: n),
    "hostname": ("hostname", lambda c, n: n),
    "options": ("options", lambda c, n: n),
}
MOTIONCAPTURE_KEYS = ("type", "hostname", "options")
"""The `mocap` keys of kind `motioncapture` only."""
RADIO_SPEC: dict[str, tuple[str, Reader]] = {
    "kind": ("kind", _choice(("cflib",))),
    "min_battery_v": ("min_battery_v", _num(POSITIVE)),
    "extpos": ("extpos", _choice(("extpos", "extpose", "packed"))),
    "extpos_rate_hz": ("extpos_rate_hz", _num(POSITIVE)),
    "dongle_type": ("dongle_type", _choice(("crazyradio_pa", "crazyradio_2"))),
    "budget_packets_s": ("budget_packets_s", _num(POSITIVE)),
    "allow_over_budget": ("allow_over_budget", lambda c, n: c.boolean(n)),
}
SAFETY_SPEC: dict[str, tuple[str, Reader]] = {
    "pose_timeout_s": ("pose_timeout_s", _num(POSITIVE)),
    "pose_lost_land_s": ("pose_lost_land_s", _num(POSITIVE)),
    "on_separation": ("on_separation", _choice(("warn", "hold", "land"))),
    "on_obstacle": ("on_obstacle", _choice(("warn", "hold", "land"))),
    "on_preflight_failure": ("on_preflight_failure", _choice(("ground", "abort"))),
    "planner_budget_s": ("planner_budget_s", _num(POSITIVE)),
    "start_tolerance_m": ("start_tolerance_m", _num(POSITIVE)),
    "arrival_hold_s": ("arrival_hold_s", _num(NON_NEGATIVE)),
    "blind_drift_m_s2": ("blind_drift_m_s2", _num(POSITIVE)),
}
DRY_RUN_SPEC: dict[str, tuple[str, Reader]] = {
    "seed": ("seed", lambda c, n: c.integer(n, 0)),
    "mocap_noise_m": ("mocap_noise_m", _num(NON_NEGATIVE)),
    "mocap_noise_deg": ("mocap_noise_deg", _num(NON_NEGATIVE)),
    "mocap_dropout": ("mocap_dropout", _num(FRACTION)),
    "dynamics": ("dynamics", _choice(("first-order", "firmware"))),
    "radio": ("radio", _choice(("fake", "crazyradio"))),
    "crazyradio": ("crazyradio", _choice(("crazyradio_pa", "crazyradio_2"))),
    "vehicle": ("vehicle", lambda c, n: c.vehicle_profile(n)),
}
SIM_SPEC: dict[str, tuple[str, Reader]] = {
    "time_limit_s": ("time_limit_s", _num(POSITIVE)),
    "start_jitter_m": ("start_jitter_m", _num(NON_NEGATIVE)),
    "angle_jitter_deg": ("angle_jitter_deg", _num(NON_NEGATIVE)),
}


# ---------------------------------------------------------------------------------------------- the loader

class _MissionParser(_Checker):
    def __init__(self, file: str, base_dir: Optional[Path]):
        super().__init__(file)
        self.base_dir = base_dir
        self.nodes: dict[str, YNode] = {}

    # -- sections -------------------------------------------------------------------------------------------

    def settings(self, node: YNode, cls: type, spec: dict[str, tuple[str, Reader]]) -> Any:
        entries = self.mapping(node, tuple(spec))
        return cls(**{spec[k][0]: spec[k][1](self, v) for k, v in entries.items()})

    def arena(self, node: YNode) -> m.Arena:
        e = self.mapping(node, ("x", "y", "z"), required=("x", "y"))
        return m.Arena(**{k: self.span(v) for k, v in e.items()})

    def planner(self, node: YNode) -> m.PlannerSettings:
        settings: m.PlannerSettings = self.settings(node, m.PlannerSettings, PLANNER_SPEC)
        entries: dict[str, YNode] = node.value  # type: ignore[assignment]
        dirs = _search_dirs(self.base_dir)
        if "policy" in entries:
            raw = str(settings.policy)
            found, looked = _find_file(raw, dirs)
            if found is None:
                raise self.error(entries["policy"], "planner.policy",
                                 f"policy file {raw!r} not found ({_looked(looked)})")
        elif settings.kind in m.POLICY_KINDS:
            found = self.default_policy(settings.kind, entries.get("kind", node), "kind" not in entries)
        else:
            found = None
        return dataclasses.replace(settings, policy=found)

    def default_policy(self, kind: str, where: YNode | int, defaulted: bool) -> Path:
        """``policies/<kind>.onnx`` for a policy kind given no ``planner.policy``; the error names the kind's
        default, and says the kind itself was the default when the mission names none (``defaulted``)."""
        raw = DEFAULT_POLICY.format(kind=kind)
        found, looked = _find_file(raw, _search_dirs(self.base_dir))
        if found is None:
            whose = f"the default planner kind {kind!r}" if defaulted else f"planner kind {kind!r}"
            hint = " (or name another planner.kind, e.g. apf, which needs none)" if defaulted else ""
            raise self.error(where, "planner.policy",
                             f"{whose} needs a policy and none is given; the default {raw!r} was not found "
                             f"({_looked(looked)}){hint}")
        return found

    def mocap(self, node: YNode) -> m.MocapSettings:
        settings: m.MocapSettings = self.settings(node, m.MocapSettings, MOCAP_SPEC)
        entries: dict[str, YNode] = node.value  # type: ignore[assignment]
        if settings.command_port == settings.data_port:
            at = entries.get("data_port") or entries["command_port"]
            raise self.error(at, at.path, f"command_port and data_port must differ, both are {settings.data_port}")
        if settings.kind == "motioncapture":
            return self.motioncapture(node, entries, settings)
        for key in MOTIONCAPTURE_KEYS:
            if key in entries:
                raise self.error(entries[key].key_line, entries[key].path,
                                 f"only for kind 'motioncapture' (this mocap is kind {settings.kind!r})")
        return settings

    def motioncapture(self, node: YNode, entries: dict[str, YNode],
                      settings: m.MocapSettings) -> m.MocapSettings:
        """`type`, `hostname` and `options` of kind `motioncapture`, checked against libmotioncapture's own table
        (rpf_fly/mocap/motioncapture_options.py): the library itself ignores unknown keys and misreads values."""
        from rpf_fly.mocap import motioncapture_options as mc

        if "type" not in entries:
            raise self.error(node.key_line, child_path(node.path, "type"),
                             f"missing required key: kind 'motioncapture' needs the system's type, one of "
                             f"{', '.join(mc.TYPES)}")
        system = self.choice(entries["type"], tuple(mc.TYPES), what="motioncapture type")
        hostname = None
        if "hostname" in entries:
            at = entries["hostname"]
            try:
                hostname = mc.check_hostname(system, at.value)
            except ValueError as err:
                raise self.error(at, at.path, str(err)) from None
        options: list[tuple[str, str]] = []
        if "options" in entries:
            at = entries["options"]
            if not at.is_map:
                raise self.bad(at, f"a mapping of {system} options")
            for key, value in at.value.items():  # type: ignore[union-attr]
                if value.is_map or value.is_seq:
                    raise self.bad(value, "a scalar (text, number, true or false)")
                try:
                    options.append((key, mc.check_option(system, key, value.value)))
                except ValueError as err:
                    where = value.key_line if str(err).startswith(("unknown option", "give the host")) else value
                    raise self.error(where, value.path, str(err)) from None
        return dataclasses.replace(settings, system=system, hostname=hostname, options=tuple(options))

    def runtime(self, node: YNode) -> m.RuntimeSettings:
        entries = self.mapping(node, ("zenoh", "mocap_relay"))
        relay = self.mocap_relay(entries["mocap_relay"]) if "mocap_relay" in entries else "auto"
        if "zenoh" not in entries:
            return m.RuntimeSettings(mocap_relay=relay)  # type: ignore[arg-type]
        z = self.mapping(entries["zenoh"], ("mode", "connect", "listen", "config"))
        mode = self.choice(z["mode"], ("client", "peer")) if "mode" in z else "client"
        config = self.zenoh_config(z["config"]) if "config" in z else None
        lists: dict[str, tuple[str, ...]] = {}
        for key in ("connect", "listen"):
            if key not in z:
                continue
            value = z[key]
            items = value.value if value.is_seq else [value]
            endpoints = tuple(self.endpoint(item) for item in items)
            lists[key] = endpoints
        return m.RuntimeSettings(zenoh=m.ZenohSettings(mode=mode, config=config, **lists),  # type: ignore[arg-type]
                                 mocap_relay=relay)  # type: ignore[arg-type]

    def mocap_relay(self, node: YNode) -> str:
        """``runtime.mocap_relay``: ``auto``, ``on`` or ``off`` (YAML 1.1 reads a bare on/off as true/false: taken
        as written)."""
        if isinstance(node.value, bool):
            return "on" if node.value else "off"
        return self.choice(node, ("auto", "on", "off"))

    def zenoh_config(self, node: YNode) -> Path:
        """``runtime.zenoh.config``: an existing file that Zenoh reads as its configuration (relative to the
        mission's folder, then the current one); one line naming the file and Zenoh's complaint otherwise."""
        raw = self.string(node)
        found, looked = _find_file(raw, _search_dirs(self.base_dir))
        if found is None:
            raise self.error(node, "runtime.zenoh.config", f"Zenoh config file {raw!r} not found ({_looked(looked)})")
        import zenoh

        try:
            zenoh.Config.from_file(str(found))
        except zenoh.ZError as err:
            first = " ".join(str(err).split())[:200]
            raise self.error(node, "runtime.zenoh.config", f"Zenoh cannot read {str(found)!r}: {first}") from None
        return found

    def dry_run(self, node: YNode) -> m.DryRunSettings:
        settings: m.DryRunSettings = self.settings(node, m.DryRunSettings, DRY_RUN_SPEC)
        if settings.vehicle is not None and settings.dynamics != "firmware":
            at = node.value["vehicle"]  # type: ignore[index]
            raise self.error(at, "dry_run.vehicle", "a vehicle profile sets the firmware model's gains: give "
                             f"dry_run.dynamics: firmware with it (it is {settings.dynamics})")
        return settings

    def vehicle_profile(self, node: YNode) -> Any:
        """``dry_run.vehicle``: a vehicle profile file (relative to the mission's folder, then the current one),
        read and checked now (rpf_fly/calibrate/profile.py); one line naming the file and the field at fault."""
        from rpf_fly.calibrate.profile import ProfileError, load_profile

        raw = self.string(node)
        found, looked = _find_file(raw, _search_dirs(self.base_dir))
        if found is None:
            raise self.error(node, "dry_run.vehicle", f"vehicle profile {raw!r} not found ({_looked(looked)})")
        try:
            return load_profile(found)
        except ProfileError as err:
            raise self.error(node, "dry_run.vehicle", str(err)) from None

    def endpoint(self, node: YNode) -> str:
        text = self.string(node)
        proto, sep, rest = text.partition("/")
        if not sep or proto not in ("tcp", "udp", "tls", "quic") or ":" not in rest:
            raise self.error(node, node.path, f"expected a Zenoh endpoint such as tcp/127.0.0.1:7447, got {text!r}")
        return text

    def obstacles(self, node: YNode) -> tuple[m.Obstacle, ...]:
        if not node.is_seq:
            raise self.bad(node, "a list of obstacles (write [] for none)")
        out: list[m.Obstacle] = []
        for item in node.value:  # type: ignore[union-attr]
            e = self.mapping(item, ("shape", "center", "radius", "min", "max"), required=("shape",),
                             what="an obstacle mapping {shape: circle|box, ...}")
            shape = self.choice(e["shape"], tuple(OBSTACLE_KEYS), what="obstacle shape")
            keys = OBSTACLE_KEYS[shape]
            e = self.mapping(item, keys, required=keys)
            if shape == "circle":
                out.append(m.CircleObstacle(center=self.vec2(e["center"]), radius=self.number(e["radius"], POSITIVE)))
            else:
                lo, hi = self.vec2(e["min"]), self.vec2(e["max"])
                for axis in (0, 1):
                    if not lo[axis] < hi[axis]:
                        raise self.error(e["max"], e["max"].path,
                                         f"inverted box: min {_pt(lo)} must be below max {_pt(hi)} in "
                                         f"{'xy'[axis]} ({_g(lo[axis])} >= {_g(hi[axis])})")
                out.append(m.BoxObstacle(min=lo, max=hi))
        return tuple(out)

    def drone_name(self, node: YNode, what: str = "drone name") -> str:
        name = self.string(node)
        if not NAME_PATTERN.fullmatch(name):
            raise self.error(node, node.path, f"{what} {name!r} must start with a letter and contain only letters, "
                             "digits, '_' and '-' (it names MCAP topics)")
        return name

    def uri(self, node: YNode) -> tuple[str, RadioUri]:
        text = self.string(node)
        try:
            return text, parse_uri(text)
        except ValueError as exc:
            raise self.error(node, node.path, str(exc)) from None

    def drones(self, node: YNode) -> tuple[m.Drone, ...]:
        if not node.is_seq:
            raise self.bad(node, "a list of drones")
        if not node.value:
            raise self.error(node, "drones", "empty list: a mission needs at least one drone")
        drones: list[m.Drone] = []
        names: dict[str, YNode] = {}
        links: dict[tuple[int, str], YNode] = {}
        bodies: dict[str, YNode] = {}
        for i, item in enumerate(node.value):  # type: ignore[arg-type]
            e = self.mapping(item, DRONE_KEYS, required=("name", "uri", "start", "goal"),
                             what="a drone mapping {name, uri, start, goal}")
            name = self.drone_name(e["name"])
            if name in names:
                raise self.error(e["name"], e["name"].path,
                                 f"duplicate drone name {name!r} (also {names[name].path}, line {names[name].line})")
            names[name] = e["name"]
            uri, parsed = self.uri(e["uri"])
            if parsed.link in links:
                other = links[parsed.link]
                raise self.error(e["uri"], e["uri"].path,
                                 f"duplicate URI {uri!r}: same channel {parsed.channel} and address "
                                 f"{parsed.address} as {other.path} ({other.value!r}, line {other.line}), "
                                 "so both would reach the same Crazyflie")
            links[parsed.link] = e["uri"]
            body_node = e.get("rigid_body", e["name"])
            body = self.string(body_node) if "rigid_body" in e else name
            if body in bodies:
                other = bodies[body]
                how = "" if "rigid_body" in e else " (defaulted from the name)"
                raise self.error(body_node, child_path(item.path, "rigid_body"),
                                 f"duplicate rigid_body {body!r}{how}: also the rigid body of "
                                 f"{other.path.rsplit('.', 1)[0]} (line {other.line})")
            bodies[body] = body_node
            drones.append(m.Drone(name=name, uri=uri, rigid_body=body,
                                  start=self.vec2(e["start"]), goal=self.vec2(e["goal"])))
        return tuple(drones)

    def formation(self, node: YNode) -> tuple[m.Formation, tuple[m.Drone, ...]]:
        e = self.mapping(node, FORMATION_KEYS, required=("kind", "count", "radius"))
        kwargs: dict[str, Any] = {
            "kind": self.choice(e["kind"], FORMATION_KINDS, what="formation kind"),
            "count": self.integer(e["count"], 1, MAX_FORMATION_COUNT),
            "radius": self.number(e["radius"], POSITIVE),
        }
        if "center" in e:
            kwargs["center"] = self.vec2(e["center"])
        if "phase_deg" in e:
            kwargs["phase_deg"] = self.number(e["phase_deg"])
        if "name_prefix" in e:
            kwargs["name_prefix"] = self.drone_name(e["name_prefix"], "name_prefix")
        if "uri_base" in e:
            kwargs["uri_base"] = self.string(e["uri_base"])
        formation = m.Formation(**kwargs)
        try:
            parse_uri(formation.uri_base + "01")
        except ValueError as exc:
            at = e.get("uri_base", node)
            raise self.error(at, "formation.uri_base",
                             f"{formation.uri_base!r} followed by the drone number as 2 hex digits must be a URI: "
                             f"{exc}") from None
        return formation, expand_formation(formation)

    # -- the whole file -------------------------------------------------------------------------------------

    def parse(self, root: YNode, text: str, source: Optional[Path]) -> m.Mission:
        if not root.is_map:
            raise self.error(root, ROOT, "expected a mapping of mission keys (name, arena, drones, ...) at the top "
                             f"level, got {describe(root)}")
        entries = self.mapping(root, TOP_KEYS, required=("arena",))
        if "drones" in entries and "formation" in entries:
            second = max(entries["drones"], entries["formation"], key=lambda n: n.key_line)
            raise self.error(second.key_line, second.path,
                             "give either `drones` or `formation`, not both")
        if "drones" not in entries and "formation" not in entries:
            raise self.error(root.key_line, "drones", "missing: give a `drones` list or a `formation`")
        self.index(root)

        parts: dict[str, Any] = {"flight": m.FlightSettings(), "planner": m.PlannerSettings(),
                                 "mocap": m.MocapSettings(), "radio": m.RadioSettings(), "sim": m.SimSettings(),
                                 "safety": m.SafetySettings(),
                                 "obstacles": (), "formation": None,
                                 "name": source.stem if source is not None else "mission"}
        readers: dict[str, Callable[[YNode], Any]] = {
            "name": self.string, "arena": self.arena, "planner": self.planner, "mocap": self.mocap,
            "obstacles": self.obstacles, "drones": self.drones, "formation": self.formation,
            "flight": lambda n: self.settings(n, m.FlightSettings, FLIGHT_SPEC),
            "radio": lambda n: self.settings(n, m.RadioSettings, RADIO_SPEC),
            "sim": lambda n: self.settings(n, m.SimSettings, SIM_SPEC),
            "safety": lambda n: self.settings(n, m.SafetySettings, SAFETY_SPEC),
            "runtime": self.runtime,
            "dry_run": self.dry_run,
        }
        for key, node in entries.items():  # document order
            parts[key] = readers[key](node)
        if "planner" not in entries and parts["planner"].kind in m.POLICY_KINDS:
            parts["planner"] = dataclasses.replace(
                parts["planner"], policy=self.default_policy(parts["planner"].kind, root.key_line, True))
        if "formation" in entries:
            parts["formation"], parts["drones"] = parts["formation"]

        mission = m.Mission(source=source, text=text, **parts)
        check_layout(mission, self.layout_error(mission, entries))
        if mission.radio.extpos == "packed":
            self.packed_extpos(mission, entries.get("radio", root.key_line))
        return mission

    def packed_extpos(self, mission: m.Mission, at: YNode | int) -> None:
        """``radio.extpos: packed``: every drone's id (its address's last byte) its own on its channel, and the
        arena within the int16 millimetres a packed position carries (rpf_fly/radio/packed_extpos.py)."""
        from rpf_fly.radio.packed_extpos import MAX_MM, shared_ids

        for channel, ident, names in shared_ids({d.name: d.uri for d in mission.drones}):
            raise self.error(at, "radio.extpos", f"packed: drones {' and '.join(names)} both have id 0x{ident:02X} "
                             f"(the last byte of their radio address) on channel {channel}; the firmware takes a "
                             "packed position by that byte, so each would fly on the other's: give them addresses "
                             "with different last bytes, or use extpos")
        reach = max(abs(v) for v in (*mission.arena.x, *mission.arena.y, *mission.arena.z))
        if reach * 1000.0 > MAX_MM:
            raise self.error(at, "radio.extpos", f"packed: positions go as int16 millimetres (+-{MAX_MM / 1000} m) "
                             f"and the arena reaches {reach:g} m: use extpos")

    def index(self, node: YNode) -> None:
        self.nodes[node.path] = node
        if node.is_map:
            for child in node.value.values():  # type: ignore[union-attr]
                self.index(child)
        elif node.is_seq:
            for child in node.value:  # type: ignore[union-attr]
                self.index(child)

    def layout_error(self, mission: m.Mission, entries: dict[str, YNode]) -> "LayoutError":
        def make(path: str, message: str, at: Sequence[str] = ()) -> MissionError:
            if path.startswith("drones[") and mission.formation is not None:
                index = int(path[len("drones["):path.index("]")])
                line = entries["formation"].key_line
                return MissionError(self.file, line, "formation",
                                    f"{path} ({mission.drones[index].name}): {message}")
            for candidate in (path, *at):
                if candidate in self.nodes:
                    return MissionError(self.file, self.nodes[candidate].line, path, message)
            return MissionError(self.file, 1, path, message)
        return make


# ------------------------------------------------------------------------------------------ layout checks

LayoutError = Callable[..., MissionError]
"""``(path, message, at=())`` -> the error to raise: ``path`` is the field at fault (``drones[2].start``),
``at`` other paths whose line to use when ``path`` has no line of its own (a defaulted value)."""


def _clearance(p: m.Vec2, obstacle: m.Obstacle) -> float:
    """Distance from ``p`` to the obstacle's surface, 0 (box) or negative (circle) inside."""
    if isinstance(obstacle, m.CircleObstacle):
        return math.hypot(p[0] - obstacle.center[0], p[1] - obstacle.center[1]) - obstacle.radius
    dx = max(obstacle.min[0] - p[0], 0.0, p[0] - obstacle.max[0])
    dy = max(obstacle.min[1] - p[1], 0.0, p[1] - obstacle.max[1])
    return math.hypot(dx, dy)


def _describe_obstacle(obstacle: m.Obstacle) -> str:
    if isinstance(obstacle, m.CircleObstacle):
        return f"circle at {_pt(obstacle.center)} radius {_g(obstacle.radius)}"
    return f"box {_pt(obstacle.min)}-{_pt(obstacle.max)}"


def check_layout(mission: m.Mission, error: LayoutError) -> None:
    """The whole-mission checks: flight height in arena.z; a pose at least every safety.pose_timeout_s; circular
    obstacles no wider than the arena (and a formation radius written in cm or mm); every start and goal inside
    arena.x/y, clear of every obstacle by planner.safety_radius, start and goal at least flight.goal_tolerance apart,
    starts at least 2 safety_radius apart, goals at least 4 safety_radius apart. Raises ``error(path, message)``."""
    arena, r = mission.arena, mission.planner.safety_radius
    h = mission.flight.height
    if not arena.z[0] <= h <= arena.z[1]:
        hint = _slip(h, "m", lambda x: max(arena.z[0], 0.1) <= x <= arena.z[1])
        raise error("flight.height", f"{_g(h)} is outside arena.z [{_g(arena.z[0])}, {_g(arena.z[1])}]"
                    f"{'; heights are in m' + hint if hint else ''}", at=("arena.z", "flight", "arena"))
    _check_rates(mission, error)
    _check_radii(mission, error)
    tolerance = mission.flight.goal_tolerance
    for i, drone in enumerate(mission.drones):
        for what, p in (("start", drone.start), ("goal", drone.goal)):
            path = f"drones[{i}].{what}"
            for axis, span in (("x", arena.x), ("y", arena.y)):
                v = p[0] if axis == "x" else p[1]
                if not span[0] <= v <= span[1]:
                    raise error(path, f"{_pt(p)} is outside the arena: {axis} {_g(v)} not in arena.{axis} "
                                f"[{_g(span[0])}, {_g(span[1])}]")
        d = math.dist(drone.start, drone.goal)
        if d < tolerance:
            raise error(f"drones[{i}].start", f"start {_pt(drone.start)} and goal {_pt(drone.goal)} are "
                        f"{_g(d)} m apart, less than flight.goal_tolerance {_g(tolerance)} m (start equals goal)")
        for what, p in (("start", drone.start), ("goal", drone.goal)):
            for k, obstacle in enumerate(mission.obstacles):
                c = _clearance(p, obstacle)
                if c <= 0:
                    raise error(f"drones[{i}].{what}",
                                f"{_pt(p)} is inside obstacles[{k}] ({_describe_obstacle(obstacle)})")
                if c < r:
                    raise error(f"drones[{i}].{what}",
                                f"{_pt(p)} is {_g(c)} m from the surface of obstacles[{k}] "
                                f"({_describe_obstacle(obstacle)}), less than planner.safety_radius {_g(r)} m")
    _check_spacing(mission, "start", 2 * r, "2 x planner.safety_radius", "they would start in collision", error)
    _check_spacing(mission, "goal", 4 * r, "4 x planner.safety_radius",
                   f"an arrived drone is held as an obstacle of radius {_g(r)} m", error)


def _check_rates(mission: m.Mission, error: LayoutError) -> None:
    """A pose at least once every ``safety.pose_timeout_s``: a slower mocap would hold every drone between frames."""
    rate, timeout = mission.mocap.rate_hz, mission.safety.pose_timeout_s
    if 1.0 / rate >= timeout:
        hint = _period_slip(rate, lambda x: 1.0 / x < timeout and x <= FIRMWARE_MAIN_LOOP_HZ)
        raise error("mocap.rate_hz", f"{_g(rate)} Hz: a pose every {_g(1.0 / rate)} s, not within "
                    f"safety.pose_timeout_s ({_g(timeout)} s), so every drone would hold between frames; rates are "
                    f"in Hz{hint}", at=("safety.pose_timeout_s", "mocap", "safety"))


def _check_radii(mission: m.Mission, error: LayoutError) -> None:
    """Circles that fit the arena: an obstacle no wider than the arena's larger side, a formation whose circle lies
    in the arena (only when the radius reads as centimetres or millimetres; otherwise its drones' starts say it)."""
    arena = mission.arena
    width = max(arena.x[1] - arena.x[0], arena.y[1] - arena.y[0])
    size = f"arena.x [{_g(arena.x[0])}, {_g(arena.x[1])}], arena.y [{_g(arena.y[0])}, {_g(arena.y[1])}]"
    for k, obstacle in enumerate(mission.obstacles):
        if isinstance(obstacle, m.CircleObstacle) and 2 * obstacle.radius > width:
            hint = _slip(obstacle.radius, "m", lambda x: 0.01 <= x <= width / 2)
            raise error(f"obstacles[{k}].radius", f"{_g(obstacle.radius)} m: a circle {_g(2 * obstacle.radius)} m "
                        f"across, wider than the arena ({size}); lengths are in m{hint}")
    formation = mission.formation
    if formation is not None:
        cx, cy = formation.center

        def fits(radius: float) -> bool:
            return (arena.x[0] <= cx - radius and cx + radius <= arena.x[1]
                    and arena.y[0] <= cy - radius and cy + radius <= arena.y[1])

        hint = _slip(formation.radius, "m", lambda x: x >= 0.1 and fits(x))
        if hint and not fits(formation.radius):
            raise error("formation.radius", f"{_g(formation.radius)} m: the circle around {_pt(formation.center)} "
                        f"leaves the arena ({size}); lengths are in m{hint}")


def _check_spacing(mission: m.Mission, what: str, minimum: float, label: str, why: str, error: LayoutError) -> None:
    points = np.array([getattr(d, what) for d in mission.drones], dtype=float).reshape(-1, 2)
    for i in range(1, len(points)):
        dist = np.hypot(*(points[:i] - points[i]).T)
        j = int(np.argmin(dist))
        if dist[j] < minimum:
            other = mission.drones[j]
            raise error(f"drones[{i}].{what}",
                        f"{what} {_pt(points[i])} is {_g(dist[j])} m from the {what} of drones[{j}] ({other.name}), "
                        f"less than {label} = {_g(minimum)} m ({why})")


# ---------------------------------------------------------------------------------------------- formations

def expand_formation(formation: m.Formation) -> tuple[m.Drone, ...]:
    """The explicit drones of a formation. ``circle_swap``: drone i (0-based) is ``f"{prefix}{i+1}"`` with URI
    ``uri_base + f"{i+1:02X}"``, starts at ``center + radius (cos t, sin t)`` with
    ``t = phase + 2 pi i / count`` and flies to the antipode ``center - radius (cos t, sin t)``."""
    cx, cy = formation.center
    drones = []
    for i in range(formation.count):
        t = math.radians(formation.phase_deg) + 2.0 * math.pi * i / formation.count
        dx, dy = formation.radius * math.cos(t), formation.radius * math.sin(t)
        name = f"{formation.name_prefix}{i + 1}"
        drones.append(m.Drone(name=name, uri=f"{formation.uri_base}{i + 1:02X}", rigid_body=name,
                              start=(cx + dx, cy + dy), goal=(cx - dx, cy - dy)))
    return tuple(drones)


# ------------------------------------------------------------------------------------------------- public API

def parse_mission(text: str, source: Path | str | None = None) -> m.Mission:
    """Validate mission YAML ``text``. ``source`` (the file it came from) names the file in errors, gives the
    default mission name (its stem) and the directory a relative ``planner.policy`` is looked up in first."""
    src = Path(source) if source is not None else None
    file = str(src) if src is not None else STRING_SOURCE
    root = compose(text, file)
    if root is None:
        raise MissionError(file, 1, ROOT, "empty mission file")
    parser = _MissionParser(file, src.parent if src is not None else None)
    return parser.parse(root, text, src)


def load_mission(path: str | Path) -> m.Mission:
    """Read and validate the mission file at ``path`` (UTF-8 YAML). Raises :class:`MissionError`."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except FileNotFoundError:
        raise MissionError(p, 0, ROOT, "no such file") from None
    except OSError as exc:
        raise MissionError(p, 0, ROOT, f"cannot read the file: {exc.strerror or exc}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[:exc.start].count(b"\n") + 1
        raise MissionError(p, line, ROOT, f"not UTF-8 text (byte 0x{data[exc.start]:02x})") from None
    return parse_mission(text.removeprefix("\ufeff"), p)


def field_line(path: str | Path, field: str) -> int:
    """The line of the dotted ``field`` (``mocap.server``) in the mission file at ``path``, for a problem found
    after loading (a host that does not resolve): the line of its nearest written parent when the field is left
    to its default, 0 when the file no longer reads as YAML."""
    try:
        node = compose(Path(path).read_text(encoding="utf-8").removeprefix("\ufeff"), str(path))
    except (OSError, UnicodeDecodeError, MissionError):
        return 0
    line = 0
    for key in field.split("."):
        if node is None or not node.is_map or key not in node.value:  # type: ignore[operator]
            break
        node = node.value[key]  # type: ignore[index]
        line = node.key_line
    return line


def with_planner(mission: m.Mission, kind: str, policy: str | Path | None = None, **overrides: Any) -> m.Mission:
    """``mission`` flown with another planner: the CLI's ``--planner``, ``--policy`` and planner overrides such as
    ``wall_following=False`` (``--no-wall-following``). ``overrides`` are PlannerSettings fields (``lam`` for
    lambda). Everything is re-validated; errors read ``FILE:0: --option: message`` (line 0: the command line).

    ``policy`` is looked up as an absolute path, else relative to the current directory, else to the mission's
    directory. Without it, the mission's policy is kept when ``kind`` is the mission's kind; a policy kind
    otherwise looks for ``policies/<kind>.onnx`` (mission directory, current directory, the shipped ``policies/``); other kinds drop it.
    """
    file = str(mission.source) if mission.source is not None else STRING_SOURCE
    check = _Checker(file)
    base_dir = mission.source.parent if mission.source is not None else None

    def cli_error(option: str, message: str) -> MissionError:
        return MissionError(file, 0, option, message)

    kind = check.choice(YNode(kind, 0, 0, "--planner", str(kind)), m.PLANNER_KINDS, what="planner kind")
    if policy is not None:
        found, looked = _find_file(str(policy), _search_dirs(base_dir, cwd_first=True))
        if found is None:
            raise cli_error("--policy", f"policy file {str(policy)!r} not found ({_looked(looked)})")
    elif kind == mission.planner.kind:
        found = mission.planner.policy
    elif kind in m.POLICY_KINDS:
        raw = DEFAULT_POLICY.format(kind=kind)
        found, looked = _find_file(raw, _search_dirs(base_dir))
        if found is None:
            raise cli_error("--planner", f"planner kind {kind!r} needs a policy: give --policy, or provide the "
                            f"default {raw!r} ({_looked(looked)})")
    else:
        found = None

    by_field = {name: (key, reader) for key, (name, reader) in PLANNER_SPEC.items() if name not in ("kind", "policy")}
    values: dict[str, Any] = {}
    for name, value in overrides.items():
        if name not in by_field:
            raise TypeError(f"with_planner() got an unknown planner override {name!r}; "
                            f"expected one of {', '.join(sorted(by_field))}")
        key, reader = by_field[name]
        option = "--" + key.replace("_", "-")
        raw_text = str(value).lower() if isinstance(value, bool) else str(value)
        values[name] = reader(check, YNode(value, 0, 0, option, raw_text))
    planner = dataclasses.replace(mission.planner, kind=kind, policy=found, **values)
    updated = dataclasses.replace(mission, planner=planner)

    option = "--safety-radius" if "safety_radius" in overrides else "--planner"

    def layout_error(path: str, message: str, at: Sequence[str] = ()) -> MissionError:
        return cli_error(option, f"{path}: {message}")

    check_layout(updated, layout_error)
    return updated
