"""`CflibBackend` across connections and ground-station deaths, over the fake radio (real cflib underneath): the
setpoint priority a previous connection latched, the emergency-stop watchdog fed through a flight, and the reboot
that leaves a flown drone ready for the next connection (docs/radio.md, "Keep-alive and the end-of-flight reboot")."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie

from rpf_fly.emulator.fake_world import FakeDroneConfig, FakeWorld
from rpf_fly.radio.cflib_backend import CflibBackend

MakeWorld = Callable[..., FakeWorld]


def address(index: int) -> int:
    return 0xE7E7E7E700 + index


def names_to_uris(world: FakeWorld) -> dict[str, str]:
    return {f"cf{i}": world.uri(a) for i, a in enumerate(world.addresses)}


def wait_for(condition: Callable[[], bool], timeout_s: float, poll_s: float = 0.02) -> bool:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(poll_s)
    return True


@pytest.fixture
def backends() -> Iterator[Callable[..., CflibBackend]]:
    made: list[CflibBackend] = []

    def make(**kwargs: object) -> CflibBackend:
        backend = CflibBackend(**kwargs)  # type: ignore[arg-type]
        made.append(backend)
        return backend

    yield make
    for backend in made:
        backend.close()


def arm_and_take_off(
    backend: CflibBackend,
    world: FakeWorld,
    name: str = "cf0",
    index: int = 0,
    height_m: float = 0.5,
    timeout_s: float = 3.0,
) -> bool:
    """Arm, take off with the high-level commander; True when the world's true height reached ``height_m``."""
    assert backend.arm(name)
    assert wait_for(lambda: backend.state(name).supervisor.can_fly, 1.0)
    assert backend.takeoff(name, height_m, 0.8)
    return world.wait_until(lambda w: w.snapshot(address(index)).position[2] > height_m - 0.03, timeout_s)


# --------------------------------------------------------------------------- a latch left by an earlier connection


