"""A take-off the firmware ignores: the drone stays on the floor where it stands, in every view and the separation
check, and a neighbour whose goal is its place does not fly there. Produced as a lab produces it: another cflib
program (a cfclient left open, a script) keeps streaming zero-thrust setpoints to the drone, which holds the
commander's CRTP priority, so every high-level take-off is refused by the firmware and cflib says nothing."""

from __future__ import annotations

import struct
import threading
import time

import cflib.crtp
from cflib.crtp.crtpstack import CRTPPacket
from flight_harness import default_factory

from rpf_fly.flight.dry_run import DryRun
from rpf_fly.flight.phases import DronePhase, FlightOutcome, SwarmPhase
from rpf_fly.flight.session import run_flight
from rpf_fly.log.reader import read_log
from rpf_fly.mission.load import parse_mission

SWAP = """\
name: refused
arena: {x: [-2.0, 2.0], y: [-2.0, 2.0], z: [0.0, 1.5]}
flight: {height: 0.5, speed: 0.5, rate_hz: 10, goal_tolerance: 0.1, takeoff_s: 1.5, land_s: 1.0, timeout_s: 30}
planner: {kind: apf, margin: 0}
mocap: {kind: sim, rate_hz: 100}
drones:
  - {name: cf1, uri: radio://0/80/2M/E7E7E7E701, start: [-1.0, 0.0], goal: [1.0, 0.0]}
  - {name: cf2, uri: radio://0/80/2M/E7E7E7E702, start: [1.0, 0.0], goal: [-1.0, 0.8]}
  - {name: cf3, uri: radio://0/80/2M/E7E7E7E703, start: [-1.0, -1.0], goal: [1.0, -1.0]}
"""


def test_a_drone_that_does_not_lift_off_stays_an_obstacle_and_nobody_lands_on_it(tmp_path):
    mission = parse_mission(SWAP, tmp_path / "refused.yaml")
    log_path = tmp_path / "flight.mcap"
    with DryRun(mission) as rig:
        done = threading.Event()

        def rogue() -> None:  # a second ground station on cf2's link, streaming zero thrust (a legacy setpoint)
            cflib.crtp.init_drivers()
            link = cflib.crtp.get_link_driver(rig.uris["cf2"])
            try:
                while not done.is_set():
                    link.send_packet(CRTPPacket(0x30, struct.pack("<fffH", 0.0, 0.0, 0.0, 0)))
                    time.sleep(0.05)
            finally:
                link.close()

        def on_loop(loop) -> None:  # type: ignore[no-untyped-def]
            def start_at_takeoff() -> None:
                while loop.phase not in (SwarmPhase.TAKEOFF, SwarmPhase.ABORTED, SwarmPhase.DONE):
                    time.sleep(0.005)
                rogue()

            threading.Thread(target=start_at_takeoff, daemon=True).start()

        try:
            report = run_flight(mission, default_factory(mission), log_path, rig=rig, on_loop=on_loop)
        finally:
            done.set()
        time.sleep(0.3)
        snapshots = {d.name: rig.snapshot(d.name) for d in mission.drones}
    assert report.outcomes["cf2"] == FlightOutcome.NOT_FLOWN
    assert "did not lift it off" in report.reasons["cf2"]
    assert report.outcomes["cf1"] == FlightOutcome.LANDED_EARLY  # its goal is cf2's place
    assert "which did not lift off" in report.reasons["cf1"]
    assert report.outcomes["cf3"] == FlightOutcome.REACHED
    retried = [e for e in report.events if e.kind == "takeoff" and e.drone == "cf2" and "again" in e.message]
    assert retried, [e.message for e in report.events]
    assert not any(s.crashed for s in snapshots.values()), {n: s.crash_reason for n, s in snapshots.items()}
    # cf1 landed near where it took off, not on cf2
    cf1 = snapshots["cf1"].position
    assert abs(cf1[0] - 1.0) > 0.5 and cf1[2] < 0.05, cf1
    states = [m.data["state"] for m in read_log(log_path).messages("/cf2/status")]
    assert states[-1] == DronePhase.GROUNDED.value


def test_a_stop_while_the_drones_arm_sends_no_take_off(tmp_path):
    """Ctrl-C (request_stop) while the loop waits for the supervisors to arm: nothing takes off, every armed
    drone is disarmed on the floor (a Crazyflie 2.x re-arms by itself, motors idle). A motor failing its spin-up check
    keeps the arming wait open for 3 s."""
    from rpf_fly.flight.dry_run import StartFault

    mission = parse_mission(SWAP, tmp_path / "refused.yaml")
    log_path = tmp_path / "flight.mcap"
    with DryRun(mission, start_faults={"cf3": StartFault(motor_fault=True)}) as rig:

        def on_loop(loop) -> None:  # type: ignore[no-untyped-def]
            def stop_while_arming() -> None:
                while loop.phase != SwarmPhase.TAKEOFF:
                    time.sleep(0.005)
                time.sleep(0.5)
                loop.request_stop("interrupted by Ctrl-C", "Ctrl-C: all drones land")

            threading.Thread(target=stop_while_arming, daemon=True).start()

        report = run_flight(mission, default_factory(mission), log_path, rig=rig, on_loop=on_loop)
        time.sleep(0.5)
        snapshots = {d.name: rig.snapshot(d.name) for d in mission.drones}
    assert report.interrupted
    assert not [e for e in report.events if e.kind == "takeoff" and "commanded" in e.message]
    data = read_log(log_path)
    for name, snap in snapshots.items():
        assert snap.position[2] < 0.01 and not snap.motors_on, (name, snap.supervisor_state)
        assert max(m.data["position"]["z"] for m in data.messages(f"/truth/{name}")) < 0.01, name  # never rose
        assert report.outcomes[name] == FlightOutcome.NOT_FLOWN, (name, report.outcomes[name])
