"""Fault schedules for dry runs: ``rpf-fly fly MISSION --dry-run --faults FAULTS.yaml`` (docs/faults.md).

A schedule lists faults injected into the simulated world (mocap, radio, the drones' firmware) or into the flight's
own process (a drone's planner, the loop thread, a Crazyradio, the process itself) at ``at_s`` seconds after the
start of the planning phase, so a lab can rehearse what its stack does when something breaks before it happens with
real drones. Some kinds act at power-on instead (``yaw_offset``, ``start_offset``, ``upside_down``,
``motor_fault``: how a drone stands before the flight). One kind counts its ``at_s`` from a phase of its own
choosing: ``ground_station_kill`` (``at_phase``: takeoff, settle, planning or landing; ``at_s`` default 0).

The file is validated like a mission (one line ``FILE:LINE: FIELD: problem``, exit 2), against the mission: every
``drone`` must be one of its drones, every ``dongle`` one of its dongles. Loading is pure;
:mod:`rpf_fly.flight.fault_injection` applies a schedule.
"""

from __future__ import annotations

import difflib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rpf_fly.mission.errors import MissionError
from rpf_fly.mission.model import Mission
from rpf_fly.mission.yaml_nodes import ROOT, YNode, child_path, compose
from rpf_fly.radio.budget import dongle_of

__all__ = ["FAULT_KINDS", "GROUND_STATION_PHASES", "Fault", "FaultKind", "load_faults", "parse_faults"]

GROUND_STATION_PHASES = ("takeoff", "settle", "planning", "landing")
"""The phases a ``ground_station_kill`` counts its ``at_s`` from: ``takeoff`` when the take-off commands were sent
(the ``take-off commanded`` event), ``settle`` the mission's ``flight.takeoff_s`` after that (the drones hover at
height before planning), ``planning`` the swarm's flying phase (``swarm: flying``, where every other timed kind
counts from), ``landing`` the swarm's landing phase (``swarm: landing``)."""


@dataclass(frozen=True)
class FaultKind:
    """What one kind of fault needs: a drone or not, a start time or not (power-on), a duration or not, and its
    own parameters (name -> (reader, required))."""

    doc: str
    drone: bool
    timed: bool = True
    duration: bool = False
    params: dict[str, tuple[str, bool]] = field(default_factory=dict)
    """param -> (type: 'positive', 'fraction', 'number', 'vec2', 'vec3', 'choice', 'dongle'), required."""
    choices: dict[str, tuple[str, ...]] = field(default_factory=dict)
    """A 'choice' param -> the words it takes."""
    at_s_default: float | None = None
    """``at_s`` when the schedule leaves it out (None: required)."""


FAULT_KINDS: dict[str, FaultKind] = {
    "occlusion": FaultKind("the drone's rigid body untracked in the NatNet frames", True, duration=True),
    "blackout": FaultKind("no NatNet frames carry any tracked body", False, duration=True),
    "pose_jump": FaultKind(
        "the drone's body reported offset_m away (a marker swap)",
        True,
        duration=True,
        params={"offset_m": ("vec3", True)},
    ),
    "orientation_flip": FaultKind(
        "the drone's body reported turned by deg about the vertical (a wrong fit of its markers)",
        True,
        duration=True,
        params={"deg": ("number", True)},
    ),
    "mocap_delay": FaultKind(
        "every frame carries poses delay_s old", False, duration=True, params={"delay_s": ("positive", True)}
    ),
    "link_drop": FaultKind("the drone's radio link lost for good (its firmware levels, then cuts)", True),
    "packet_loss": FaultKind(
        "the drone's radio attempts lost with probability rate",
        True,
        duration=True,
        params={"rate": ("fraction", True)},
    ),
    "low_battery": FaultKind("the drone's battery sags to a low voltage", True),
    "planner_error": FaultKind("the drone's planner raises from at_s on", True),
    "planner_hang": FaultKind("the drone's planner blocks for duration_s", True, duration=True),
    "loop_stall": FaultKind("the flight loop's thread blocks for duration_s", False, duration=True),
    "yaw_offset": FaultKind(
        "the drone stands rotated by deg at power-on", True, timed=False, params={"deg": ("number", True)}
    ),
    "start_offset": FaultKind(
        "the drone stands offset_m (x, y) from its mission start",
        True,
        timed=False,
        params={"offset_m": ("vec2", True)},
    ),
    "upside_down": FaultKind(
        "the drone lies on its back at power-on (its supervisor reports tumbled)", True, timed=False
    ),
    "motor_fault": FaultKind("a motor of the drone fails the arming spin-up check", True, timed=False),
    "gust": FaultKind(
        "an external acceleration accel (m/s^2) on the drone", True, duration=True, params={"accel": ("vec3", True)}
    ),
    "estimator_divergence": FaultKind(
        "the drone's estimator stops taking extpos and runs away at rate_m_s",
        True,
        params={"rate_m_s": ("positive", True)},
    ),
    "reboot": FaultKind("the drone browns out: motors off, radio silent while it boots", True),
    "ground_station_kill": FaultKind(
        "the ground station (this flight's process) is SIGKILLed at_s after the start "
        "of at_phase: nothing of it runs any more, no landing, no log close",
        False,
        params={"at_phase": ("choice", True)},
        choices={"at_phase": GROUND_STATION_PHASES},
        at_s_default=0.0,
    ),
    "dongle_unplug": FaultKind(
        "the Crazyradio of that dongle number is pulled out: every link on it fails with cflib's link error, for good",
        False,
        params={"dongle": ("dongle", True)},
    ),
}
"""Every fault kind a schedule may name."""

