"""Contact in the fake world: drones that touch each other or an obstacle crash (motors off, fall, locked, crashed
and tumbled), flown through real cflib over the fake radio; the contact model itself on synthetic bodies; the
firmware's side of a crash on synthetic time."""

from __future__ import annotations

import errno
import struct
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie

from rpf_fly.emulator.fake_contact import DRONE_CONTACT_M, OBSTACLE_CONTACT_M, ContactModel
from rpf_fly.emulator.fake_firmware import Body, FakeFirmware
from rpf_fly.emulator.fake_vehicle import VehicleConfig
from rpf_fly.emulator.fake_world import FakeDroneConfig, FakeWorld
from rpf_fly.emulator.firmware_tables import LOG_TOC
from rpf_fly.mission.model import BoxObstacle, CircleObstacle
from rpf_fly.radio.backend import SupervisorBits

MakeWorld = Callable[..., FakeWorld]
A, B = 0xE7E7E7E701, 0xE7E7E7E702
CRASH_BITS = SupervisorBits.CRASHED | SupervisorBits.TUMBLED | SupervisorBits.LOCKED


def take_off(scfs: list[SyncCrazyflie], world: FakeWorld, height: float = 0.5) -> None:
    for scf in scfs:
        scf.cf.high_level_commander.takeoff(height, 1.0)
    assert world.wait_until(lambda w: all(abs(s.position[2] - height) < 0.02 for s in w.snapshots().values()), 3.0)


def on_the_floor_where_it_fell(world: FakeWorld, address: int) -> tuple[float, float, float]:
    """Wait until the drone lies on the floor; check it stays there (no sliding) and the mocap still sees it."""
    assert world.wait_until(lambda w: w.snapshot(address).position[2] == 0.0, 2.0)
    fell = world.snapshot(address).position
    time.sleep(0.3)
    assert world.snapshot(address).position == fell
    assert world.true_poses()[address][0] == fell
    return fell


def test_two_drones_commanded_into_each_other_both_crash(make_world: MakeWorld, toc_cache: Path) -> None:
    world = make_world({A: FakeDroneConfig.at(0.0, 0.0), B: FakeDroneConfig.at(1.0, 0.0)})
    cache = str(toc_cache)
    with (
        SyncCrazyflie(world.uri(A), cf=Crazyflie(rw_cache=cache)) as a,
        SyncCrazyflie(world.uri(B), cf=Crazyflie(rw_cache=cache)) as b,
    ):
        take_off([a, b], world)
        a.cf.high_level_commander.go_to(1.0, 0.0, 0.5, 0.0, 2.0)  # each to the other's place: they meet midway
        b.cf.high_level_commander.go_to(0.0, 0.0, 0.5, 0.0, 2.0)
        assert world.wait_until(lambda w: w.snapshot(A).crashed and w.snapshot(B).crashed, 3.0)
        fell = {x: on_the_floor_where_it_fell(world, x) for x in (A, B)}
        for scf in (a, b):  # the supervisor, as cflib reads it over the radio
            assert scf.cf.supervisor.is_crashed and scf.cf.supervisor.is_tumbled and scf.cf.supervisor.is_locked
            assert not scf.cf.supervisor.is_flying
        a.cf.high_level_commander.takeoff(0.5, 1.0)  # a crashed drone never flies again (until reboot)
        b.cf.commander.send_position_setpoint(0.5, 0.0, 0.5, 0.0)
        time.sleep(0.5)
        assert world.snapshot(A).position == fell[A] and world.snapshot(B).position == fell[B]
    snaps = {x: world.snapshot(x) for x in (A, B)}
    assert snaps[A].crash_reason == "contact with E7E7E7E702" and snaps[B].crash_reason == "contact with E7E7E7E701"
    assert snaps[A].crash_time_s == pytest.approx(snaps[B].crash_time_s, abs=1e-9)
    for snap in snaps.values():
        assert snap.crashed and snap.locked and not snap.motors_on and not snap.flying
        assert snap.supervisor_bits & CRASH_BITS == CRASH_BITS
        assert snap.entered("Exception, free fall") == pytest.approx(snap.crash_time_s, abs=0.011)
    # They stopped where their rotors met (centres one span apart, a sweep of 1 cm steps at most), and fell there
    # (to a few micrometres: their last integration steps before the cut are the world's, 1.5 um seen)
    assert fell[B][0] - fell[A][0] == pytest.approx(DRONE_CONTACT_M, abs=1e-5)
    assert (fell[A][0] + fell[B][0]) / 2 == pytest.approx(0.5, abs=0.03) and fell[A][1] == fell[B][1] == 0.0
    world.reboot(A)  # a reboot clears the crash, once the drone has booted (about 1.5 s, radio silent)
    assert world.wait_until(lambda w: not w.snapshot(A).booting and w.snapshot(A).powered, 4.0)
    assert not world.snapshot(A).crashed and not world.snapshot(A).locked


