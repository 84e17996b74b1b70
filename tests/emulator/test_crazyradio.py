"""The emulated Crazyradio at the USB boundary: plain cflib programs with ``radio://`` URIs, cflib's own RadioDriver,
_SharedRadio and Crazyradio classes unchanged, pyusb above an emulated backend, simulated drones behind it; and the
dongle's time, from the figures of `crazyradio_timing` (upper bounds on what a dongle carries only: a slow host can
only make it slower)."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import cflib.crtp
import libusb_package
import pytest
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.log import LogConfig
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie
from cflib.crazyflie.syncLogger import SyncLogger
from cflib.crtp.radiodriver import RadioDriver, RadioManager
from cflib.drivers import crazyradio as cflib_crazyradio

from rpf_fly.emulator import crazyradio
from rpf_fly.emulator.crazyradio import SET_RADIO_ADDRESS, SET_RADIO_CHANNEL, Plugged
from rpf_fly.emulator.crazyradio_timing import CRAZYRADIO_2, RADIO_TYPES, ceiling_per_s, transaction_s
from rpf_fly.emulator.fake_world import FakeDroneConfig, FakeWorld

E1, E2, E3, E7 = 0xE7E7E7E7E1, 0xE7E7E7E7E2, 0xE7E7E7E7E3, 0xE7E7E7E7E7


@pytest.fixture(scope="module")
def cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One TOC cache for the module: the first connection downloads the fake firmware's TOCs, the rest read them."""
    return tmp_path_factory.mktemp("toc")


@pytest.fixture
def radio_only() -> Iterator[None]:
    """cflib's driver list as ``init_drivers()`` makes it on a fresh interpreter, radio first (other tests append
    their own drivers to the same process-wide list); put back afterwards."""
    saved = list(cflib.crtp.CLASSES)
    cflib.crtp.CLASSES[:] = []
    cflib.crtp.init_drivers()
    yield
    cflib.crtp.CLASSES[:] = saved


