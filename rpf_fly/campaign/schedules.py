"""The campaign's fault schedules: each kind's default fault, the lab kinds' runs, and the random draws.

A schedule is what ``rpf-fly fly --faults`` reads (docs/faults.md); the campaign writes one per run so every run is
one ordinary faulted dry run a lab could fly by hand. The defaults are what the fixed campaign injects; the random
draws span what a lab meets, wider than the defaults, so a stack tuned to the defaults alone does not pass.
"""

from __future__ import annotations

import difflib
import json
import math
import random
from typing import Any

from rpf_fly.flight.faults import GROUND_STATION_PHASES
from rpf_fly.mission.model import Mission
from rpf_fly.radio.budget import dongle_of

AT_S = 3.0
"""When the fixed campaign's timed faults strike: seconds into the planning phase."""

DEFAULTS: dict[str, dict[str, Any]] = {
    "occlusion": {"duration_s": 1.0},
    "blackout": {"duration_s": 2.0},
    "pose_jump": {"duration_s": 0.3, "offset_m": [0.6, 0.0, 0.0]},
    "orientation_flip": {"duration_s": 1.0, "deg": 180},
    "mocap_delay": {"duration_s": 3.0, "delay_s": 0.08},
    "link_drop": {},
    "packet_loss": {"duration_s": 4.0, "rate": 0.5},
    "low_battery": {},
    "planner_error": {},
    "planner_hang": {"duration_s": 2.0},
    "loop_stall": {"duration_s": 1.0},
    "yaw_offset": {"deg": 120},
    "start_offset": {"offset_m": [0.5, 0.0]},
    "upside_down": {},
    "motor_fault": {},
    "gust": {"duration_s": 1.0, "accel": [0.0, 1.5, 0.0]},
    "estimator_divergence": {"rate_m_s": 0.3},
    "reboot": {},
}
"""Each dry-run kind's parameters in the fixed campaign (a kind's fault names the mission's middle drone)."""

UNPLUG_AT_S = 3.0
"""When a dongle is pulled out: seconds into the planning phase."""
KILL_AT_S: dict[str, float] = {"takeoff": 1.6, "settle": 0.2, "planning": 3.0, "landing": 0.7}
"""A kill in each phase (`GROUND_STATION_PHASES`): 1.6 s into a 2 s take-off (a Crazyflie leaves the floor about
half way through its take-off, docs/flight.md "Take-off": a kill at 1 s found no drone airborne on the firmware
model), inside the 0.5 s settle, 3 s into the planning, half way down a 2 s landing's first metre."""
LAB_KINDS = frozenset({"ground_station_kill", "dongle_unplug"})
"""The kinds that leave drones without a ground station: they fly against a lab (`rpf-fly lab`), whose log outlives
the flight's process."""
LAB_RUNS: list[tuple[str, str, dict[str, Any]]] = [
    *[
        ("ground_station_kill", mission, {"at_phase": phase, "at_s": KILL_AT_S[phase]})
        for mission in ("lab-3", "circle-8-r3")
        for phase in GROUND_STATION_PHASES
    ],
    ("dongle_unplug", "campaign/pillars-6", {"dongle": 1, "at_s": UNPLUG_AT_S}),
    ("dongle_unplug", "radio/split-10", {"dongle": 1, "at_s": UNPLUG_AT_S}),
]
"""The fixed campaign's lab runs (kind, shipped mission under missions/, the fault's fields): the kill in each phase on
lab-3 and circle-8-r3, the unplug of dongle 1 on the shipped missions with two dongles."""
ALL_KINDS: tuple[str, ...] = (*DEFAULTS, *sorted(LAB_KINDS))

SWARM_KINDS = frozenset({"blackout", "mocap_delay", "loop_stall"})
"""Kinds that name no drone: they strike the whole swarm."""
POWER_ON = frozenset({"yaw_offset", "start_offset", "upside_down", "motor_fault"})
"""Kinds that act before the flight (how a drone stands at power-on): no ``at_s``."""


class ScheduleError(ValueError):
    """A campaign asked for something no schedule can hold (an unknown kind, a lab kind in a random draw)."""


def check_kinds(kinds: list[str], allowed: tuple[str, ...] = ALL_KINDS, option: str = "--kinds") -> list[str]:
    """``kinds`` when each is one ``allowed``; else `ScheduleError` naming the first unknown one, with the kind it
    is closest to (a misspelt kind) or the list of kinds."""
    if not kinds:
        raise ScheduleError(f"{option}: no kind given; expected some of {', '.join(allowed)}")
    for kind in kinds:
        if kind not in allowed:
            close = difflib.get_close_matches(kind, list(allowed), n=1)
            hint = f"did you mean {close[0]!r}?" if close else f"expected one of {', '.join(allowed)}"
            raise ScheduleError(f"{option}: unknown fault kind {kind!r} ({hint})")
    return kinds


def fault_fields(
    kind: str, drone: str | None, params: dict[str, Any] | None = None, at_s: float = AT_S
) -> dict[str, Any]:
    """One fault's schedule entry: the kind's `DEFAULTS` unless ``params`` are given (a random draw's)."""
    return {
        "kind": kind,
        **({} if kind in SWARM_KINDS else {"drone": drone}),
        **({} if kind in POWER_ON else {"at_s": at_s}),
        **(DEFAULTS[kind] if params is None else params),
    }


def schedule_of(faults: list[dict[str, Any]]) -> str:
    """The schedule file's text for ``faults`` (entries of `fault_fields`; several at once: a compound failure)."""
    return "faults:\n" + "".join(f"  - {json.dumps(f)}\n" for f in faults)