LOW_BATTERY_OPEN_CIRCUIT_V = 3.3
"""``low_battery``: the open-circuit voltage the battery drops to (about 3.05 V under hover load, under the
supervisor's in-flight threshold of ``radio.min_battery_v`` - 0.4 V for the default 3.7 V)."""


@dataclass(frozen=True)
class Fault:
    """One scheduled fault. ``at_s`` counts from the start of the planning phase (None: at power-on); for a
    ``ground_station_kill`` from the start of its ``at_phase`` (`phase`)."""

    kind: str
    drone: str | None = None
    at_s: float | None = None
    duration_s: float | None = None
    params: dict[str, Any] = field(default_factory=dict)
    line: int = 0

    @property
    def phase(self) -> str:
        """The flight phase ``at_s`` counts from: the fault's ``at_phase``, else ``planning``."""
        return str(self.params.get("at_phase", "planning"))

    @property
    def target(self) -> str:
        """Who the fault names in the events it should cause: its drone, or mocap / loop / radio / ground
        station."""
        if self.drone is not None:
            return self.drone
        return {"loop_stall": "loop", "dongle_unplug": "radio", "ground_station_kill": "ground station"}.get(
            self.kind, "mocap"
        )

    @property
    def ends_at_s(self) -> float | None:
        if self.at_s is None:
            return None
        return self.at_s + (self.duration_s or 0.0)


def _fail(file: str, node: YNode | int, path: str, message: str) -> MissionError:
    return MissionError(file, node if isinstance(node, int) else node.line, path, message)


def _number(file: str, node: YNode, check: Callable[[float], bool], expected: str) -> float:
    v = node.value
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not check(float(v)):
        raise _fail(file, node, node.path, f"expected {expected}, got {node.raw if node.raw else repr(v)}")
    return float(v)


def _vector(file: str, node: YNode, n: int) -> tuple[float, ...]:
    items = node.seq if node.is_seq else None
    if items is None or len(items) != n:
        raise _fail(file, node, node.path, f"expected a list of {n} numbers (metres), got {node.raw or node.plain()!r}")
    return tuple(_number(file, item, lambda x: x == x and abs(x) < 1e6, "a finite number") for item in items)


_SAME_AS = {"flying": "planning"}
"""Words a schedule may mean by a choice (the swarm's phase ``flying`` is the planning phase)."""


