"""The flight's ways out under faults, on simulated drones through the real stack: a stuck loop, an interrupt, an
emergency stop asked for while a radio send is in progress, a drone whose link is lost. Each of these once left a
drone flying or cut its motors in the air."""

from __future__ import annotations

import _thread
import re
import threading
import time
from dataclasses import replace

import pytest
from flight_harness import default_factory, fly

from rpf_fly.flight.phases import FlightOutcome
from rpf_fly.flight.watchdog import LoopWatchdog, stall_timeout_s


def landed(snapshot) -> bool:  # type: ignore[no-untyped-def]
    return snapshot.position[2] < 0.05 and not snapshot.motors_on


def event_time_ns(flight, text: str) -> int:  # type: ignore[no-untyped-def]
    for m in flight.log.messages("/events"):
        if text in m.data["message"]:
            return m.log_time
    raise AssertionError(f"no event with {text!r}")


def test_a_loop_stall_lands_every_drone_and_the_landing_stands(tmp_path, short_mission):
    """The loop thread blocks for 1 s: the watchdog lands every drone through the commander, and when the loop comes
    back it streams no setpoint to a drone that was told to land (a streamed setpoint would override the high-level
    landing and the drone would fly on, unplanned)."""
    flight = fly(short_mission, tmp_path, when_flying=lambda loop, rig: (time.sleep(1.0), rig.mocap.stall(1.0)))
    stalled = event_time_ns(flight, "flight loop stalled")
    for name in ("cf1", "cf2", "cf3"):
        late = [m for m in flight.log.messages(f"/{name}/setpoint") if m.log_time > stalled]
        assert late == [], f"{name}: {len(late)} setpoints streamed after the watchdog landed it"
        assert flight.report.outcomes[name] == FlightOutcome.LANDED_EARLY
    assert all(landed(s) for s in flight.snapshots.values())
    assert [e.level for e in flight.events("loop") if e.level >= 5] == [5]  # the watchdog, once


def test_a_loop_stall_shorter_than_the_watchdog_is_a_warning_and_the_flight_goes_on(tmp_path, short_mission):
    """The loop blocks 0.2 s at 20 Hz planning: under the watchdog's 0.35 s, so nothing lands, but the drones flew
    on old setpoints for four ticks: one warning says so (before, nothing did)."""
    from dataclasses import replace

    mission = replace(short_mission, flight=replace(short_mission.flight, rate_hz=20))
    flight = fly(mission, tmp_path, when_flying=lambda loop, rig: (time.sleep(1.0), rig.mocap.stall(0.2)))
    loop_events = flight.events("loop")
    assert [e.level for e in loop_events] == [3], [(e.level, e.message) for e in loop_events]
    assert "flight loop late" in loop_events[0].message
    assert all(o == FlightOutcome.REACHED for o in flight.report.outcomes.values()), flight.report.reasons


def test_poses_the_ground_station_held_back_do_not_pull_the_estimators_back(tmp_path, short_mission, caplog):
    """The loop reads a frame, then is held back 0.3 s before it uses it (a loaded host descheduling it, a long
    garbage collection): the poses it then forwards are 0.3 s old, 0.24 m behind drones flying 0.8 m/s. Fed as
    extpos, the firmware takes them as where the drones are now: their estimates fell 0.11-0.14 m behind the truth
    (found in a dry run looping beside the test suite, where the estimate check then cut two drones' motors). They
    are dropped instead (`EXTPOS_MAX_WAIT_S`): the estimators dead-reckon to the next fresh pose."""
    flight = fly(short_mission, tmp_path, when_flying=lambda loop, rig: (time.sleep(1.0), rig.mocap.hold(0.3)))
    # 0.3 s from the tick before is under the loop watchdog's 0.35 s, or just over it on a loaded host: then it lands
    # the swarm, which is right too; either way no drone's estimate is cut as diverged
    assert FlightOutcome.EMERGENCY not in flight.report.outcomes.values(), flight.report.reasons
    for name in ("cf1", "cf2", "cf3"):
        off = [
            abs(
                complex(m.data["position"]["x"], m.data["position"]["y"])
                - complex(m.data["estimate"]["x"], m.data["estimate"]["y"])
            )
            for m in flight.log.messages(f"/truth/{name}")
            if m.data["motors"] and m.data["position"]["z"] > 0.3
        ]
        # fed: 0.11-0.14 m; dropped: under 0.02 m idle, 0.051 m seen beside a loaded suite (extpos late on its way)
        assert len(off) > 200 and max(off) < 0.08, (name, max(off))
    assert "not sent to its estimator" in caplog.text