@pytest.mark.parametrize(
    "obstacle", [CircleObstacle((1.0, 0.0), 0.1), BoxObstacle((0.9, -0.5), (1.3, 0.5))], ids=["pole", "box"]
)
def test_a_drone_flown_into_an_obstacle_crashes(make_world: MakeWorld, toc_cache: Path, obstacle) -> None:
    world = make_world({A: FakeDroneConfig.at(0.0, 0.0)}, obstacles=[obstacle])
    with SyncCrazyflie(world.uri(A), cf=Crazyflie(rw_cache=str(toc_cache))) as scf:
        take_off([scf], world)
        scf.cf.high_level_commander.go_to(2.0, 0.0, 0.5, 0.0, 3.0)  # straight through it
        assert world.wait_until(lambda w: w.snapshot(A).crashed, 4.0)
        fell = on_the_floor_where_it_fell(world, A)
        assert scf.cf.supervisor.is_crashed and scf.cf.supervisor.is_locked
    snap = world.snapshot(A)
    assert snap.crash_reason == "obstacle" and not snap.motors_on
    assert snap.supervisor_bits & CRASH_BITS == CRASH_BITS
    assert fell[0] == pytest.approx(0.9 - OBSTACLE_CONTACT_M, abs=0.011) and fell[1] == 0.0  # at the surface


def test_drones_that_pass_0_2_m_apart_do_not_crash(make_world: MakeWorld, toc_cache: Path) -> None:
    pole = CircleObstacle((0.5, -0.3), 0.1)  # 0.2 m from A's path to its surface, too
    world = make_world({A: FakeDroneConfig.at(0.0, 0.0), B: FakeDroneConfig.at(1.0, 0.2)}, obstacles=[pole])
    cache = str(toc_cache)
    with (
        SyncCrazyflie(world.uri(A), cf=Crazyflie(rw_cache=cache)) as a,
        SyncCrazyflie(world.uri(B), cf=Crazyflie(rw_cache=cache)) as b,
    ):
        take_off([a, b], world)
        a.cf.high_level_commander.go_to(1.0, 0.0, 0.5, 0.0, 2.0)
        b.cf.high_level_commander.go_to(0.0, 0.2, 0.5, 0.0, 2.0)
        assert world.wait_until(lambda w: abs(w.snapshot(A).position[0] - 1.0) < 0.01, 4.0)
        for scf in (a, b):
            scf.cf.high_level_commander.land(0.0, 1.0)
        assert world.wait_until(lambda w: all(not s.motors_on for s in w.snapshots().values()), 3.0)
    for address, x, y in ((A, 1.0, 0.0), (B, 0.0, 0.2)):
        snap = world.snapshot(address)
        assert not snap.crashed and not snap.locked and snap.crash_reason is None
        assert snap.supervisor_bits & CRASH_BITS == 0
        assert snap.position == pytest.approx((x, y, 0.0), abs=0.02)


# ------------------------------------------------------------------------------------ the model, synthetic bodies


def body(x: float, y: float = 0.0, z: float = 0.5, *, airborne: bool = True, crashed: bool = False) -> Body:
    return Body((x, y, z), 0.0, airborne and z > 0.0, airborne, crashed, (x, y, z))