def _released(devid: int = 0, timeout_s: float = 2.0) -> None:
    """Wait until cflib's shared radio of ``devid`` closed its dongle (its STOP command is handled on its own
    thread), so the next test's `plug` is the one cflib opens."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        radios = RadioManager._radios
        if len(radios) <= devid or radios[devid] is None or radios[devid]._radio is None:
            return
        time.sleep(0.01)


@pytest.fixture
def plugged(radio_only: None) -> Iterator[list[Plugged]]:
    """Plugs made by a test, unplugged and their worlds closed afterwards."""
    made: list[Plugged] = []
    yield made
    _released()
    crazyradio.unplug()
    for plug in made:
        if hasattr(plug.world, "close"):
            plug.world.close()


def _world() -> FakeWorld:
    return FakeWorld(
        {
            E1: FakeDroneConfig.at(0.0, 0.0),
            E2: FakeDroneConfig.at(0.5, 0.0, channel=90),
            E3: FakeDroneConfig.at(1.0, 0.0),
            E7: FakeDroneConfig.at(1.5, 0.0),
        }
    )


def test_plug_shows_dongles_to_pyusb_and_cflib_and_unplug_gives_the_real_backend_back(plugged: list[Plugged]) -> None:
    real = libusb_package.get_libusb1_backend
    plug = crazyradio.plug(_world(), dongles=2, radio="crazyradio_pa")
    plugged.append(plug)
    assert libusb_package.get_libusb1_backend() is plug.backend
    serials = cflib_crazyradio.get_serials()
    assert serials == tuple(d.serial for d in plug.dongles) and len(serials[0]) == 10
    radio = cflib_crazyradio.Crazyradio(devid=1)
    try:
        assert radio.version == 0.53  # bcdDevice 0x0053, read as cflib reads it
        assert radio.dev.product == "Crazyradio PA USB Dongle"
        # what cflib's constructor configured, through vendor requests on dongle 1 only
        second = plug.dongles[1]
        assert (second.rate, second.channel, second.arc, second.ard, second.ack_enabled) == (2, 2, 3, 0xA0, True)
        assert plug.dongles[0].counters.vendor_requests == {}
    finally:
        radio.close()
    crazyradio.unplug()
    assert libusb_package.get_libusb1_backend is real


def test_each_operation_spends_the_documented_time_and_an_ack_is_never_empty(plugged: list[Plugged]) -> None:
    for name in ("crazyradio_pa", "crazyradio_2"):
        kind = RADIO_TYPES[name]
        plug = crazyradio.plug(_world(), radio=name)
        plugged.append(plug)
        radio = cflib_crazyradio.Crazyradio(devid=0)
        try:
            radio.set_address((0xE7,) * 5)
            radio.set_channel(80)
            start = time.monotonic()
            for i in range(20):
                radio.set_channel(81 + i % 2)
            assert time.monotonic() - start >= 20 * kind.control_s
            radio.set_channel(80)
            start = time.monotonic()
            for _ in range(20):
                ack = radio.send_packet((0xFF,))
                assert ack.ack and len(ack.data) >= 1 and ack.data[0] & 0xF3 == 0xF3  # the nRF's empty ack
            assert time.monotonic() - start >= 20 * transaction_s(kind)
            radio.set_address((0xE7, 0xE7, 0xE7, 0xE7, 0x99))  # nobody there: ARC retransmissions, no ack
            start = time.monotonic()
            ack = radio.send_packet((0xFF,))
            assert not ack.ack and ack.retry == 3
            assert time.monotonic() - start >= kind.bulk_out_s + 4 * (kind.ramp_s + 500e-6) + kind.bulk_in_s
        finally:
            radio.close()


def test_scan_interfaces_finds_the_drones_on_their_channels(plugged: list[Plugged]) -> None:
    plugged.append(crazyradio.plug(_world()))
    assert cflib.crtp.scan_interfaces() == [["radio://0/80/2M", ""]]  # E7E7E7E7E7, a Crazyflie out of the box
    assert cflib.crtp.scan_interfaces(E2) == [["radio://0/90/2M/E7E7E7E7E2", ""]]


def test_plug_without_a_world_brings_drones_on_their_first_connection(plugged: list[Plugged], cache: Path) -> None:
    plug = crazyradio.plug()
    plugged.append(plug)
    assert cflib.crtp.scan_interfaces(0xE7E7E7E701) == []
    with SyncCrazyflie("radio://0/60/2M/E7E7E7E701", cf=Crazyflie(rw_cache=str(cache))) as scf:
        assert scf.is_link_open()
    assert plug.world.addresses == (0xE7E7E7E701,)
    _released()
    assert cflib.crtp.scan_interfaces(0xE7E7E7E701) == [["radio://0/60/2M/E7E7E7E701", ""]]


def test_a_plain_cflib_program_flies_several_drones_through_cflibs_own_radio_driver(
    plugged: list[Plugged], cache: Path
) -> None:
    world = _world()
    plug = crazyradio.plug(world)
    plugged.append(plug)
    uris = {E1: "radio://0/80/2M/E7E7E7E7E1", E2: "radio://0/90/2M/E7E7E7E7E2", E3: "radio://0/80/2M/E7E7E7E7E3"}
    links = {a: SyncCrazyflie(uri, cf=Crazyflie(rw_cache=str(cache))) for a, uri in uris.items()}
    for scf in links.values():
        scf.open_link()
    try:
        shared = RadioManager._radios[0]
        assert type(shared._radio) is cflib_crazyradio.Crazyradio
        assert shared._radio.dev._ctx.backend is plug.backend
        for scf in links.values():
            assert type(scf.cf.link) is RadioDriver and RadioDriver.__module__ == "cflib.crtp.radiodriver"
            assert scf.cf.link.needs_resending is False  # safelink answered by the simulated nRF
            assert scf.cf.param.get_value("stabilizer.estimator") == "0"
            scf.cf.param.set_value("stabilizer.estimator", 2)
            log = LogConfig(name="z", period_in_ms=10)
            log.add_variable("stateEstimate.z", "float")
            with SyncLogger(scf, log) as logger:
                samples = [entry for _, entry in zip(range(5), logger)]
            assert len(samples) == 5 and all("stateEstimate.z" in entry[1] for entry in samples)
            for _ in range(20):
                scf.cf.commander.send_position_setpoint(0.0, 0.0, 0.0, 0.0)
                time.sleep(0.01)
        for address in uris:
            assert world.wait_until(lambda w, a=address: w.snapshot(a).packets_received.get((7, 0)) == 20, 5.0)
            assert world.snapshot(address).params["stabilizer.estimator"] == 2
    finally:
        for scf in links.values():
            scf.close_link()
    _released()
    for address in uris:
        # every packet a firmware got went through cflib's Crazyradio and the emulated backend's bulk writes: one
        # bulk write each, plus the link's safelink packet (no loss here, so nothing was sent twice)
        drone = plug.air.radio(address)
        assert drone is not None
        assert sum(world.snapshot(address).packets_received.values()) == drone.passed_on
        assert plug.dongles[0].counters.packets[address] == drone.passed_on + 1


def test_links_on_one_dongle_share_it_one_setup_call_per_address_switch(plugged: list[Plugged], cache: Path) -> None:
    plug = crazyradio.plug(_world(), radio="crazyradio_2")
    plugged.append(plug)
    dongle = plug.dongles[0]
    uris = ["radio://0/80/2M/E7E7E7E7E1", "radio://0/90/2M/E7E7E7E7E2", "radio://0/80/2M/E7E7E7E7E3"]
    links = [SyncCrazyflie(uri, cf=Crazyflie(rw_cache=str(cache))) for uri in uris]
    for scf in links:
        scf.open_link()
    try:
        time.sleep(0.3)
        with dongle._lock:
            before = (
                time.monotonic(),
                dongle.counters.bulk_writes,
                dongle.counters.address_switches,
                dongle.counters.channel_switches,
                dict(dongle.counters.vendor_requests),
            )
        time.sleep(1.5)
        with dongle._lock:
            after = (
                time.monotonic(),
                dongle.counters.bulk_writes,
                dongle.counters.address_switches,
                dongle.counters.channel_switches,
                dict(dongle.counters.vendor_requests),
            )
    finally:
        for scf in links:
            scf.close_link()
    elapsed = after[0] - before[0]
    writes, switches, channel_switches = (after[i] - before[i] for i in (1, 2, 3))
    set_address = after[4].get(SET_RADIO_ADDRESS, 0) - before[4].get(SET_RADIO_ADDRESS, 0)
    set_channel = after[4].get(SET_RADIO_CHANNEL, 0) - before[4].get(SET_RADIO_CHANNEL, 0)
    assert writes > 0 and switches > 0 and channel_switches > 0
    # cflib's Crazyradio sends SET_RADIO_ADDRESS (SET_RADIO_CHANNEL) only when the next packet's differs: one setup
    # call per switch (a call at either edge of the window may fall on the other side of it)
    assert abs(set_address - switches) <= 1
    assert abs(set_channel - channel_switches) <= 1
    # the dongle never does more than its figures allow: each setup call and each transaction takes its time
    needed = (set_address + set_channel) * CRAZYRADIO_2.control_s + writes * transaction_s(CRAZYRADIO_2)
    assert needed <= elapsed + 2 * (CRAZYRADIO_2.control_s + transaction_s(CRAZYRADIO_2))
    assert writes / elapsed <= ceiling_per_s(CRAZYRADIO_2, switching=False)


def test_what_each_firmware_transmits_a_safelink_echo_and_the_data_rates_and_channels_it_refuses(
    plugged: list[Plugged],
) -> None:
    safelink = (0xFF, 0x05, 0x01)
    for name in ("crazyradio_pa", "crazyradio_2"):
        plug = crazyradio.plug(_world(), radio=name)
        plugged.append(plug)
        radio = cflib_crazyradio.Crazyradio(devid=0)
        try:
            radio.set_address((0xE7, 0xE7, 0xE7, 0xE7, 0xE3))
            radio.set_channel(101)
            refused = radio.send_packet(safelink)
            radio.set_channel(70)
            radio.set_data_rate(radio.DR_250KPS)
            at_250k = radio.send_packet(safelink)
        finally:
            radio.close()
        if name == "crazyradio_pa":  # channels to 125 and 250 kbps: the first safelink packet tunes the drone
            assert refused.ack and tuple(refused.data) == safelink
            assert not at_250k.ack  # the drone now listens on channel 101 at 2M only
        else:  # the 2.0 sends nothing above channel 100 or at 250 kbps: a single 0 byte at once
            assert not refused.ack and not at_250k.ack
            assert plug.air.radio(E3) is None or plug.air.radio(E3).tuned is None
        _released()


def test_unplug_leaves_open_links_working_until_cflib_closes_them(plugged: list[Plugged], cache: Path) -> None:
    world = _world()
    plug = crazyradio.plug(world)
    plugged.append(plug)
    with SyncCrazyflie("radio://0/80/2M/E7E7E7E7E1", cf=Crazyflie(rw_cache=str(cache))) as scf:
        crazyradio.unplug()
        assert libusb_package.get_libusb1_backend() is not plug.backend
        scf.cf.param.set_value("stabilizer.estimator", 1)
        assert world.wait_until(lambda w: w.snapshot(E1).params["stabilizer.estimator"] == 1, 2.0)
        assert plug.air.radio(E1) is not None
    _released()
    assert plug.air.radio(E1) is None  # the last handle closed: the drones are let go
