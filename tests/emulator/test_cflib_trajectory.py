"""Uploaded trajectories through real cflib over the fake radio: memory discovery, trajectory memory upload and read
back, the firmware's refusal of an upload that does not fit, and figure-8s flown (absolute; relative with a time
scale and relative yaw) with the true positions (world snapshots) on the polynomial."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.mem import MemoryElement
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie
from trajectory_shapes import Piece, figure_eight, reference, total_duration

from rpf_fly.emulator.fake_firmware import FirmwareSnapshot
from rpf_fly.emulator.fake_trajectory import normalize_radians, shortest_signed_angle_radians
from rpf_fly.emulator.fake_world import FakeDroneConfig, FakeWorld

MakeWorld = Callable[..., FakeWorld]
A, B = 0xE7E7E7E700, 0xE7E7E7E701


def read_memory(cf: Crazyflie, mem: MemoryElement, address: int, length: int, timeout_s: float = 5.0) -> bytes:
    """cflib's `Memory.read`, waited for: the bytes, or an AssertionError when the firmware refuses."""
    done = threading.Event()
    result: dict[str, object] = {}

    def ok(m: MemoryElement, addr: int, data: bytes) -> None:
        if m.id == mem.id:
            result["data"] = bytes(data)
            done.set()

    def failed(m: MemoryElement, addr: int, data: bytes) -> None:
        if m.id == mem.id:
            result["failed"] = True
            done.set()

    cf.mem.mem_read_cb.add_callback(ok)
    cf.mem.mem_read_failed_cb.add_callback(failed)
    try:
        assert cf.mem.read(mem, address, length)
        assert done.wait(timeout_s), "no answer to the memory read"
    finally:
        cf.mem.mem_read_cb.remove_callback(ok)
        cf.mem.mem_read_failed_cb.remove_callback(failed)
    assert "failed" not in result, "the firmware refused the read"
    return result["data"]  # type: ignore[return-value]


def upload(cf: Crazyflie, pieces: list[Piece], trajectory_id: int = 1) -> bool:
    """Upload and define, as cflib's own example does."""
    trajectory_mem = cf.mem.get_mems(MemoryElement.TYPE_TRAJ)[0]
    trajectory_mem.trajectory = [piece.to_cflib() for piece in pieces]
    if not trajectory_mem.write_data_sync():
        return False
    cf.high_level_commander.define_trajectory(trajectory_id, 0, len(pieces))
    return True


def test_cflib_finds_the_memories_and_round_trips_the_trajectory_memory(make_world: MakeWorld, toc_cache: Path) -> None:
    world = make_world(1)
    with SyncCrazyflie(world.uri(A), cf=Crazyflie(rw_cache=str(toc_cache))) as scf:
        cf = scf.cf
        assert [(m.id, m.type) for m in cf.mem.mems] == [
            (0, MemoryElement.TYPE_I2C),
            (1, MemoryElement.TYPE_TRAJ),
            (2, MemoryElement.TYPE_MEMORY_TESTER),
            (3, MemoryElement.TYPE_DECK_MEMORY),
            (4, MemoryElement.TYPE_DECKCTRL_DFU),
        ]
        (trajectory_mem,) = cf.mem.get_mems(MemoryElement.TYPE_TRAJ)
        assert trajectory_mem.size == 4096
        pieces = figure_eight()
        assert upload(cf, pieces)
        data = b"".join(piece.packed() for piece in pieces)
        assert read_memory(cf, trajectory_mem, 0, len(data)) == data

        # 32 pieces (4224 bytes) do not fit 4096: the chunk that crosses the end is refused, cflib reports failure
        trajectory_mem.trajectory = [pieces[i % len(pieces)].to_cflib() for i in range(32)]
        assert trajectory_mem.write_data_sync() is False
        big = b"".join(pieces[i % len(pieces)].packed() for i in range(32))
        assert read_memory(cf, trajectory_mem, 0, 4080) == big[:4080]  # 170 chunks of 24 went in before it
        assert read_memory(cf, trajectory_mem, 4080, 16) == bytes(16)

        # the EEPROM's config block, as cflib's I2C element decodes it
        (eeprom,) = cf.mem.get_mems(MemoryElement.TYPE_I2C)
        updated = threading.Event()
        eeprom.update(lambda mem: updated.set())
        assert updated.wait(5.0) and eeprom.valid
        assert eeprom.elements["radio_address"] == A and eeprom.elements["radio_speed"] == 2