def test_a_latch_left_by_an_earlier_connection_is_released(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    """A plain cflib program (a check, an earlier flight, cfclient) sends a low-level setpoint and closes (cflib's
    close_link sends another): the firmware keeps the CRTP priority, and its high-level commander, lower, is refused
    until something relaxes it. A new backend relaxes it at connect, so its take-off flies."""
    world = make_world({address(0): FakeDroneConfig.at(0.0, 0.0, auto_arm=False)})
    with SyncCrazyflie(world.uri(address(0)), cf=Crazyflie(rw_cache=str(toc_cache))) as scf:
        scf.cf.commander.send_setpoint(0, 0, 0, 0)
    assert world.snapshot(address(0)).last_crtp_setpoint_s is not None  # the latch is there

    backend = backends(cache_dir=toc_cache)
    assert backend.connect(names_to_uris(world)) == {}
    assert arm_and_take_off(backend, world), f"the take-off did not fly: {world.snapshot(address(0))}"
    snap = world.snapshot(address(0))
    assert snap.hl_state == "FLYING" and snap.hl_commands_rejected == 0


# --------------------------------------------------------------------------- the emergency-stop watchdog

FREE_FALL = "Exception, free fall"


def fly_a_long_plan(backend: CflibBackend, world: FakeWorld, index: int = 0) -> None:
    """cf<index> armed with its watchdog, at 0.5 m, then on a 20 s high-level go-to: the high-level commander
    re-stamps its setpoint every tick, so the commander's own watchdog never trips."""
    name = f"cf{index}"
    assert backend.arm_watchdog(name)
    assert arm_and_take_off(backend, world, name, index)
    assert backend.go_to(name, (0.5 * index, 0.5, 0.5), 0.0, 20.0)


def test_a_fed_watchdog_lets_a_flight_go_on_while_the_flight_loop_is_silent(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    """Keep-alives come from the backend's own thread: a flight that sends nothing for 2.5 s (a busy loop, a hold)
    is not stopped; the firmware got one about every 0.2 s."""
    world = make_world(1)
    backend = backends(cache_dir=toc_cache)
    assert backend.connect(names_to_uris(world)) == {}
    with pytest.raises(KeyError):
        backend.arm_watchdog("cf9")
    fly_a_long_plan(backend, world)
    fed = world.snapshot(address(0)).packets_received[(9, 1)]
    time.sleep(2.5)
    snap = world.snapshot(address(0))
    assert snap.motors_on and snap.supervisor_state == "Flying" and not snap.emergency_stop_latched
    assert 10 <= snap.packets_received[(9, 1)] - fed <= 14  # supervisor commands: the keep-alives, 5 a second


def test_a_backend_that_stops_feeding_has_its_drone_stopped_within_a_second(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    """The ground station dies (its process: no more keep-alives, the links stay open): the firmware's watchdog
    stops the drone 1 s after the last keep-alive, in the middle of a high-level plan, and locks it."""
    world = make_world(2)
    backend = backends(cache_dir=toc_cache)
    assert backend.connect(names_to_uris(world)) == {}
    fly_a_long_plan(backend, world, 0)
    assert arm_and_take_off(backend, world, "cf1", 1)  # flies without a watchdog: nothing stops it
    stopped_at = world.time_s()
    backend._stop_feeder()
    assert world.wait_until(lambda w: not w.snapshot(address(0)).motors_on, 2.0)
    snap = world.snapshot(address(0))
    assert 0.75 < snap.entered(FREE_FALL) - stopped_at < 1.1
    assert world.wait_until(lambda w: w.snapshot(address(0)).locked and w.snapshot(address(0)).position[2] == 0.0, 1.0)
    assert world.snapshot(address(1)).motors_on and world.snapshot(address(1)).flying
    assert backend.land("cf1", 0.0, 0.8)


def test_a_dropped_link_stops_its_drone_within_a_second(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    """An unplugged dongle or a link out of range: no keep-alive reaches the drone, whose firmware stops it."""
    world = make_world(1)
    backend = backends(cache_dir=toc_cache)
    assert backend.connect(names_to_uris(world)) == {}
    fly_a_long_plan(backend, world)
    dropped_at = world.time_s()
    world.drop_link(address(0))
    assert world.wait_until(lambda w: not w.snapshot(address(0)).motors_on, 2.0)
    assert world.snapshot(address(0)).entered(FREE_FALL) - dropped_at < 1.1
    assert world.wait_until(lambda w: w.snapshot(address(0)).locked, 1.0)
    assert wait_for(lambda: not backend.state("cf0").link.up, 2.0)


# --------------------------------------------------------------------------- the end-of-flight reboot


def land_and_disarm(backend: CflibBackend, name: str = "cf0") -> None:
    """Land, wait until the supervisor no longer says flying (2 s after the motors stopped), disarm: what the
    flight does before it closes."""
    assert backend.land(name, 0.0, 0.8)
    assert wait_for(lambda: not backend.state(name).supervisor.flying, 5.0)
    assert backend.arm(name, False)


def test_a_flown_drone_is_rebooted_at_close_and_the_next_backend_flies_it(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    """Its watchdog is never disarmed by the firmware: without the reboot the drone would lock 1 s after close.
    Rebooted over its link, it boots fresh on the floor and a new backend arms it and takes off. A drone whose
    watchdog was never armed is not rebooted."""
    world = make_world(2)
    backend = backends(cache_dir=toc_cache)
    assert backend.connect(names_to_uris(world)) == {}
    fly_a_long_plan(backend, world)
    land_and_disarm(backend)
    backend.close()
    assert backend.rebooted() == ("cf0",)
    assert world.snapshot(address(0)).booting
    assert world.wait_until(lambda w: w.snapshot(address(0)).boots == 1, 3.0)
    time.sleep(1.2)  # past the old watchdog's second
    for i in range(2):
        snap = world.snapshot(address(i))
        assert not snap.locked and snap.position[2] == 0.0
        assert all(t.new.value != "Locked" for t in snap.transitions)
    assert world.snapshot(address(1)).boots == 0

    again = backends(cache_dir=toc_cache)
    assert again.connect(names_to_uris(world)) == {}
    assert arm_and_take_off(again, world)


def test_a_locked_or_flying_drone_is_not_rebooted(
    make_world: MakeWorld, toc_cache: Path, backends: Callable[..., CflibBackend]
) -> None:
    """A drone locked by an emergency stop stays locked (a person looks at it); one still flying at close is left
    to its watchdog (cflib's close_link already cut its motors)."""
    world = make_world(2)
    backend = backends(cache_dir=toc_cache)
    assert backend.connect(names_to_uris(world)) == {}
    fly_a_long_plan(backend, world, 0)
    fly_a_long_plan(backend, world, 1)
    assert backend.emergency_stop("cf0") == {}
    assert wait_for(lambda: backend.state("cf0").supervisor.locked, 1.0)
    backend.close()
    assert backend.rebooted() == ()
    time.sleep(1.3)
    for i in range(2):
        snap = world.snapshot(address(i))
        assert snap.boots == 0 and snap.locked and not snap.motors_on


def test_the_nrf_reset_commands_reboot_the_simulated_drone() -> None:
    """cflib's `PowerSwitch.reboot_to_fw` on an open link: reset-init (answered with the nRF's address), then reset
    to firmware; a reset without reset-init, or into the bootloader, does nothing."""
    from rpf_fly.emulator.crtp import PORT_LINK
    from rpf_fly.emulator.fake_firmware import REBOOT_BOOT_S, FakeFirmware

    firmware = FakeFirmware(now_s=0.0, radio_address=0xE7E7E7E701)
    for t in range(1, 101):
        firmware.step(t * 0.01)
    firmware.handle(9, 1, bytes([0x04]), 1.0)  # a keep-alive: its watchdog armed
    assert firmware.handle(PORT_LINK, 3, bytes([0xFE, 0xF0, 0x01]), 1.0) == []  # no reset-init yet
    assert firmware.handle(PORT_LINK, 3, bytes([0xFE, 0xFF]), 1.0) == [
        (PORT_LINK, 3, bytes([0xFE, 0xFF, 0x01, 0xE7, 0xE7, 0xE7, 0xE7, 0x00]))
    ]
    assert firmware.handle(PORT_LINK, 3, bytes([0xFE, 0xF0, 0x00]), 1.0) == [] and not firmware.booting
    assert firmware.handle(PORT_LINK, 3, bytes([0xFE, 0xF0, 0x01]), 1.0) == [] and firmware.booting
    assert firmware.handle(PORT_LINK, 0, b"echo", 1.1) == []  # silent while it boots
    t = 1.0
    while t < 1.0 + REBOOT_BOOT_S + 2.0:  # past its boot and the old watchdog's second
        t += 0.01
        firmware.step(t)
    snap = firmware.snapshot()
    assert snap.boots == 1 and not snap.booting and not snap.locked and snap.supervisor_state != "Locked"
    assert firmware.handle(PORT_LINK, 3, bytes([0xFE, 0xF0, 0x01]), t) == [] and not firmware.booting  # re-init
