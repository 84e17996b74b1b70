"""Fixtures shared by the emulator and radio tests: one fake world per test, a warm cflib TOC cache per worker,
a hang guard (autouse in tests/emulator and tests/radio, through their conftest)."""

from __future__ import annotations

import faulthandler
import sys
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path

import cflib.crtp
import pytest
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie

from rpf_fly.emulator import fake_radio
from rpf_fly.emulator.fake_world import FakeDroneConfig, FakeWorld

ADDRESS_BASE = 0xE7E7E7E700
HANG_GUARD_S = 120.0
"""A radio test that runs longer than this is stuck (cflib waits forever on silence): dump stacks and exit."""


def address(index: int) -> int:
    """Radio address of drone `index` in the test worlds."""
    return ADDRESS_BASE + index


def fake_drivers() -> list[type]:
    return [c for c in cflib.crtp.CLASSES if isinstance(c, type) and issubclass(c, fake_radio.FakeRadioDriver)]


@pytest.fixture
def hang_guard() -> Iterator[None]:
    faulthandler.dump_traceback_later(HANG_GUARD_S, exit=True, file=sys.stderr)
    yield
    faulthandler.cancel_dump_traceback_later()


MakeWorld = Callable[..., FakeWorld]


@pytest.fixture
def make_world() -> Iterator[MakeWorld]:
    """``make_world(n_or_configs, **FakeWorld kwargs)``: a registered `FakeWorld`; drones ``i`` at (0.5 i, 0, 0)
    when given a count. Teardown unregisters the driver and powers the world off."""
    worlds: list[FakeWorld] = []

    def make(drones: int | Mapping[int, FakeDroneConfig], **kwargs: object) -> FakeWorld:
        configs = (
            {address(i): FakeDroneConfig.at(0.5 * i, 0.0) for i in range(drones)}
            if isinstance(drones, int)
            else dict(drones)
        )
        world = FakeWorld(configs, **kwargs)  # type: ignore[arg-type]
        fake_radio.register(world)
        worlds.append(world)
        return world

    yield make
    fake_radio.unregister()
    for world in worlds:
        world.close()
    assert fake_drivers() == []


@pytest.fixture(scope="session")
def toc_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A cflib TOC cache directory, warmed by one connection (one JSON file per TOC)."""
    path = tmp_path_factory.mktemp("toc_cache")
    world = FakeWorld({address(0): FakeDroneConfig()})
    fake_radio.register(world)
    try:
        with SyncCrazyflie(world.uri(address(0)), cf=Crazyflie(rw_cache=str(path))) as scf:
            scf.wait_for_params()
    finally:
        fake_radio.unregister()
        world.close()
    assert len(list(path.glob("*.json"))) == 2
    return path