def test_figure_eights_are_flown_on_the_polynomial(make_world: MakeWorld, toc_cache: Path) -> None:
    """Drone A flies the figure absolute (around the origin, at 0.5 m); drone B, 2 m away and turned by 1 rad,
    flies a smaller one relative to its hover point with time scale 0.75 (faster) and relative yaw.

    Tolerance: the commands take effect at the start of the fake's 10 ms tick they arrive in, so a drone starts up
    to 10 ms early (up to 9 mm at the figure's 0.9 m/s), an error that decays with the 0.25 s tracking time
    constant; after that it stays within 4 mm (the one-tick lag of the velocity feed-forward and the tracking).
    The world steps on the wall clock, so a step that wakes late adds its lateness times the speed (B flies at up
    to 1.2 m/s: 2 ms late is 2.4 mm; CI once saw 4.1 mm): 12 mm at the start, 6 mm after. A wrong polynomial, time
    scale or relative frame is off by centimetres."""
    world = make_world({A: FakeDroneConfig.at(0.0, 0.0), B: FakeDroneConfig.at(0.0, 2.0)})
    pieces = figure_eight(height=0.5)
    small = figure_eight(a=0.3, b=0.15, height=0.5)
    duration = total_duration(pieces)
    b_hover, b_yaw = (0.0, 2.0, 0.6), 1.0
    samples: dict[int, list[FirmwareSnapshot]] = {A: [], B: []}
    with (
        SyncCrazyflie(world.uri(A), cf=Crazyflie(rw_cache=str(toc_cache))) as a,
        SyncCrazyflie(world.uri(B), cf=Crazyflie(rw_cache=str(toc_cache))) as b,
    ):
        assert upload(a.cf, pieces) and upload(b.cf, small, trajectory_id=3)
        a.cf.high_level_commander.takeoff(0.5, 1.0)
        b.cf.high_level_commander.takeoff(b_hover[2], 1.0, yaw=b_yaw)
        time.sleep(1.3)
        a.cf.high_level_commander.start_trajectory(1)
        b.cf.high_level_commander.start_trajectory(3, time_scale=0.75, relative_position=True, relative_yaw=True)
        deadline = time.monotonic() + duration + 0.4
        while time.monotonic() < deadline:
            for address in (A, B):
                samples[address].append(world.snapshot(address))
            time.sleep(0.02)
        finished = (a.cf.supervisor.hl_traj_finished, a.cf.supervisor.hl_control_active)
        a.cf.high_level_commander.land(0.0, 1.0)
        b.cf.high_level_commander.land(0.0, 1.0)
        time.sleep(1.2)
        landed = world.snapshots()

    p0, _, yaw0 = reference(small, 0.0)
    rotation = shortest_signed_angle_radians(normalize_radians(yaw0), normalize_radians(b_yaw))
    c, s = math.cos(rotation), math.sin(rotation)

    def expected_b(t: float) -> tuple[float, float, float]:
        x, y, z = reference(small, t, timescale=0.75)[0]
        return (c * x - s * y + b_hover[0] - p0[0], s * x + c * y + b_hover[1] - p0[1], z + b_hover[2] - p0[2])

    expectations = {A: (lambda t: reference(pieces, t)[0], duration), B: (expected_b, 0.75 * duration)}
    for address, (expected, length) in expectations.items():
        plan_start = samples[address][-1].hl_plan_start_s  # the trajectory's (earlier samples: the take-off's)
        flying = [
            snap
            for snap in samples[address]
            if snap.hl_plan_start_s == plan_start and snap.time_s - plan_start <= length
        ]
        assert len(flying) > 0.7 * length / 0.02, f"{len(flying)} samples of {address:X}"
        errors = [
            (snap.time_s - plan_start, math.dist(snap.position, expected(snap.time_s - plan_start))) for snap in flying
        ]
        start_error = max(e for t, e in errors if t < 0.25)
        later_error = max(e for t, e in errors if t >= 0.25)
        assert start_error < 0.012 and later_error < 0.006, (
            f"{address:X}: {start_error * 1000:.1f} mm, {later_error * 1000:.1f} mm off the polynomial"
        )
        # it went round the figure: 0.4 m (A) or 0.3 m (B) either side of the start
        spread = max(math.dist(snap.position[:2], flying[0].position[:2]) for snap in flying)
        assert spread > (0.38 if address == A else 0.28)
        assert landed[address].position[2] == pytest.approx(0.0, abs=1e-6)
    # after the figure, before landing: still FLYING, hovering at the end, the trajectory-finished bit set
    last = samples[A][-1]
    assert last.hl_state == "FLYING" and last.position == pytest.approx(reference(pieces, duration)[0], abs=2e-3)
    assert finished == (True, True)
