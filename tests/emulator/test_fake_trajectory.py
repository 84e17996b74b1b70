"""The memory subsystem and uploaded trajectories of the fake firmware at the packet level, on synthetic time.

Expectations come from `trajectory_shapes.reference` (numpy, independent of the emulator) and from the firmware's
rules quoted in rpf_fly/emulator/fake_trajectory.py and docs/radio.md ("Trajectories")."""

from __future__ import annotations

import errno
import math
import struct

import numpy as np
import pytest
from cflib.crazyflie.mem import CompressedSegment, CompressedStart
from trajectory_shapes import Piece, figure_eight, reference, total_duration

from rpf_fly.emulator.fake_firmware import FakeFirmware
from rpf_fly.emulator.fake_memory import EEPROM_SIZE, TRAJECTORY_MEMORY_SIZE, config_block
from rpf_fly.emulator.fake_trajectory import normalize_radians, shortest_signed_angle_radians
from rpf_fly.emulator.fake_vehicle import VehicleConfig
from rpf_fly.emulator.firmware_tables import LOG_TOC, PARAM_TOC
from rpf_fly.emulator.vehicle_figures import SUBSTEP_S

DT = 0.01
READY_S = 0.15
"""Power-on to ready to fly: three supervisor updates at the firmware's 25 Hz (pre-flight checks passed, arming,
ready to fly: 0.12 s), with a tick to spare."""
HL_ACTIVE, HL_FINISHED, HL_DISABLED = 0x0100, 0x0200, 0x0400


class Sim:
    """A firmware on a synthetic clock stepped at 100 Hz."""

    def __init__(self, **config: object) -> None:
        self.t = 0.0
        self.fw = FakeFirmware(VehicleConfig(**config), radio_address=0xE7E7E7E742, radio_channel=42)  # type: ignore[arg-type]

    def send(self, port: int, channel: int, data: bytes) -> bytes:
        replies = self.fw.handle(port, channel, data, self.t)
        return replies[0][2] if replies else b""

    def hl(self, data: bytes) -> int:
        """A high-level command; its answer's errno."""
        return self.send(8, 0, data)[3]

    def run(self, seconds: float) -> None:
        end = self.t + seconds
        while self.t < end - 1e-9:
            self.t = round(self.t + DT, 6)
            self.fw.step(self.t)

    def write(self, address: int, data: bytes, mem_id: int = 1) -> list[int]:
        """Write as cflib does, 24 bytes a packet; the status of each packet."""
        return [
            self.send(4, 2, struct.pack("<BI", mem_id, address + i) + data[i : i + 24])[5]
            for i in range(0, len(data), 24)
        ]

    def read(self, address: int, length: int, mem_id: int = 1) -> bytes | int:
        """One read packet: the data, or the error status."""
        reply = self.send(4, 1, struct.pack("<BIB", mem_id, address, length))
        assert reply[:5] == struct.pack("<BI", mem_id, address)
        return reply[6:] if reply[5] == 0 else reply[5]

    def hover(self, height: float = 0.5) -> None:
        self.run(READY_S)
        assert self.hl(struct.pack("<BBff?f", 7, 0, height, 0.0, True, 1.0)) == 0
        self.run(1.5)


def define(trajectory_id: int, offset: int, n_pieces: int, kind: int = 0, location: int = 1) -> bytes:
    return struct.pack("<BBBBIB", 6, trajectory_id, location, kind, offset, n_pieces)


def start(
    trajectory_id: int,
    timescale: float = 1.0,
    relative: bool = False,
    relative_yaw: bool = False,
    reversed_: bool = False,
    group: int = 0,
) -> bytes:
    return struct.pack("<BBBBBBf", 13, group, relative, relative_yaw, reversed_, trajectory_id, timescale)


def upload(sim: Sim, pieces: list[Piece], trajectory_id: int = 1, offset: int = 0) -> None:
    data = b"".join(p.packed() for p in pieces)
    assert sim.write(offset, data) == [0] * math.ceil(len(data) / 24)
    assert sim.hl(define(trajectory_id, offset, len(pieces))) == 0


