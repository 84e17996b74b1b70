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


def arm_and_take_off(backend: CflibBackend, world: FakeWorld, name: str = "cf0", index: int = 0,
                     height_m: float = 0.5, timeout_s: float = 3.0) -> bool:
    """Arm, take off with the high-level commander; True when the world's true height reached ``height_m``."""
    assert backend.arm(name)
    assert wait_for(lambda: backend.state(name).supervisor.can_fly, 1.0)
    assert backend.takeoff(name, height_m, 0.8)
    return world.wait_until(lambda w: w.snapshot(address(index)).position[2] > height_m - 0.03, timeout_s)


# --------------------------------------------------------------------------- a latch left by an earlier connection

def test_a_latch_left_by_an_earlier_connection_is_released(make_world: MakeWorld, toc_cache: Path,
                                                          backends: Callable[..., CflibBackend]) -> None:
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