def _did_you_mean(word: Any, words: tuple[str, ...] | list[str]) -> str:
    """``" (did you mean 'x'?)"`` for the one word of ``words`` close to a misspelt ``word``, else ``""``."""
    if not isinstance(word, str):
        return ""
    close = [_SAME_AS[word]] if _SAME_AS.get(word) in words else difflib.get_close_matches(word, list(words), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _choice(file: str, node: YNode, words: tuple[str, ...]) -> str:
    v = node.value
    if not isinstance(v, str) or v not in words:
        raise _fail(
            file,
            node,
            node.path,
            f"expected one of {', '.join(words)}, got {node.raw or node.plain()!r}{_did_you_mean(v, words)}",
        )
    return v


def _dongle(file: str, node: YNode, dongles: tuple[int, ...]) -> int:
    v = node.value
    if isinstance(v, bool) or not isinstance(v, int) or v not in dongles:
        raise _fail(
            file,
            node,
            node.path,
            f"expected a dongle of the mission (the first number of its radio URIs: "
            f"{', '.join(str(d) for d in dongles)}), got {node.raw or node.plain()!r}",
        )
    return v


@dataclass(frozen=True)
class _Context:
    """What a param reader may check against: the param's words (a choice), the mission's dongles."""

    choices: tuple[str, ...] = ()
    dongles: tuple[int, ...] = ()


_READERS: dict[str, Callable[[str, YNode, _Context], Any]] = {
    "positive": lambda f, n, c: _number(f, n, lambda x: 0 < x < 1e6, "a positive number"),
    "fraction": lambda f, n, c: _number(f, n, lambda x: 0 <= x <= 1, "a number in [0, 1]"),
    "number": lambda f, n, c: _number(f, n, lambda x: x == x and abs(x) < 1e6, "a finite number"),
    "vec2": lambda f, n, c: _vector(f, n, 2),
    "vec3": lambda f, n, c: _vector(f, n, 3),
    "choice": lambda f, n, c: _choice(f, n, c.choices),
    "dongle": lambda f, n, c: _dongle(f, n, c.dongles),
}


def _fault(file: str, node: YNode, drones: set[str], dongles: tuple[int, ...]) -> Fault:
    if not node.is_map:
        raise _fail(file, node, node.path, f"expected a mapping {{kind: ..., ...}}, got {node.raw or node.plain()!r}")
    entries = node.mapping
    if "kind" not in entries:
        raise _fail(file, node, child_path(node.path, "kind"), f"missing; one of {', '.join(FAULT_KINDS)}")
    kind_node = entries["kind"]
    kind = kind_node.value
    if kind not in FAULT_KINDS:
        raise _fail(
            file,
            kind_node,
            kind_node.path,
            f"unknown fault kind {kind!r}{_did_you_mean(kind, list(FAULT_KINDS))}; one of {', '.join(FAULT_KINDS)}",
        )
    spec = FAULT_KINDS[str(kind)]
    allowed = (
        {"kind"}
        | set(spec.params)
        | ({"drone"} if spec.drone else set())
        | ({"at_s"} if spec.timed else set())
        | ({"duration_s"} if spec.duration else set())
    )
    for key, value in entries.items():
        if key not in allowed:
            raise _fail(
                file,
                value.key_line,
                value.path,
                f"not a field of a {kind} fault; its fields: {', '.join(sorted(allowed))}",
            )
    required = [
        k
        for k in sorted(allowed - {"kind"})
        if (k not in spec.params or spec.params[k][1]) and not (k == "at_s" and spec.at_s_default is not None)
    ]
    for key in required:
        if key not in entries:
            raise _fail(
                file, node, child_path(node.path, key), f"missing (the {kind} fault needs {', '.join(required)})"
            )
    drone = None
    if spec.drone:
        d = entries["drone"]
        if not isinstance(d.value, str) or d.value not in drones:
            raise _fail(
                file,
                d,
                d.path,
                f"expected one of the mission's drones ({', '.join(sorted(drones))}), got {d.raw or d.value!r}",
            )
        drone = d.value
    at_s = None
    if spec.timed:
        at_s = (
            _number(file, entries["at_s"], lambda x: 0 <= x < 1e6, "seconds >= 0")
            if "at_s" in entries
            else spec.at_s_default
        )
    duration = _number(file, entries["duration_s"], lambda x: 0 < x < 1e6, "seconds > 0") if spec.duration else None
    params = {
        k: _READERS[t](file, entries[k], _Context(spec.choices.get(k, ()), dongles))
        for k, (t, _) in spec.params.items()
        if k in entries
    }
    return Fault(str(kind), drone, at_s, duration, params, node.line)


def parse_faults(text: str, source: Path | str, mission: Mission) -> list[Fault]:
    """Validate a fault schedule (``faults:`` a list of faults) against ``mission``. Raises MissionError."""
    file = str(source)
    root = compose(text, file)
    if root is None or not root.is_map or "faults" not in root.mapping:
        raise _fail(file, root.line if root is not None else 1, ROOT, "expected a mapping with a 'faults' list")
    for key, value in root.mapping.items():
        if key != "faults":
            raise _fail(file, value.key_line, value.path, "unknown key; a fault file holds only 'faults'")
    items = root.mapping["faults"]
    if not items.is_seq:
        raise _fail(file, items, items.path, "expected a list of faults")
    drones = {d.name for d in mission.drones}
    dongles = tuple(sorted({dongle_of(d.uri) for d in mission.drones}))
    faults = [_fault(file, item, drones, dongles) for item in items.seq]
    seen: dict[tuple[str, str], int] = {}
    for f in faults:
        if not FAULT_KINDS[f.kind].timed and f.drone is not None:
            pair = (f.kind, f.drone)
            if pair in seen:
                raise _fail(file, f.line, f"faults ({f.kind})", f"{f.drone} already has a {f.kind} (line {seen[pair]})")
            seen[pair] = f.line
    return faults


def load_faults(path: str | Path, mission: Mission) -> list[Fault]:
    """Read and validate the fault file at ``path``. Raises :class:`MissionError`."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise MissionError(p, 0, ROOT, "no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise MissionError(p, 0, ROOT, f"cannot read the file: {exc}") from None
    return parse_faults(text.removeprefix("\ufeff"), p, mission)
