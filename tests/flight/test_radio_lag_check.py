"""The radio lag check on a drone's superseded setpoints: a steady share lands the drone, a busy moment does not,
and only what was streamed counts (rpf_fly/flight/radio_lag_check.py)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import pytest
from flight_harness import SHORT_MISSION

from rpf_fly.flight.agent import DroneAgent
from rpf_fly.flight.events import WARNING
from rpf_fly.flight.findings import Finding
from rpf_fly.flight.phases import DronePhase
from rpf_fly.flight.poses import PoseTracker
from rpf_fly.flight.radio_lag_check import SETPOINT_STARVED_S, RadioLagCheck
from rpf_fly.flight.supervisor import Supervisor
from rpf_fly.mission import parse_mission
from rpf_fly.radio.backend import DroneState, LinkState
from rpf_fly.sim.scenario import obstacle_set

MISSION = parse_mission(SHORT_MISSION)


def agent(phase: DronePhase = DronePhase.PLANNING) -> DroneAgent:
    drone = MISSION.drones[0]
    a = DroneAgent(drone, None, height=0.5, speed=0.5, dt=0.1, arena=MISSION.arena, budget_s=1.0)  # type: ignore[arg-type]
    a.set_phase(phase, 0.0)
    return a


@dataclass
class Link:
    """One drone's link as the check reads it: the setpoints superseded so far, and the time."""

    check: RadioLagCheck
    agent: DroneAgent
    t: float = 0.0
    superseded: float = 0.0

    def stream(self, superseded_per_s: float, seconds: float, up: bool = True) -> list[tuple[float, Finding]]:
        """10 Hz setpoints for ``seconds``, ``superseded_per_s`` of them replaced; the check runs at every 10 ms
        mocap frame. The findings and their times."""
        found = []
        base = DroneState(self.agent.name, "radio://0/80/2M/E7E7E7E701", LinkState(up), None, None, None, None)
        for _ in range(int(round(seconds * 100))):
            self.t += 0.01
            self.superseded += superseded_per_s * 0.01
            state = replace(base, setpoints_superseded=int(self.superseded + 1e-9))
            found += [(self.t, f) for f in self.check.check(self.t, [self.agent], {self.agent.name: state})]
        return found


def test_a_steady_share_of_superseded_setpoints_is_said_then_lands_the_drone_and_a_busy_moment_does_not() -> None:
    link = Link(RadioLagCheck(10.0), agent())
    assert not link.stream(superseded_per_s=0.5, seconds=5.0)  # one in twenty: a busy radio, nothing said
    found = link.stream(superseded_per_s=6.0, seconds=3.0)  # 6 of 10 a second never sent, from 5 s
    assert (found[0][1].level, found[0][1].response) == (WARNING, "warn"), found
    assert "% of its setpoints in the last 1 s replaced by newer ones" in found[0][1].message
    lands = [(t, f) for t, f in found if f.response == "land"]
    assert len(lands) == 1 and 6.9 <= lands[0][0] <= 7.1, found  # after two whole windows over 30 %
    assert "landing" in lands[0][1].message and lands[0][1].drone == "cf1"


def test_only_streamed_setpoints_count_and_a_recovered_link_is_said() -> None:
    check = RadioLagCheck(10.0)
    taking_off = Link(check, agent(DronePhase.TAKEOFF))
    assert not taking_off.stream(6.0, 3.0)  # the firmware flies a take-off: nothing streamed, nothing superseded
    link = Link(RadioLagCheck(10.0), agent())
    assert [f.response for _, f in link.stream(superseded_per_s=2.0, seconds=1.5)] == ["warn"]  # 20 %: said
    back = link.stream(superseded_per_s=0.0, seconds=2.5)
    assert [f.message for _, f in back] == ["its radio link carries its setpoints on time again"]
    assert not link.stream(superseded_per_s=6.0, seconds=3.0, up=False)  # a lost link is another check's


def test_the_supervisor_lands_a_drone_whose_radio_lags() -> None:
    supervisor = Supervisor(MISSION, obstacle_set(MISSION.obstacles))
    a = agent()
    tracker = PoseTracker({d.name: d.rigid_body for d in MISSION.drones})
    base = DroneState(a.name, "radio://0/80/2M/E7E7E7E701", LinkState(True), None, None, None, None)
    found = []
    for k in range(301):
        t = k / 100
        state = replace(base, setpoints_superseded=int(6 * t))
        found += [f for f in supervisor.check(t, [a], tracker, {a.name: state}) if f.kind == "radio_lag"]
    assert [f.response for f in found] == ["warn", "land"], found


def test_a_drone_whose_link_takes_none_of_its_setpoints_lands_before_its_firmware_stops_its_motors() -> None:
    """Its setpoint waits unsent (replaced by newer ones each tick): at `SETPOINT_STARVED_S` it lands at once, long
    before two windows of superseded setpoints and the firmware's 2 s watchdog; a setpoint that waits less (a busy
    moment) lands nothing, nor one waiting for a drone that is not streaming."""
    check = RadioLagCheck(10.0)
    a = agent()
    base = DroneState(a.name, "radio://0/80/2M/E7E7E7E701", LinkState(True), None, None, None, None)
    found = []
    for k in range(1, 301):
        t = k / 100
        waiting = max(0.0, t - 1.0) if t < 1.4 else max(0.0, t - 2.0)  # 0.4 s at 1.0-1.4 s, then from 2.0 s on
        superseded = int(10 * max(0.0, t - 2.0))  # every setpoint since 2.0 s
        state = replace(base, setpoint_waiting_s=waiting, setpoints_superseded=superseded)
        found += [(t, f) for f in check.check(t, [a], {a.name: state})]
    lands = [(t, f) for t, f in found if f.response == "land"]
    assert len(lands) == 1 and lands[0][0] == pytest.approx(2.0 + SETPOINT_STARVED_S, abs=0.011), found
    assert "took none of its setpoints" in lands[0][1].message
    landing = RadioLagCheck(10.0)
    b = agent(DronePhase.LANDING)
    assert not landing.check(3.0, [b], {b.name: replace(base, setpoint_waiting_s=2.0)})