def test_contact_needs_one_airborne_drone_and_ignores_two_wrecks() -> None:
    model = ContactModel()
    assert model.check({A: body(0.0, z=0.0, airborne=False), B: body(0.05, z=0.0, airborne=False)}) == []
    hits = model.check({A: body(0.0, z=0.0, airborne=False), B: body(0.05, z=0.0, airborne=True)})
    assert {(c.address, c.reason) for c in hits} == {(A, "contact with E7E7E7E702"), (B, "contact with E7E7E7E701")}
    assert ContactModel().check({A: body(0.0, crashed=True), B: body(0.05, crashed=True)}) == []
    # a wreck is there to be hit: only the drone that flies into it crashes now
    hits = ContactModel().check({A: body(0.0, z=0.0, airborne=False, crashed=True), B: body(0.1, z=0.05)})
    assert [c.address for c in hits] == [B]
    assert ContactModel().check({A: body(0.0), B: body(DRONE_CONTACT_M + 1e-6)}) == []
    assert ContactModel().check({A: body(0.0), B: body(0.0, z=0.5 + DRONE_CONTACT_M + 1e-6)}) == []  # above: 3D


def test_a_long_step_cannot_carry_a_drone_through_another_or_through_a_thin_wall() -> None:
    wall = BoxObstacle((0.99, -1.0), (1.01, 1.0))
    model = ContactModel([wall])
    assert model.check({A: body(-1.0), B: body(0.0, 0.05)}) == []
    hits = model.check({A: body(2.0), B: body(0.0, 0.05)})  # 3 m in one step (a stalled machine): through both
    assert [(c.address, c.reason) for c in hits] == [(A, "contact with E7E7E7E702"), (B, "contact with E7E7E7E701")]
    x = -((DRONE_CONTACT_M**2 - 0.05**2) ** 0.5)  # first touch: 0.13 m from B's centre, before the wall
    assert hits[0].position == pytest.approx((x, 0.0, 0.5), abs=1e-9) and hits[0].fraction == pytest.approx((x + 1) / 3)
    model = ContactModel([wall])
    model.check({A: body(0.0)})
    (hit,) = model.check({A: body(3.0)})
    assert hit.reason == "obstacle" and hit.position[0] == pytest.approx(0.99 - OBSTACLE_CONTACT_M, abs=0.0101)


def test_crash_on_synthetic_time_cuts_the_motors_at_once_and_locks_for_good() -> None:
    fw = FakeFirmware(VehicleConfig())
    t = 0.0
    for _ in range(15):  # ready to fly: three supervisor updates at 25 Hz
        t += 0.01
        fw.step(t)
    assert fw.handle(8, 0, struct.pack("<BBff?f", 7, 0, 0.5, 0.0, True, 1.0), t)[0][2][3] == 0
    for _ in range(150):
        t += 0.01
        fw.step(t)
    fw.vehicle.vel[0] = 0.5  # moving when it hits
    assert fw.crash(t, "obstacle") and not fw.crash(t, "contact with E7E7E7E702")  # the first crash is kept
    snap = fw.snapshot()
    assert not snap.motors_on and snap.velocity[:2] == (0.0, 0.0) and snap.supervisor_state == "Exception, free fall"
    assert snap.crashed and snap.crash_reason == "obstacle" and snap.crash_time_s == t
    x = snap.position[0]
    for _ in range(50):
        t += 0.01
        fw.step(t)
    snap = fw.snapshot()
    assert snap.position == (x, 0.0, 0.0) and snap.supervisor_state == "Locked"
    assert snap.supervisor_bits & CRASH_BITS == CRASH_BITS
    assert fw.handle(9, 1, bytes([0x02]), t) == [(9, 1, bytes([0x82, 0, 0]))]  # crash recovery refused: tumbled
    assert fw.handle(8, 0, struct.pack("<BBff?f", 7, 0, 0.5, 0.0, True, 1.0), t)[0][2][3] == errno.EBUSY
    tumbled = LOG_TOC.by_name["sys.isTumbled"].ident  # the log variable says so too
    assert fw.handle(5, 1, bytes([6, 1, 0x01, *struct.pack("<H", tumbled)]), t) == [(5, 1, bytes([6, 1, 0]))]
    assert fw.handle(5, 1, bytes([3, 1, 1]), t)[0][2] == bytes([3, 1, 0])
    packets = []
    for _ in range(3):
        t += 0.01
        packets += fw.step(t)
    assert packets and all(payload[4] == 1 for _, _, payload in packets)