def fly_and_compare(
    sim: Sim, expected, seconds: float, end_s: float, boundaries: tuple[float, ...] = ()
) -> tuple[float, float]:
    """Step `seconds`; each tick compare the commander's setpoint with `expected(t since start)` (the plan is
    evaluated at the start of the tick's interval, `SUBSTEP_S` before the snapshot time) and, until the trajectory
    ends at `end_s`, the true position with `expected` at the snapshot time. Velocities are not compared at the
    instants in `boundaries` and `end_s` (where they jump, and rounding decides the side). Returns the largest
    setpoint (position and velocity) and truth errors."""
    t0 = sim.fw.snapshot().hl_plan_start_s
    worst_setpoint = worst_truth = 0.0
    stop = sim.t + seconds
    while sim.t < stop - 1e-9:
        sim.run(DT)
        snap = sim.fw.snapshot()
        elapsed = snap.time_s - t0
        if elapsed - SUBSTEP_S >= 0:
            pos, vel, yaw = expected(elapsed - SUBSTEP_S)
            worst_setpoint = max(worst_setpoint, math.dist(snap.setpoint_position, pos))
            if all(abs(elapsed - SUBSTEP_S - b) > 1e-6 for b in (*boundaries, end_s)):
                worst_setpoint = max(worst_setpoint, math.dist(snap.setpoint_velocity, vel))
            assert math.radians(snap.setpoint_yaw_deg) == pytest.approx(yaw, abs=1e-5)
        if elapsed <= end_s:
            worst_truth = max(worst_truth, math.dist(snap.position, expected(elapsed)[0]))
    return worst_setpoint, worst_truth


def test_memory_map_is_a_deckless_crazyflie_21() -> None:
    sim = Sim()
    assert sim.send(4, 0, bytes([1])) == bytes([1, 5])
    infos = [struct.unpack("<BBBI8s", sim.send(4, 0, bytes([2, i]))) for i in range(5)]
    assert [(i[1], i[2], i[3]) for i in infos] == [
        (0, 0x00, EEPROM_SIZE),
        (1, 0x12, 4096),
        (2, 0x15, 0x1000),
        (3, 0x19, 5 * 0x10000000),
        (4, 0x20, 0x18000),
    ]
    assert all(i[4] == bytes(8) for i in infos)
    assert sim.send(4, 0, bytes([2, 5])) == bytes([2, 5])  # no such memory: the protocol document's answer
    # EEPROM: the config block v1 with the drone's own channel and address, then erased bytes
    block = config_block(42, 2, 0xE7E7E7E742)
    assert block[:4] == b"0xBC" and sum(block[:-1]) & 0xFF == block[-1] and len(block) == 21
    assert sim.read(0, 21, mem_id=0) == block and sim.read(21, 3, mem_id=0) == b"\xff\xff\xff"
    assert sim.read(EEPROM_SIZE - 2, 3, mem_id=0) == errno.EIO
    # memory tester: reads give the address pattern; a wrong write counts, memTst.resetW clears at the next write
    assert sim.read(0x0FE, 4, mem_id=2) == bytes([0xFE, 0xFF, 0x00, 0x01])
    assert sim.write(0x10, bytes([0x10, 0x11]), mem_id=2) == [0] and sim.fw.memory_tester.write_errors == 0
    assert sim.write(0x10, bytes([0x10, 0x99]), mem_id=2) == [0] and sim.fw.memory_tester.write_errors == 1
    assert "memTst.errCntW" in LOG_TOC.by_name and "memTst.resetW" in PARAM_TOC.by_name
    ident = struct.pack("<H", PARAM_TOC.by_name["memTst.resetW"].ident)
    sim.send(2, 2, ident + bytes([1]))
    sim.write(0, bytes([0]), mem_id=2)
    assert sim.fw.memory_tester.write_errors == 0 and sim.fw.snapshot().params["memTst.resetW"] == 0
    # deck memory without decks: version 3, no deck infos; deck sections refused
    assert sim.read(0, 4, mem_id=3) == bytes([3, 0, 0, 0]) and sim.read(0x10000000, 4, mem_id=3) == errno.EIO
    assert sim.read(0, 4, mem_id=4) == bytes([1, 0, 2, 0]) and sim.read(0x10000, 1, mem_id=4) == errno.EIO
    assert sim.read(0, 4, mem_id=7) == errno.EIO


