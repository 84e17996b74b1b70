"""Our own schemas of the log: ``rpf_fly.PlannerStep``, ``rpf_fly.DroneStatus``, ``rpf_fly.TruthState`` (dry runs
only), ``rpf_fly.RadioLoad``, and a lab's ``rpf_fly.FirmwareState`` and ``rpf_fly.HostLag``, with the values their
fields name.

They follow Foxglove's conventions (rpf_fly/log/schema_parts.py): times ``{"sec", "nsec"}``, planar vectors
``{"x", "y"}``, unknown values ``null``. See docs/log-format.md for what each field means; the registry of every
schema the log writes is rpf_fly/log/schemas.py.
"""

from __future__ import annotations

from typing import Any

from rpf_fly.log.schema_parts import (
    nullable_num as _nullable_num,
)
from rpf_fly.log.schema_parts import (
    num as _num,
)
from rpf_fly.log.schema_parts import (
    obj as _obj,
)
from rpf_fly.log.schema_parts import (
    time as _time,
)
from rpf_fly.log.schema_parts import (
    vector2 as _vector2,
)

PLANNER_MODES = (
    "apf",
    "wall",
    "soft",
    "arrived",
    "stalled",
    "hold",
    "takeoff",
    "landing",
    "landed",
    "link_lost",
    "emergency",
)
"""Values of ``rpf_fly.PlannerStep.mode``: the rule that chose the direction (apf, wall, soft), or what the drone did
instead of planning (arrived, hold, and the flight phases in which it does not plan)."""

MODE_NAMES = {0: "apf", 1: "wall", 2: "soft", -1: "arrived"}
"""Planner mode codes (``PlanStep.mode``, ``Rollout.modes``) to their log names."""

DRONE_STATES = (
    "waiting",
    "ready",
    "takeoff",
    "planning",
    "holding",
    "arrived",
    "landing",
    "landed",
    "failed",
    "grounded",
    "link_lost",
    "emergency",
)
"""The flight states a ``rpf_fly.DroneStatus`` names: the drone phases (rpf_fly/flight/phases.py; a test keeps them
equal). The schema accepts any string."""

PLANNER_STEP: dict[str, Any] = _obj(
    {
        "timestamp": _time("Time of the planning tick"),
        "tick": {"type": "integer", "minimum": 0, "description": "Planning step index from 0"},
        "position": _obj({"x": _num(), "y": _num(), "z": _num()}, description="The pose the planner used (m)"),
        "goal": _vector2("The drone's goal (m)"),
        "eta": _nullable_num("Obstacle repulsion gain; null for planners without gains"),
        "lambda": _nullable_num("Inter-robot repulsion gain; null for planners without gains"),
        "f_a": _vector2("Attractive force"),
        "f_r": _vector2("Obstacle repulsive force"),
        "f_in": _vector2("Inter-robot repulsive force"),
        "direction": _vector2("Planned unit direction (zero when stalled or holding)"),
        "mode": {"type": "string", "enum": list(PLANNER_MODES), "description": "Which rule chose the direction"},
        "heading": _num("Heading of the drone (rad, counter-clockwise from +x)"),
        "neighbours": {"type": "integer", "minimum": 0, "description": "Neighbours that exerted a force"},
        "obstacle_distance": _nullable_num("Distance to the nearest visible obstacle surface (m); null if none"),
        "goal_distance": _num("Distance to the goal (m)"),
        "reference": _vector2(
            "Where the drone planned from: its reference (its own position in its view) before "
            "the step (m); only on ticks it planned (for rpf-fly replay)"
        ),
    },
    required=(
        "timestamp",
        "tick",
        "position",
        "goal",
        "eta",
        "lambda",
        "f_a",
        "f_r",
        "f_in",
        "direction",
        "mode",
        "heading",
        "neighbours",
        "obstacle_distance",
        "goal_distance",
    ),
    title="rpf_fly.PlannerStep",
    description="One planning tick of one drone",
)

DRONE_STATUS: dict[str, Any] = _obj(
    {
        "timestamp": _time("Time of the status"),
        "state": {"type": "string", "description": "Flight state: " + ", ".join(DRONE_STATES)},
        "battery_v": _nullable_num("Battery voltage (V); null if unknown"),
        "link_quality": {
            "type": ["number", "null"],
            "minimum": 0,
            "maximum": 1,
            "description": "Radio link quality 0..1; null if unknown",
        },
        "latency_ms": _nullable_num("Radio round-trip latency (ms); null if unknown"),
        "outcome": {"type": ["string", "null"], "description": "null while flying; reached, stalled, timeout, ..."},
        "estimate": {
            "type": ["object", "null"],
            "properties": {"x": _num(), "y": _num(), "z": _num()},
            "description": "The on-board estimate of the drone's position (m), as its firmware logs it; "
            "null if unknown",
        },
        "target": {
            "type": ["object", "null"],
            "properties": {"x": _num(), "y": _num(), "z": _num()},
            "description": "Where the drone's own controller is taking it (m): the streamed setpoint, or the "
            "high-level take-off's or landing's point; null if the firmware does not log it",
        },
    },
    required=("timestamp", "state", "battery_v", "link_quality", "latency_ms", "outcome"),
    title="rpf_fly.DroneStatus",
    description="State, battery and link of one drone",
)

