"""How each section of a mission file is read: per YAML key the dataclass field and the reader of its value, with
the ranges the firmware allows (speeds, rates and drone-scale lengths: a value written in the wrong unit says so).
Why apart: the keys of docs/mission-format.md and their bounds in one table, apart from the parsing around them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from . import model as m
from .checker import FRACTION, NON_NEGATIVE, POSITIVE, Bound, Checker, fmt, options_text
from .yaml_nodes import YNode

if TYPE_CHECKING:
    from .parser import MissionParser

Reader = Callable[["MissionParser", YNode], Any]
"""Reads one key's value: called by :meth:`MissionParser.settings` with the parser itself."""


def _num(bound: Bound | None = None) -> Reader:
    return lambda c, n: c.number(n, bound)


def _choice(choices: Sequence[str]) -> Reader:
    return lambda c, n: c.choice(n, choices)


def _port(c: Checker, n: YNode) -> int:
    return c.integer(n, 1, 65535)


def _planner_kind(c: Checker, n: YNode) -> str:
    return c.choice(n, m.PLANNER_KINDS, what="planner kind")


def _mocap_kind(c: Checker, n: YNode) -> str:
    """`natnet`, `sim` or `motioncapture`; a system the motioncapture package knows (`kind: vicon`) is pointed there."""
    from rpf_fly.mocap.motioncapture_options import TYPES

    kinds = ("natnet", "sim", "motioncapture")
    if isinstance(n.value, str) and n.value in TYPES:
        raise c.error(
            n,
            n.path,
            f"expected one of {options_text(kinds)}, got {n.value!r} ({n.value} is a type of the "
            f"motioncapture package: kind: motioncapture, type: {n.value})",
        )
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


def unit_slip(v: float, unit: str, fits: Callable[[float], bool]) -> str:
    """`` (40 cm/s is 0.4 m/s)``: ``v`` read as centimetres (or millimetres) when that value ``fits``; else ''."""
    for prefix, scale in (("c", 100.0), ("m", 1000.0)):
        if fits(v / scale):
            return f" ({fmt(v)} {prefix}{unit} is {fmt(v / scale)} {unit})"
    return ""


def period_slip(v: float, fits: Callable[[float], bool]) -> str:
    """`` (a period of 0.1 s is 10 Hz)``: ``v`` read as a period in seconds when its rate ``fits``; else ''."""
    return f" (a period of {fmt(v)} s is {fmt(1.0 / v)} Hz)" if v > 0 and fits(1.0 / v) else ""


def _speed(c: Checker, n: YNode) -> float:
    v = c.number(n, POSITIVE)
    limit = FIRMWARE_VELOCITY_LIMIT_M_S
    if v > limit:
        raise c.error(
            n,
            n.path,
            f"{fmt(v)} m/s: above the firmware's {fmt(limit)} m/s velocity limit "
            f"(posCtlPid.xVelMax); speeds are in m/s{unit_slip(v, 'm/s', lambda x: 0.05 <= x <= limit)}",
        )
    return v


def _drone_length(what: str, default: float, bound: Bound = POSITIVE) -> Reader:
    """A length at the scale of a drone (at most :data:`MAX_DRONE_LENGTH_M`): ``what`` says what it is."""

    def read(c: Checker, n: YNode) -> float:
        v = c.number(n, bound)
        top = MAX_DRONE_LENGTH_M
        if v > top:
            hint = unit_slip(v, "m", lambda x: default / 5 <= x <= top)
            raise c.error(
                n,
                n.path,
                f"{fmt(v)} m: above {fmt(top)} m, implausible for {what} (the default is "
                f"{fmt(default)} m; a Crazyflie 2.x is 92 mm across); lengths are in m{hint}",
            )
        return v

    return read


def _flight_rate(c: Checker, n: YNode) -> float:
    v = c.number(n)
    top = FIRMWARE_POSITION_RATE_HZ
    if v < m.MIN_RATE_HZ:
        hint = period_slip(v, lambda x: m.MIN_RATE_HZ <= x <= top)
        raise c.error(n, n.path, f"must be {RATE_HZ.text}, got {n.raw or fmt(v)}{hint}")
    if v > top:
        raise c.error(
            n,
            n.path,
            f"{fmt(v)} Hz: above the firmware's {fmt(top)} Hz position loop (POSITION_RATE), "
            f"which never acts on a faster stream; rates are in Hz",
        )
    return v


def _mocap_rate(c: Checker, n: YNode) -> float:
    v = c.number(n, POSITIVE)
    top = FIRMWARE_MAIN_LOOP_HZ
    if v > top:
        raise c.error(
            n,
            n.path,
            f"{fmt(v)} Hz: above the Crazyflie's {fmt(top)} Hz main loop (RATE_MAIN_LOOP), "
            f"which could use no faster poses; rates are in Hz",
        )
    return v


# YAML key -> (dataclass field, reader)
RATE_HZ = Bound(
    f"at least {m.MIN_RATE_HZ:g} Hz, so the loop watchdog acts before the Crazyflie's "
    f"{m.FIRMWARE_SETPOINT_WATCHDOG_S:g} s setpoint watchdog levels the drones out",
    lambda x: x >= m.MIN_RATE_HZ,
)
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
    # kind motioncapture: read as they are here, checked against the library's table in MissionParser.mocap
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
