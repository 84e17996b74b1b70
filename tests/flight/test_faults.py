"""The fault schedule's ``ground_station_kill`` and ``dongle_unplug`` (docs/faults.md): what parses, each error's one
line, and when the injection applies them on the flight's phase timeline (without killing anything: the kill is
the test's own)."""

from __future__ import annotations

import threading
import time
from types import SimpleNamespace

import pytest

from rpf_fly.flight.events import INFO, EventBus
from rpf_fly.flight.fault_injection import FaultInjection, StallableMocap
from rpf_fly.flight.faults import Fault, parse_faults
from rpf_fly.flight.phases import SwarmPhase
from rpf_fly.mission import parse_mission
from rpf_fly.mission.errors import MissionError

TWO_DONGLES = """\
name: two-dongles
arena: {x: [-2.0, 2.0], y: [-2.0, 2.0], z: [0.0, 1.5]}
flight: {height: 0.5, speed: 0.5, rate_hz: 10, goal_tolerance: 0.1, takeoff_s: 0.3, land_s: 1.0, timeout_s: 30}
mocap: {kind: sim, rate_hz: 100}
drones:
  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [-1.0, -0.6], goal: [1.0, -0.6]}
  - {name: cf2, uri: radio://2/80/2M/E7E7E7E702, start: [-1.0, 0.0], goal: [1.0, 0.0]}
"""


@pytest.fixture
def mission():  # type: ignore[no-untyped-def]
    return parse_mission(TWO_DONGLES)


def parse(mission, *entries: str) -> list[Fault]:  # type: ignore[no-untyped-def]
    return parse_faults("faults:\n" + "".join(f"  - {e}\n" for e in entries), "f.yaml", mission)


def test_both_kinds_parse_with_their_fields_and_the_kill_counts_from_its_phase(mission) -> None:
    kill, late, unplug, other = parse(
        mission,
        "{kind: ground_station_kill, at_phase: takeoff}",
        "{kind: ground_station_kill, at_phase: landing, at_s: 1.5}",
        "{kind: dongle_unplug, dongle: 2, at_s: 3}",
        "{kind: occlusion, drone: cf1, at_s: 2, duration_s: 1}",
    )
    assert (kill.kind, kill.drone, kill.at_s, kill.params, kill.phase) == (
        "ground_station_kill",
        None,
        0.0,
        {"at_phase": "takeoff"},
        "takeoff",
    )  # at_s defaults to 0
    assert (late.at_s, late.phase) == (1.5, "landing")
    assert (unplug.drone, unplug.at_s, unplug.params, unplug.phase) == (None, 3.0, {"dongle": 2}, "planning")
    assert other.phase == "planning"  # every other timed kind counts from the planning phase
    assert (kill.target, unplug.target) == ("ground station", "radio")
    for phase in ("settle", "planning"):
        assert parse(mission, f"{{kind: ground_station_kill, at_phase: {phase}}}")[0].phase == phase