def test_a_planner_that_blocks_faults_its_drone_only(tmp_path, short_mission):
    """A drone's planner blocks for 1 s: it runs on its own thread with a deadline, so the loop keeps streaming the
    others' setpoints; that drone holds and lands, the others reach their goals (before, the loop stopped with it
    and the watchdog landed everyone)."""
    base = default_factory(short_mission)

    class Hanging:
        def __init__(self, planner):  # type: ignore[no-untyped-def]
            self.planner, self.calls = planner, 0

        def step(self, view):  # type: ignore[no-untyped-def]
            self.calls += 1
            if self.calls == 10:
                time.sleep(1.0)
            return self.planner.step(view)

    factory = lambda drone: Hanging(base(drone)) if drone.name == "cf2" else base(drone)  # noqa: E731
    flight = fly(short_mission, tmp_path, factory=factory)
    fault = flight.events("planner_fault", "cf2")
    assert fault and "did not return within" in fault[0].message
    # The others were streamed on time all along: the tick does not wait for a drone whose planner is still
    # computing (before, it waited out the 0.25 s deadline with every drone's setpoint held back: a "flight loop
    # late" warning and a 0.35 s gap in cf1's and cf3's setpoints, over two thirds of the firmware's 0.5 s).
    assert flight.events("loop") == []
    faulted = event_time_ns(flight, "did not return within")
    for name in ("cf1", "cf3"):
        times = [
            m.log_time
            for m in flight.log.messages(f"/{name}/setpoint")
            if faulted - 1_000_000_000 < m.log_time < faulted + 500_000_000
        ]
        gaps = [(b - a) / 1e9 for a, b in zip(times, times[1:])]
        assert len(times) > 10 and max(gaps) < short_mission.flight.dt + 0.08, (name, max(gaps))
    assert flight.report.outcomes["cf2"] == FlightOutcome.LANDED_EARLY
    assert flight.report.outcomes["cf1"] == flight.report.outcomes["cf3"] == FlightOutcome.REACHED
    assert all(landed(s) for s in flight.snapshots.values())


def test_the_watchdog_rearms_after_a_stall_and_follows_the_rate():
    assert stall_timeout_s(0.1) == pytest.approx(0.35)
    assert stall_timeout_s(0.125) == pytest.approx(0.375)
    stalls = []
    watchdog = LoopWatchdog(lambda: stalls.append(time.monotonic()), 0.1)
    watchdog.start()
    try:
        watchdog.arm(True)
        time.sleep(0.3)
        assert len(stalls) == 1  # once a stall
        for _ in range(10):
            watchdog.beat()
            time.sleep(0.02)
        time.sleep(0.3)
        assert len(stalls) == 2  # and again after the loop ticked again
    finally:
        watchdog.close()


def test_a_keyboard_interrupt_in_library_use_lands_every_drone(tmp_path, short_mission):
    """Python's own SIGINT handling (a library user's script): the first Ctrl-C lands, it does not cut motors."""
    flight = fly(short_mission, tmp_path, when_flying=lambda loop, rig: (time.sleep(0.5), _thread.interrupt_main()))
    assert flight.report.interrupted and not flight.events("emergency")
    assert all(o == FlightOutcome.LANDED_EARLY for o in flight.report.outcomes.values())
    assert all(landed(s) for s in flight.snapshots.values())
    assert flight.events("interrupt")


def test_an_emergency_stop_asked_during_a_radio_send_does_not_wait_for_it(tmp_path, short_mission):
    """The second Ctrl-C's handler runs on the thread it interrupted, which may be inside cflib's send_packet
    holding the send lock: the handler must only set flags (radio I/O there would deadlock), and another thread
    stops the motors."""
    returned_after: list[float] = []

    def second_ctrl_c(loop, rig):  # type: ignore[no-untyped-def]
        time.sleep(0.5)
        cf = loop.backend._drones["cf1"].scf.cf  # noqa: SLF001 - the send lock a real handler could interrupt
        with cf._send_lock:  # noqa: SLF001
            started = time.monotonic()
            loop.emergency_stop("second Ctrl-C (test)")
            returned_after.append(time.monotonic() - started)
            time.sleep(0.3)

    flight = fly(short_mission, tmp_path, when_flying=second_ctrl_c)
    assert returned_after and returned_after[0] < 0.05, returned_after
    assert all(o == FlightOutcome.EMERGENCY for o in flight.report.outcomes.values())
    assert all(not s.motors_on and s.emergency_stop_latched for s in flight.snapshots.values())