def test_trajectory_memory_keeps_what_was_written_and_refuses_what_does_not_fit() -> None:
    sim = Sim()
    data = bytes(range(200))
    assert sim.write(100, data) == [0] * 9
    assert b"".join(sim.read(100 + i, 20) for i in range(0, 200, 20)) == data  # type: ignore[misc]
    assert sim.read(TRAJECTORY_MEMORY_SIZE - 24, 24) == bytes(24)
    # a write that crosses the end is refused whole (crtpCommanderHighLevelWriteTrajectory: offset + length <= 4096)
    assert sim.write(TRAJECTORY_MEMORY_SIZE - 10, bytes([7]) * 11) == [errno.EIO]
    assert sim.read(TRAJECTORY_MEMORY_SIZE - 10, 10) == bytes(10)
    assert sim.write(TRAJECTORY_MEMORY_SIZE - 10, bytes([7]) * 10) == [0]
    assert sim.read(TRAJECTORY_MEMORY_SIZE - 10, 11) == errno.EIO
    assert sim.read(0, 25) == errno.EIO  # more than a reply carries
    # the trajectory memory is RAM: a reboot clears it; the EEPROM keeps what was written
    assert sim.write(30, b"\x01\x02", mem_id=0) == [0]
    sim.fw.reboot(sim.t)
    sim.run(2.0)
    assert sim.read(100, 20) == bytes(20) and sim.read(30, 2, mem_id=0) == b"\x01\x02"


def test_figure_eight_is_flown_exactly_and_ends_hovering_in_the_flying_state() -> None:
    sim = Sim()
    sim.hover(0.5)
    pieces = figure_eight(height=0.5)
    upload(sim, pieces)
    snap = sim.fw.snapshot()
    assert snap.supervisor_bits & HL_FINISHED  # the take-off is done
    assert sim.hl(start(1)) == 0
    sim.run(DT)
    assert not sim.fw.snapshot().supervisor_bits & HL_FINISHED
    duration = total_duration(pieces)
    worst_setpoint, worst_truth = fly_and_compare(sim, lambda t: reference(pieces, t), duration + 0.3, duration)
    assert worst_setpoint < 1e-5  # position (m) and velocity (m/s): the polynomial itself
    assert worst_truth < 0.004  # the true drone, tracking with the velocity feed-forward (0.9 m/s at most)
    sim.run(0.8)
    snap = sim.fw.snapshot()
    assert snap.hl_state == "FLYING" and snap.supervisor_bits & HL_ACTIVE and snap.supervisor_bits & HL_FINISHED
    end = reference(pieces, total_duration(pieces))[0]
    assert snap.setpoint_position == pytest.approx(end, abs=1e-6) and snap.setpoint_velocity == (0.0, 0.0, 0.0)
    assert snap.position == pytest.approx(end, abs=1e-3) and snap.flying
    # a finished trajectory hands over to the next command like any plan
    assert sim.hl(struct.pack("<BBff?f", 8, 0, 0.0, 0.0, True, 1.0)) == 0
    sim.run(1.6)
    assert sim.fw.snapshot().hl_state == "IDLE" and not sim.fw.snapshot().motors_on


def test_time_scale_and_relative_position_and_yaw() -> None:
    sim = Sim()
    sim.hover(0.5)
    goal, goal_yaw = (0.7, -0.3, 0.8), 2.0
    assert sim.hl(struct.pack("<BBBBfffff", 12, 0, 0, 0, *goal, goal_yaw, 1.0)) == 0
    sim.run(1.5)
    pieces = figure_eight(height=0.3, yaw_amplitude=0.4)
    upload(sim, pieces, trajectory_id=4, offset=132 * 3)
    assert sim.hl(start(4, timescale=1.5, relative=True, relative_yaw=True)) == 0
    p0, _, yaw0 = reference(pieces, 0.0)
    rotation = shortest_signed_angle_radians(normalize_radians(yaw0), normalize_radians(goal_yaw))
    c, s = math.cos(rotation), math.sin(rotation)
    shift = tuple(g - p for g, p in zip(goal, p0))

    def expected(t: float):
        (x, y, z), (vx, vy, vz), yaw = reference(pieces, t, timescale=1.5)
        return (
            (c * x - s * y + shift[0], s * x + c * y + shift[1], z + shift[2]),
            (c * vx - s * vy, s * vx + c * vy, vz),
            yaw + rotation,
        )

    assert expected(0.0)[0] == pytest.approx(goal, abs=1e-6)  # the figure starts at the origin: no jump
    duration = 1.5 * total_duration(pieces)
    worst_setpoint, worst_truth = fly_and_compare(sim, expected, duration + 0.3, duration)
    assert worst_setpoint < 1e-5 and worst_truth < 0.004
    assert sim.fw.snapshot().setpoint_position == pytest.approx(goal, abs=1e-5)