def schedule(kind: str, drone: str | None, params: dict[str, Any] | None = None, at_s: float = AT_S) -> str:
    """The one-fault schedule's text."""
    return schedule_of([fault_fields(kind, drone, params, at_s)])


def middle_drone_fault(kind: str, mission: Mission) -> dict[str, Any]:
    """The fixed campaign's fault of ``kind`` on ``mission``: the kind's defaults, on the middle drone, at `AT_S`."""
    names = [d.name for d in mission.drones]
    return fault_fields(kind, None if kind in SWARM_KINDS else names[len(names) // 2])


def lab_faults(mission: Mission, kinds: list[str]) -> list[dict[str, Any]]:
    """The lab kinds' faults among ``kinds`` on any mission: the kill in every phase, the unplug of the mission's
    highest dongle (on a one-dongle mission that is every drone's)."""
    faults: list[dict[str, Any]] = []
    if "ground_station_kill" in kinds:
        faults += [
            {"kind": "ground_station_kill", "at_phase": phase, "at_s": KILL_AT_S[phase]}
            for phase in GROUND_STATION_PHASES
        ]
    if "dongle_unplug" in kinds:
        faults.append(
            {"kind": "dongle_unplug", "dongle": max(dongle_of(d.uri) for d in mission.drones), "at_s": UNPLUG_AT_S}
        )
    return faults


def _direction(rng: random.Random, length: float, dims: int = 2) -> list[float]:
    angle = rng.uniform(-math.pi, math.pi)
    vec = [length * math.cos(angle), length * math.sin(angle)]
    return [round(v, 3) for v in vec] + ([0.0] if dims == 3 else [])


def random_fault(rng: random.Random, kind: str, start_tolerance_m: float) -> dict[str, Any]:
    """Parameters of one fault of ``kind`` drawn over what a lab meets (wider than `DEFAULTS`, within what a flight
    is expected to survive: a gust a Crazyflie's controller can fight, a pose jump of a marker swap)."""
    u = rng.uniform
    draws: dict[str, Any] = {
        "occlusion": lambda: {"duration_s": round(u(0.15, 3.0), 2)},
        "blackout": lambda: {"duration_s": round(u(0.15, 3.0), 2)},
        "pose_jump": lambda: {"duration_s": round(u(0.05, 1.0), 2), "offset_m": _direction(rng, u(0.3, 1.5), 3)},
        # a turn of a nearly symmetric marker set's wrong fit: 90 or 180 degrees on a square or a line, tens on others
        "orientation_flip": lambda: {
            "duration_s": round(u(0.1, 3.0), 2),
            "deg": round(rng.choice((-1, 1)) * u(30.0, 180.0), 1),
        },
        "mocap_delay": lambda: {"duration_s": round(u(1.0, 4.0), 2), "delay_s": round(u(0.02, 0.15), 3)},
        "link_drop": lambda: {},
        # under 28 % of the attempts lost, cflib's link quality dips no lower than in a lab's normal bursts; near
        # 30 % its 100-ack average takes about 2 s to cross the warning
        "packet_loss": lambda: {"duration_s": round(u(1.0, 5.0), 2), "rate": round(u(0.35, 0.8), 2)},
        "low_battery": lambda: {},
        "planner_error": lambda: {},
        "planner_hang": lambda: {"duration_s": round(u(0.3, 3.0), 2)},
        "loop_stall": lambda: {"duration_s": round(u(0.1, 2.0), 2)},
        "yaw_offset": lambda: {"deg": round(rng.choice((-1, 1)) * u(15.0, 180.0), 1)},
        "start_offset": lambda: {"offset_m": _direction(rng, u(start_tolerance_m + 0.05, 0.8))},
        "upside_down": lambda: {},
        "motor_fault": lambda: {},
        # a push that moves a drone less than a real one's normal tracking error (5 cm) is noise to any stack
        "gust": lambda: {"duration_s": round(u(1.0, 1.5), 2), "accel": _direction(rng, u(1.0, 2.0), 3)},
        "estimator_divergence": lambda: {"rate_m_s": round(u(0.1, 0.6), 2)},
        "reboot": lambda: {},
    }
    return draws[kind]()


def draw_faults(
    rng: random.Random, mission: Mission, kinds: list[str] | None, faults_per_run: int
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """One random run's faults: ``faults_per_run`` of different kinds (of ``kinds``, default every dry-run kind),
    each with its drone, time (0.5-6 s into the planning phase) and parameters drawn from ``rng``; and the draws as
    the report shows them (a swarm kind without a drone, a power-on kind without a time). The draw order is fixed:
    one fault a run draws, seed for seed, what the campaigns before compound faults drew."""
    names = [d.name for d in mission.drones]
    pool = sorted(kinds or DEFAULTS)
    faults, draws = [], []
    for _ in range(min(faults_per_run, len(pool))):
        kind = rng.choice(pool)
        pool.remove(kind)
        params = random_fault(rng, kind, mission.safety.start_tolerance_m)
        drone = names[rng.randrange(len(names))]
        at_s = round(rng.uniform(0.5, 6.0), 2)
        faults.append(fault_fields(kind, None if kind in SWARM_KINDS else drone, params, at_s))
        draws.append(
            {
                "kind": kind,
                **({} if kind in SWARM_KINDS else {"drone": drone}),
                **({} if kind in POWER_ON else {"at_s": at_s}),
                **params,
            }
        )
    return faults, draws