def test_a_lost_link_drone_stays_in_the_others_views_until_it_is_down(tmp_path, short_mission):
    """cf3's link drops: its firmware's emergency-stop watchdog cuts its motors about 1 s after the last keep-alive
    reached it, and it falls. Until mocap shows it on the floor it is still in cf2's view (before, it vanished from
    every view at once, still in the air)."""
    base = default_factory(short_mission)
    seen: list[tuple[float, int]] = []  # (time, neighbours in cf2's view)

    class Probe:
        """cf2's own planner, with a record of the view it was given."""

        def __init__(self, planner):  # type: ignore[no-untyped-def]
            self.planner = planner

        def step(self, view):  # type: ignore[no-untyped-def]
            seen.append((time.monotonic(), int(sum(bool(m) for m in view.neighbour_mask))))
            return self.planner.step(view)

    dropped_at: list[float] = []

    def drop(loop, rig):  # type: ignore[no-untyped-def]
        time.sleep(1.0)
        rig.world.drop_link(rig.addresses["cf3"])
        dropped_at.append(time.monotonic())

    factory = lambda drone: Probe(base(drone)) if drone.name == "cf2" else base(drone)  # noqa: E731
    # at 0.3 m/s cf2 still plans when cf3 is down (at 0.5 m/s it arrived 4.2-4.5 s after take-off)
    slow = replace(short_mission, flight=replace(short_mission.flight, speed=0.3))
    flight = fly(slow, tmp_path, factory=factory, when_flying=drop)
    assert flight.report.outcomes["cf3"] == FlightOutcome.LINK_LOST
    # cflib declares the link lost after 100 lost acks (~0.2 s); cf3's motors stop 0.8-1.0 s after the drop (its
    # last keep-alive went out up to 0.2 s before it), and it falls from 0.5 m in 0.32 s.
    soon = [n for t, n in seen if dropped_at[0] + 0.3 < t < dropped_at[0] + 0.75]
    assert soon and all(n == 2 for n in soon), soon
    late = [n for t, n in seen if t > dropped_at[0] + 3.5]
    assert late and all(n == 1 for n in late), late  # on the floor: out of the way
    assert flight.report.outcomes["cf1"] == flight.report.outcomes["cf2"] == FlightOutcome.REACHED
    # cf3's rows after the loss are logged too (schema mode link_lost), and the log dropped and failed nothing.
    assert any(m.data["mode"] == "link_lost" for m in flight.log.messages("/cf3/planner"))
    assert flight.report.log_dropped == 0 and flight.report.log_failed == 0


def test_a_drone_standing_rotated_flies_right_after_its_estimator_is_reset_to_mocap(tmp_path, short_mission):
    """cf2 was powered on facing 120 degrees from +x: its yaw estimate starts at 0 (kalman.initialYaw) and
    position-only extpos never corrects it, so without the preflight reset it flies off (the classic fly-away)."""
    from rpf_fly.emulator.fake_world import FakeDroneConfig

    start = short_mission.drones[1].start
    configs = {"cf2": FakeDroneConfig.at(start[0], start[1], 0.0, yaw_deg=120.0, positioning="extpos")}
    flight = fly(short_mission, tmp_path, configs=configs)
    assert flight.report.success, flight.report.reasons
    assert abs(flight.snapshots["cf2"].yaw_deg) < 5.0  # it turned to the setpoints' yaw 0 on a right estimate
    goal = short_mission.drones[1].goal
    assert abs(flight.snapshots["cf2"].position[0] - goal[0]) < 0.2


def test_the_preflight_says_when_a_yaw_estimate_was_off_before_its_reset(tmp_path, short_mission):
    from rpf_fly.emulator.fake_world import FakeDroneConfig

    start = short_mission.drones[0].start
    configs = {"cf1": FakeDroneConfig.at(start[0], start[1], 0.0, yaw_deg=-90.0, positioning="extpos")}
    flight = fly(short_mission, tmp_path, configs=configs)
    warned = flight.events("estimator", "cf1")
    assert warned and warned[0].level == 3 and "yaw estimate" in warned[0].message
    assert not flight.events("estimator", "cf2")
    assert flight.report.success


def test_a_drone_is_disarmed_only_after_its_supervisor_says_it_landed(tmp_path, short_mission):
    """Disarming a flying Crazyflie cuts its motors. Every drone's supervisor must go Flying -> Landed before the
    disarm resets it: a reset straight from Flying (before, the disarm followed the landing command on a timer, while
    the firmware still counted the drone as flying) is a motor cut."""
    flight = fly(short_mission, tmp_path)
    assert flight.report.success, flight.report.reasons
    for name, snap in flight.snapshots.items():
        moves = [(t.old.value, t.new.value) for t in snap.transitions]
        assert ("Flying", "Reset") not in moves, (name, moves)
        assert ("Flying", "Landed") in moves, (name, moves)
        assert landed(snap)