def test_relative_yaw_rotates_about_the_world_origin_as_the_firmware_does() -> None:
    """traj_eval_transform rotates the polynomial's output, then shifts it; the shift was computed unrotated, so a
    trajectory whose first point is not the origin does not start at the current setpoint."""
    sim = Sim()
    sim.hover(0.5)
    line = Piece(((1.0, 0.1, 0, 0, 0, 0, 0, 0), (0.0,) * 8, (0.5,) + (0.0,) * 7, (0.0,) * 8), 2.0)
    upload(sim, [line])
    assert sim.hl(start(1, relative=True, relative_yaw=True)) == 0  # hovering at (0, 0, 0.5), yaw 0
    sim.run(0.1)
    assert sim.fw.snapshot().setpoint_position == pytest.approx((0.0, 0.0, 0.5), abs=0.02)  # yaw 0: no rotation
    assert sim.hl(struct.pack("<BBBBfffff", 12, 0, 0, 0, 0.0, 0.0, 0.5, math.pi / 2, 1.0)) == 0
    sim.run(1.5)
    assert sim.hl(start(1, relative=True, relative_yaw=True)) == 0
    sim.run(DT)
    # shift = (0, 0, 0.5) - (1, 0, 0.5); rotated start (0, 1) + shift = (-1, 1): a 1.4 m jump of the setpoint
    assert sim.fw.snapshot().setpoint_position[:2] == pytest.approx((-1.0, 1.0), abs=1e-3)


def test_reversed_flies_the_pieces_backwards_and_ignores_relative_yaw() -> None:
    sim = Sim()
    sim.hover(0.5)
    here = (0.3, 0.2, 0.7)
    assert sim.hl(struct.pack("<BBBBfffff", 12, 0, 0, 0, *here, 1.0, 1.0)) == 0  # and turn to 1 rad
    sim.run(1.5)
    pieces = figure_eight(height=0.5)
    upload(sim, pieces)
    duration = total_duration(pieces)
    end_point = reference(pieces, duration)[0]
    assert sim.hl(start(1, relative=True, relative_yaw=True, reversed_=True)) == 0
    shift = tuple(h - e for h, e in zip(here, end_point))

    def expected(t: float):
        pos, vel, yaw = reference(pieces, max(duration - t, 0.0))
        moving = t < duration
        return (tuple(p + s for p, s in zip(pos, shift)), tuple(-v if moving else 0.0 for v in vel), yaw)

    worst_setpoint, worst_truth = fly_and_compare(sim, expected, duration + 0.2, duration)
    assert worst_setpoint < 1e-5 and worst_truth < 0.004


def _bezier(points: list[float], s: float) -> float:
    n = len(points) - 1
    return sum(math.comb(n, i) * (1 - s) ** (n - i) * s**i * p for i, p in enumerate(points))


def test_compressed_trajectory_is_flown_and_its_limits_answer_enoexec() -> None:
    sim = Sim()
    sim.hover(0.5)
    start_point = CompressedStart(0.0, 0.0, 0.5, 0.0)
    segments = [
        CompressedSegment(1.5, [0.1, 0.2, 0.4, 0.5, 0.6, 0.6, 0.6], [0.2, 0.2, 0.2], [0.8], []),
        CompressedSegment(1.0, [0.3], [], [0.5, 0.5, 0.5], [0.5]),
    ]
    data = start_point.pack() + b"".join(segment.pack() for segment in segments)
    assert sim.write(0, data) == [0] * math.ceil(len(data) / 24)
    assert sim.hl(define(2, 0, len(segments), kind=1)) == 0
    assert sim.hl(start(2, timescale=2.0)) == errno.ENOEXEC
    assert sim.hl(start(2, reversed_=True)) == errno.ENOEXEC
    assert sim.hl(start(2)) == 0

    def expected(t: float):
        """Each coordinate a Bezier from the previous end (mm / decidegree rounding as cflib encodes)."""
        x0, y0, z0, yaw0 = 0.0, 0.0, 0.5, 0.0
        first = ([x0] + [int(v * 1000) / 1000 for v in segments[0].x], [y0] + [0.2] * 3, [z0, 0.8], [yaw0])
        second = (
            [first[0][-1], 0.3],
            [first[1][-1]],
            [first[2][-1]] + [0.5] * 3,
            [yaw0, int(math.degrees(0.5) * 10) / 10 * math.pi / 180],
        )
        for curves, duration in ((first, 1.5), (second, 1.0)):
            if t < duration:
                s = t / duration
                pos = tuple(_bezier(c, s) for c in curves[:3])
                vel = tuple((_bezier(c, min(s + 1e-6, 1)) - _bezier(c, s)) / 1e-6 / duration for c in curves[:3])
                return pos, vel, _bezier(curves[3], s)
            t -= duration
        return tuple(c[-1] for c in second[:3]), (0.0, 0.0, 0.0), second[3][-1]

    worst_setpoint, worst_truth = fly_and_compare(sim, expected, 2.8, 2.5, boundaries=(1.5,))
    assert worst_setpoint < 2e-5  # velocities by finite differences
    assert worst_truth < 0.005  # the velocity jumps at 1.5 s: the drone needs a few ticks to catch up
    assert sim.fw.snapshot().supervisor_bits & HL_FINISHED and sim.fw.snapshot().hl_state == "FLYING"