@pytest.mark.parametrize(
    "entry, line",
    [
        (
            "{kind: ground_station_kil, at_phase: takeoff}",
            "f.yaml:2: faults[0].kind: unknown fault kind 'ground_station_kil' (did you mean 'ground_station_kill'?); "
            "one of occlusion, ",
        ),
        (
            "{kind: dongle_unplg, dongle: 0, at_s: 1}",
            "f.yaml:2: faults[0].kind: unknown fault kind 'dongle_unplg' (did you mean 'dongle_unplug'?); one of ",
        ),
        (
            "{kind: ground_station_kill}",
            "f.yaml:2: faults[0].at_phase: missing (the ground_station_kill fault needs at_phase)",
        ),
        (
            "{kind: ground_station_kill, at_phase: planing}",
            "f.yaml:2: faults[0].at_phase: expected one of takeoff, settle, planning, landing, got 'planing' "
            "(did you mean 'planning'?)",
        ),
        (
            "{kind: ground_station_kill, at_phase: flying}",
            "f.yaml:2: faults[0].at_phase: expected one of takeoff, settle, planning, landing, got 'flying' "
            "(did you mean 'planning'?)",
        ),
        (
            "{kind: ground_station_kill, at_phase: 3}",
            "f.yaml:2: faults[0].at_phase: expected one of takeoff, settle, planning, landing, got '3'",
        ),
        (
            "{kind: ground_station_kill, at_phase: takeoff, at_s: -1}",
            "f.yaml:2: faults[0].at_s: expected seconds >= 0, got -1",
        ),
        (
            "{kind: ground_station_kill, at_phase: takeoff, drone: cf1}",
            "f.yaml:2: faults[0].drone: not a field of a ground_station_kill fault; its fields: at_phase, at_s, kind",
        ),
        (
            "{kind: dongle_unplug, dongle: 1, at_s: 1}",
            "f.yaml:2: faults[0].dongle: expected a dongle of the mission (the first number of its radio URIs: 0, 2), "
            "got '1'",
        ),
        (
            "{kind: dongle_unplug, dongle: radio, at_s: 1}",
            "f.yaml:2: faults[0].dongle: expected a dongle of the mission (the first number of its radio URIs: 0, 2), "
            "got 'radio'",
        ),
        (
            "{kind: dongle_unplug, dongle: 2.0, at_s: 1}",
            "f.yaml:2: faults[0].dongle: expected a dongle of the mission (the first number of its radio URIs: 0, 2), "
            "got '2.0'",
        ),
        (
            "{kind: dongle_unplug, at_s: 1}",
            "f.yaml:2: faults[0].dongle: missing (the dongle_unplug fault needs at_s, dongle)",
        ),
        (
            "{kind: dongle_unplug, dongle: 0}",
            "f.yaml:2: faults[0].at_s: missing (the dongle_unplug fault needs at_s, dongle)",
        ),
        (
            "{kind: dongle_unplug, dongle: 0, at_s: 1, drone: cf1}",
            "f.yaml:2: faults[0].drone: not a field of a dongle_unplug fault; its fields: at_s, dongle, kind",
        ),
    ],
)
def test_each_error_is_one_line(mission, entry: str, line: str) -> None:
    with pytest.raises(MissionError) as err:
        parse(mission, entry)
    text = str(err.value)
    assert "\n" not in text
    assert text.startswith(line), text


class _Loop:
    """What the injection reads of a flight loop: its events and its swarm phase."""

    def __init__(self) -> None:
        self.events = EventBus(time.monotonic)
        self.phase = SwarmPhase.CONNECTING

    def enter(self, phase: SwarmPhase, message: str = "") -> None:
        self.phase = phase
        self.events.emit(INFO, "phase", message or f"swarm: {phase.value}")