def test_a_flight_whose_last_drone_lost_its_link_ends_once_mocap_sees_it_down(tmp_path, short_mission):
    """A one-drone flight whose link drops: nothing is left flying its mission, but the flight waits, its log
    open, until mocap shows the drone on the floor (its firmware's emergency-stop watchdog cuts the motors about 1 s
    after the last keep-alive).
    Before, the flight ended at once and its log closed with the drone still in the air, motors on."""
    solo = replace(short_mission, drones=short_mission.drones[:1])
    name = solo.drones[0].name
    dropped_at: list[int] = []

    def drop(loop, rig):  # type: ignore[no-untyped-def]
        time.sleep(1.0)
        rig.world.drop_link(rig.addresses[name])
        dropped_at.append(time.time_ns())

    flight = fly(solo, tmp_path, when_flying=drop)
    assert flight.report.outcomes[name] == FlightOutcome.LINK_LOST
    truth = [m.data for m in flight.log.messages(f"/truth/{name}")]
    last = truth[-1]
    assert not last["motors"] and last["position"]["z"] < 0.05, last
    assert flight.log.messages(f"/truth/{name}")[-1].log_time > dropped_at[0] + 1_000_000_000
    cut = next(
        m.log_time for m in flight.log.messages(f"/truth/{name}") if m.log_time > dropped_at[0] and not m.data["motors"]
    )
    assert 0.6e9 < cut - dropped_at[0] < 1.3e9, (cut - dropped_at[0]) / 1e9  # the watchdog, not the 2 s one


def test_an_orientation_flip_under_extpose_is_not_fed_to_the_estimator(tmp_path, short_mission):
    """Motive flips cf2's rigid body 180 degrees (a wrong fit of its markers) for 1.5 s mid-flight. Forwarded with
    extpose, that orientation would give the estimator the flipped yaw, the position controller would act in a frame
    turned 180 degrees, and cf2 would fly off. The tracker refuses the flip, extpose carries the position only until
    the fit turns back, and the supervisor says so within a frame."""
    mission = replace(short_mission, radio=replace(short_mission.radio, extpos="extpose"))
    injected: list[float] = []

    def flip(loop, rig):  # type: ignore[no-untyped-def]
        time.sleep(0.5)
        injected.append(time.time())
        rig.orientation_flip("cf2", 180.0, 1.5)

    flight = fly(mission, tmp_path, when_flying=flip)
    assert flight.report.success, flight.report.reasons
    warned = flight.events("orientation_glitch", "cf2")
    assert warned and warned[0].level == 3 and re.search(r"turned 1[78][0-9] deg", warned[0].message), warned
    assert "consistent again" in warned[-1].message
    said_ns = event_time_ns(flight, "mocap orientation turned")
    assert 0.0 <= said_ns / 1e9 - injected[0] < 0.2
    cf2 = flight.snapshots["cf2"]
    assert abs(cf2.estimate_yaw_deg - cf2.yaw_deg) < 5.0  # its estimator never took the flipped yaw
    assert abs(cf2.position[0] - mission.drones[1].goal[0]) < 0.2 and landed(cf2)


def test_a_drone_whose_mocap_orientation_flipped_on_the_ground_does_not_take_off(tmp_path, short_mission):
    """A flip seen before take-off: one of the two fits is wrong and nothing says which, and the estimator would
    start from that yaw. The drone stays on the ground with the reason; the others fly."""
    from rpf_fly.flight.dry_run import DryRun
    from rpf_fly.flight.phases import SwarmPhase
    from rpf_fly.flight.session import run_flight
    from rpf_fly.log.reader import read_log

    log_path = tmp_path / "flight.mcap"
    with DryRun(short_mission, mocap="natnet") as rig:

        def flip_when_tracked(loop) -> None:  # type: ignore[no-untyped-def]
            def act() -> None:
                deadline = time.monotonic() + 20
                while (
                    loop.phase != SwarmPhase.PREFLIGHT or loop.tracker.get("cf1") is None
                ) and time.monotonic() < deadline:  # tracked first: the flip is a jump, not its first pose
                    time.sleep(0.002)
                rig.orientation_flip("cf1", 90.0, 60.0)

            threading.Thread(target=act, daemon=True).start()

        report = run_flight(short_mission, default_factory(short_mission), log_path, rig=rig, on_loop=flip_when_tracked)
        cf1 = rig.snapshot("cf1")
    assert report.phase == SwarmPhase.DONE
    assert report.outcomes["cf1"] == FlightOutcome.NOT_FLOWN, report.outcomes
    said = re.search(r"orientation of its rigid body turned (\d+) deg", report.reasons["cf1"])
    assert said and abs(int(said.group(1)) - 90) <= 5, report.reasons  # the dry run's mocap jitters by ~0.5 deg
    assert report.outcomes["cf2"] == report.outcomes["cf3"] == FlightOutcome.REACHED
    truth = read_log(log_path).messages("/truth/cf1")
    assert truth and max(m.data["position"]["z"] for m in truth) < 0.01  # it never left the floor
    assert not cf1.flying and cf1.position[2] == 0.0