def test_define_and_start_answer_as_the_firmware() -> None:
    sim = Sim()
    assert sim.hl(define(31, 0, 1)) == errno.ENOEXEC  # NUM_TRAJECTORY_DEFINITIONS is 31
    assert sim.hl(define(30, 0, 1)) == 0
    sim.run(READY_S)
    for silent in (start(31), start(7), start(30, group=0x02)):  # id too large, undefined, not in the group
        assert sim.hl(silent) == 0
        sim.run(0.05)
        assert sim.fw.snapshot().hl_state == "IDLE"
    assert sim.hl(define(8, 0, 1, location=0)) == 0 and sim.hl(start(8)) == 0  # location invalid: nothing
    assert sim.hl(define(9, 0, 1, kind=5)) == 0 and sim.hl(start(9)) == 0  # unknown type: nothing
    sim.run(0.05)
    assert sim.fw.snapshot().hl_state == "IDLE"
    # pieces past the end of the memory: an invalid evaluation disables the planner
    assert sim.hl(define(3, TRAJECTORY_MEMORY_SIZE - 100, 2)) == 0 and sim.hl(start(3)) == 0
    sim.run(0.05)
    snap = sim.fw.snapshot()
    assert snap.hl_state == "DISABLED" and snap.supervisor_bits & HL_DISABLED
    # blocked while the supervisor forbids flying (after an emergency stop)
    sim.send(9, 1, bytes([0x03]))
    sim.run(0.05)
    assert sim.hl(start(30)) == errno.EBUSY and sim.hl(define(5, 0, 1)) == 0  # define is never blocked


def test_a_trajectory_started_on_the_floor_takes_off_along_it() -> None:
    """plan_start_trajectory needs no state: an armed drone on the floor flies the trajectory from its start."""
    sim = Sim()
    sim.run(READY_S)
    climb = Piece(((0.0,) * 8, (0.0,) * 8, (0.0, 0.0, 0.15, 0.05) + (0.0,) * 4, (0.0,) * 8), 2.0)
    upload(sim, [climb])
    assert sim.hl(start(1)) == 0
    sim.run(2.5)
    snap = sim.fw.snapshot()
    assert snap.flying and snap.position[2] == pytest.approx(0.15 * 4 + 0.05 * 8, abs=0.01)
    assert np.isclose(snap.setpoint_position[2], 1.0)


def test_a_shorter_compressed_upload_flies_on_into_the_remains_of_a_longer_one() -> None:
    """cflib writes no terminating piece: a compressed trajectory ends at the first zero duration after it."""
    sim = Sim()
    sim.hover(0.5)
    first = CompressedStart(0.0, 0.0, 0.5, 0.0).pack() + CompressedSegment(1.0, [0.1], [], [], []).pack()
    longer = first + CompressedSegment(2.0, [0.2], [], [], []).pack()
    assert sim.write(0, longer) == [0] * math.ceil(len(longer) / 24)
    assert sim.write(0, first) == [0]  # the same first piece again: the second is still there after it
    assert sim.hl(define(0, 0, 1, kind=1)) == 0 and sim.hl(start(0)) == 0
    sim.run(3.2)
    assert sim.fw.snapshot().setpoint_position[0] == pytest.approx(0.2, abs=1e-6)
    assert sim.write(len(first), bytes(3)) == [0]  # a zero header and duration end it after the first piece
    assert sim.hl(start(0)) == 0
    sim.run(1.5)
    assert sim.fw.snapshot().setpoint_position[0] == pytest.approx(0.1, abs=1e-6)