TRUTH_STATE: dict[str, Any] = _obj(
    {
        "timestamp": _time("When the simulated world was in this state"),
        "position": _obj({"x": _num(), "y": _num(), "z": _num()}, description="The drone's true centre (m)"),
        "yaw": _num("True yaw (rad, counter-clockwise from +x)"),
        "motors": {"type": "boolean", "description": "The motors spin"},
        "crashed": {"type": "boolean", "description": "The drone hit another drone or an obstacle (locked)"},
        "estimate": _obj({"x": _num(), "y": _num(), "z": _num()}, description="The firmware's estimated position (m)"),
    },
    title="rpf_fly.TruthState",
    description="One drone's true state in a dry run's simulated world (not measured: real flights have none)",
)

RADIO_LOAD: dict[str, Any] = _obj(
    {
        "timestamp": _time("End of the window"),
        "dongle": {"type": "integer", "minimum": 0, "description": "The dongle number (the URI's first number)"},
        "drones": {"type": "array", "items": {"type": "string"}, "description": "The drones on this dongle"},
        "window_s": _num("Length of the window (s)"),
        "packets": _num("Uplink packets acknowledged in the window: setpoints, extpos, commands, cflib's pings"),
        "transactions": _num("Radio transactions acknowledged in the window, cflib's empty polls included"),
        "packets_per_s": _num("packets / window_s: the dongle's measured load"),
        "transactions_per_s": _num("transactions / window_s: the dongle's air in use (polls yield to packets)"),
        "planned_per_s": _num(
            "What the radio budget counts for this dongle while the drones stream setpoints "
            "(rpf_fly.radio.budget: setpoints + extpos or packed broadcasts + pings + "
            "keep-alives)"
        ),
        "budget_per_s": _num(
            "What this dongle carries of that mix (the dongle type's figures, scaled to "
            "radio.budget_packets_s when given)"
        ),
        "setpoints_superseded": _num(
            "Setpoints of this dongle's drones replaced by a newer one before the radio took "
            "them (the radio lagged; rpf_fly/radio/outbox.py)"
        ),
    },
    required=(
        "timestamp",
        "dongle",
        "drones",
        "window_s",
        "packets",
        "transactions",
        "packets_per_s",
        "transactions_per_s",
        "planned_per_s",
        "budget_per_s",
    ),
    title="rpf_fly.RadioLoad",
    description="One dongle's measured radio load over one window, from cflib's link statistics",
)

FIRMWARE_STATE: dict[str, Any] = _obj(
    {
        "timestamp": _time("When the simulated firmware was in this state"),
        "powered": {"type": "boolean", "description": "The flight stack runs (false while a reboot boots)"},
        "supervisor": {
            "type": "string",
            "description": "The supervisor's state, named as in the firmware "
            "(supervisor_state_machine.c): 'Pre-flight checks passed', "
            "'Flying', 'Locked', ...",
        },
        "armed": {"type": "boolean", "description": "The supervisor is armed"},
        "motors": {"type": "boolean", "description": "The motors spin"},
        "flying": {"type": "boolean", "description": "The supervisor's is-flying condition"},
        "locked": {"type": "boolean", "description": "Locked: only a reboot leaves it"},
        "crashed": {"type": "boolean", "description": "The drone hit another drone or an obstacle"},
        "emergency_stop": {
            "type": "boolean",
            "description": "An emergency stop (command, parameter or the emergency-stop watchdog) is latched",
        },
        "commander": {
            "type": "string",
            "description": "Who feeds the controller: the streamed (CRTP) setpoints or the high-level commander",
        },
        "high_level": {"type": "string", "description": "The high-level commander's state"},
        "setpoint_age_s": {
            "type": ["number", "null"],
            "description": "Seconds since the last streamed setpoint (null: none since power-on)",
        },
        "battery_v": _num("Battery voltage (V)"),
        "boots": {"type": "integer", "description": "Reboots since the lab started"},
    },
    required=("timestamp", "supervisor", "motors", "locked", "commander", "high_level"),
    title="rpf_fly.FirmwareState",
    description="One simulated Crazyflie's firmware state in a lab (rpf-fly lab): what its supervisor and "
    "commander do, whoever is connected",
)

HOST_LAG: dict[str, Any] = _obj(
    {
        "timestamp": _time("When the figures were read"),
        "bound_s": _num("A step or frame later than this against its schedule counts as behind (s)"),
        "behind_s": _num("Seconds so far during which the simulated world ran behind the bound"),
        "world": {"type": "object", "description": "The 100 Hz physics steps: runs, late_runs, max_late_s, behind_s"},
        "natnet": {"type": ["object", "null"], "description": "The NatNet emulator's frames (same fields)"},
        "links": {
            "type": ["object", "null"],
            "description": "The fake radio links' transactions in the reading process (same fields; null: not read)",
        },
    },
    required=("timestamp", "bound_s", "behind_s", "world"),
    title="rpf_fly.HostLag",
    description="How far the host let the simulated world fall behind its own time (rpf_fly/emulator/host_lag.py)",
)