def test_the_kill_strikes_at_its_phase_and_every_other_kind_counts_from_the_planning_phase(mission) -> None:
    """Phases 0.5 s apart: take-off commanded at 0, planning at 0.5 s (settle: takeoff_s 0.3 s after the take-off),
    landing at 1.0 s. Each kill is due at_s after its own phase's start; the occlusion at_s after the planning
    phase's start, as before."""
    faults = parse(
        mission,
        "{kind: ground_station_kill, at_phase: landing, at_s: 0.1}",
        "{kind: ground_station_kill, at_phase: takeoff, at_s: 0.1}",
        "{kind: ground_station_kill, at_phase: settle}",
        "{kind: ground_station_kill, at_phase: planning, at_s: 0.2}",
        "{kind: occlusion, drone: cf1, at_s: 0.1, duration_s: 1}",
    )
    kills: list[float] = []
    injection = FaultInjection(mission, faults, kill=lambda: kills.append(time.monotonic()))
    hidden: list[float] = []
    rig = SimpleNamespace(
        mocap=StallableMocap(SimpleNamespace()), hide=lambda name, seconds: hidden.append(time.monotonic())
    )
    loop = _Loop()
    seen: list[str] = []
    loop.events.subscribe(lambda e: seen.append(e.message) if e.kind == "fault" else None)
    injection.start(loop, rig)
    try:
        loop.enter(SwarmPhase.TAKEOFF)
        time.sleep(0.2)
        assert not kills  # arming is not the take-off: nothing counts from the swarm's takeoff phase alone
        t0 = time.monotonic()
        loop.events.emit(INFO, "takeoff", "take-off commanded: 2 drone(s) to 0.50 m in 0.3 s")
        time.sleep(0.5 - (time.monotonic() - t0))
        loop.enter(SwarmPhase.FLYING)
        time.sleep(1.0 - (time.monotonic() - t0))
        loop.enter(SwarmPhase.LANDING, "swarm: landing (every flying drone is at its goal)")
        deadline = time.monotonic() + 2.0
        while len(kills) < 4 and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        loop.phase = SwarmPhase.DONE
        injection.close()
    phases = injection.phases
    assert phases["settle"] - phases["takeoff"] == pytest.approx(0.3)
    assert phases["takeoff"] < phases["planning"] < phases["landing"]
    due = [phases["takeoff"] + 0.1, phases["settle"], phases["planning"] + 0.2, phases["landing"] + 0.1]
    assert len(kills) == 4 and all(0.0 <= k - d < 0.05 for k, d in zip(kills, due)), [k - d for k, d in zip(kills, due)]
    assert len(hidden) == 1 and 0.0 <= hidden[0] - (phases["planning"] + 0.1) < 0.05
    assert injection.t0 == phases["planning"]
    kill_events = [m for m in seen if m.startswith("injected ground_station_kill")]
    assert kill_events == [
        "injected ground_station_kill at takeoff + 0.1 s: SIGKILL of this ground station (no landing, no log close)",
        "injected ground_station_kill at settle + 0 s: SIGKILL of this ground station (no landing, no log close)",
        "injected ground_station_kill at planning + 0.2 s: SIGKILL of this ground station (no landing, no log close)",
        "injected ground_station_kill at landing + 0.1 s: SIGKILL of this ground station (no landing, no log close)",
    ]


def test_a_phase_the_flight_never_reaches_injects_nothing(mission) -> None:
    """A flight that ends before its landing phase (here: done from the planning phase) leaves a landing kill
    unapplied, and the injection thread ends with the flight."""
    (fault,) = parse(mission, "{kind: ground_station_kill, at_phase: landing}")
    kills: list[float] = []
    injection = FaultInjection(mission, [fault], kill=lambda: kills.append(time.monotonic()))
    loop = _Loop()
    injection.start(loop, SimpleNamespace(mocap=StallableMocap(SimpleNamespace())))
    loop.enter(SwarmPhase.FLYING)
    loop.phase = SwarmPhase.DONE
    time.sleep(3 * FaultInjection.POLL_S)
    assert injection._thread is not None and not injection._thread.is_alive()  # noqa: SLF001
    injection.close()
    assert not kills and injection.due(fault) is None


def test_dongle_unplug_pulls_out_that_dongle_of_the_fake_radio(mission, monkeypatch) -> None:
    from rpf_fly.emulator import fake_radio

    pulled: list[int] = []
    monkeypatch.setattr(fake_radio, "unplug", lambda devid: pulled.append(devid) or 0)
    (fault,) = parse(mission, "{kind: dongle_unplug, dongle: 2, at_s: 0.05}")
    injection = FaultInjection(mission, [fault])
    loop = _Loop()
    done = threading.Event()
    loop.events.subscribe(lambda e: done.set() if e.message.startswith("injected dongle_unplug") else None)
    injection.start(loop, SimpleNamespace(mocap=StallableMocap(SimpleNamespace())))
    loop.enter(SwarmPhase.FLYING)
    assert done.wait(2.0)
    loop.phase = SwarmPhase.DONE
    injection.close()
    assert pulled == [2]
