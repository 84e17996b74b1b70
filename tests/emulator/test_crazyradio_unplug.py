"""An emulated Crazyradio pulled out under cflib 0.1.34 (`crazyradio.pull_out`, the ``dongle_unplug`` fault with
``dry_run.radio: crazyradio``): cflib does what it does with a real dongle that vanishes, and these tests pin it
(docs/radio.md, "A dongle pulled out"). Every sender then waits 2 s and gets cflib's "Could not send packet to
copter"; the link-error callback runs in that sender's thread under the Crazyflie's send lock, and cflib's
``Crazyflie`` hangs in it before ``connection_lost``: with several links in ``RadioDriver.close`` (the driver
threads wait for ever on the shared radio thread, which died on the USB error), or in ``link_statistics.stop`` (it
joins the latency ping thread, which waits for the send lock; when the ping thread is the sender, the join raises in
it and the send lock stays taken). Also: a fresh `plug` forgets the dead shared radio, and an answer never rides on
its own packet's acknowledgement."""

from __future__ import annotations

import logging
import struct
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import cflib.crtp
import pytest
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie
from cflib.crtp.crtpstack import CRTPPacket, CRTPPort
from cflib.crtp.radiodriver import RadioManager

from rpf_fly.emulator import crazyradio, fake_radio
from rpf_fly.emulator.fake_world import FakeDroneConfig, FakeWorld
from rpf_fly.flight.fault_injection import FaultInjection
from rpf_fly.flight.faults import Fault
from rpf_fly.mission import parse_mission

UNSENT = "Got link error callback [RadioDriver: Could not send packet to copter]"


def address(i: int) -> int:
    return 0xE7E7E7E7E0 + i


@pytest.fixture
def worlds() -> Iterator[list[FakeWorld]]:
    """cflib's radio driver first (other tests append their own drivers to the process-wide list); every world
    closed, the dongles unplugged and the fake radio's dongles put back afterwards."""
    saved = list(cflib.crtp.CLASSES)
    cflib.crtp.CLASSES[:] = []
    cflib.crtp.init_drivers()
    made: list[FakeWorld] = []
    yield made
    crazyradio.unplug()
    fake_radio.replug()
    for world in made:
        world.close()
    cflib.crtp.CLASSES[:] = saved


def _fly(worlds: list[FakeWorld], cache: Path, n: int) -> tuple[crazyradio.Plugged, list[SyncCrazyflie]]:
    world = FakeWorld({address(i): FakeDroneConfig.at(0.5 * i, 0.0) for i in range(n)})
    worlds.append(world)
    plug = crazyradio.plug(world, radio="crazyradio_pa")
    links = [SyncCrazyflie(f"radio://0/80/2M/{address(i):010X}", cf=Crazyflie(rw_cache=str(cache))) for i in range(n)]
    for scf in links:
        scf.open_link()
    return plug, links


def _stream(links: list[SyncCrazyflie], seconds: float) -> None:
    """Setpoints at 10 Hz on every link from a thread of its own (the flight's senders), for ``seconds``."""

    def send(scf: SyncCrazyflie) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            scf.cf.commander.send_position_setpoint(0.0, 0.0, 0.0, 0.0)
            time.sleep(0.1)

    for scf in links:
        threading.Thread(target=send, args=(scf,), daemon=True).start()


def _pulled_out(links: list[SyncCrazyflie], caplog: pytest.LogCaptureFixture, pull: object) -> dict[str, float]:
    """Pull the dongle out with ``pull()`` while every link streams; the links cflib said lost, with when."""
    lost: dict[str, float] = {}
    for scf in links:
        scf.cf.connection_lost.add_callback(lambda uri, message: lost.setdefault(uri, time.monotonic()))
    _stream(links, 4.0)
    time.sleep(0.3)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="cflib.crazyflie"):
        pull()  # type: ignore[operator]
        pulled = time.monotonic()
        time.sleep(3.2)
    unsent = [r for r in caplog.records if r.getMessage().startswith(UNSENT)]
    assert len(unsent) == len(links), [r.getMessage() for r in caplog.records]
    assert all(r.created - (time.time() - time.monotonic() + pulled) >= 1.9 for r in unsent)  # a 2 s put timeout
    return lost


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")  # cflib's ping thread (doc)
def test_a_dongle_pulled_out_under_several_links_fails_every_send_and_cflib_never_says_lost(
    worlds: list[FakeWorld], tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    plug, links = _fly(worlds, tmp_path, 3)
    mission = parse_mission(
        "name: m\narena: {x: [-2, 2], y: [-2, 2]}\ndrones:\n"
        "  - {name: cf1, uri: radio://0/80/2M/E7E7E7E7E0, start: [0, 0], goal: [1, 0]}\n"
    )
    unplug = Fault(kind="dongle_unplug", params={"dongle": 0})
    # the fault's own injection: the fake radio's dongle 0 (no link on it here) and the emulated Crazyradio 0
    lost = _pulled_out(links, caplog, lambda: FaultInjection(mission, [unplug])._apply(unplug, None, None))
    assert not plug.dongles[0].present and fake_radio.unplugged() == {0}
    assert lost == {}  # cflib's Crazyflie hangs in its link-error callback (module doc): no connection_lost
    shared = RadioManager._radios[0]
    assert shared is not None and not shared.is_alive()  # died on the USB error of a SET_RADIO_ADDRESS
    # a fresh plug (a new process would have none of this): the dead shared radio is forgotten, links work again
    world = FakeWorld({address(7): FakeDroneConfig.at(0.0, 0.0)})
    worlds.append(world)
    crazyradio.plug(world, radio="crazyradio_pa")
    assert RadioManager._radios[0] is None
    with SyncCrazyflie(f"radio://0/80/2M/{address(7):010X}", cf=Crazyflie(rw_cache=str(tmp_path))) as scf:
        assert scf.cf.param.get_value("stabilizer.estimator") == "0"


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")  # cflib's ping thread (doc)
def test_a_dongle_pulled_out_under_one_link_fails_its_sends_and_cflib_never_says_lost(
    worlds: list[FakeWorld], tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    plug, links = _fly(worlds, tmp_path, 1)
    lost = _pulled_out(links, caplog, lambda: crazyradio.pull_out(0))
    assert lost == {}  # hangs in link_statistics.stop (module doc)
    # the driver thread retried at once on every missing status (no error of its own); the sender's link error
    # closed the link, and the shared radio closed its dongle
    assert crazyradio.wait_released([0], 1.0)
    assert plug.dongles[0].counters.bulk_writes > 0
    assert not crazyradio.pull_out(5)  # no such dongle


def test_an_answer_rides_on_the_next_acknowledgement_never_on_its_own(worlds: list[FakeWorld]) -> None:
    world = FakeWorld({address(1): FakeDroneConfig.at(0.0, 0.0)})
    worlds.append(world)
    plug = crazyradio.plug(world, radio="crazyradio_pa")
    from cflib.drivers.crazyradio import Crazyradio

    radio = Crazyradio(devid=0)
    try:
        radio.set_channel(80)
        radio.set_address(tuple(address(1).to_bytes(5, "big")))
        assert tuple(radio.send_packet((0xFF, 0x05, 0x01)).data) == (0xFF, 0x05, 0x01)  # safelink on
        echo = CRTPPacket()
        echo.set_header(CRTPPort.LINKCTRL, 0)
        echo.data = struct.pack("<BH", 0x50, 7)
        bits = {"up": 0, "down": 0}

        def safe(packet: bytes) -> bytes:
            """One packet with cflib's safelink bits (``_RadioDriverThread._send_packet_safe``)."""
            head = (packet[0] & 0xF3) | bits["up"] << 3 | bits["down"] << 2
            ack = radio.send_packet(bytes((head,)) + packet[1:])
            assert ack.ack
            if ack.data and (ack.data[0] & 0x04) == bits["down"] << 2:
                bits["down"] ^= 1
            bits["up"] ^= 1
            return bytes(ack.data)

        own = safe(bytes((echo.header,)) + bytes(echo.data))
        assert len(own) == 1 and own[0] & 0xF3 == 0xF3  # its own acknowledgement: empty (chosen before it came)
        assert safe(bytes((0xFF,)))[1:] == bytes(echo.data)  # the echo, on the next poll's
    finally:
        radio.close()
    assert plug.air.radio(address(1)) is not None


def test_a_broadcast_reaches_every_drone_on_the_channel_at_each_of_its_attempts(worlds: list[FakeWorld]) -> None:
    """cflib 0.1.34's shared radio sends a packed extpos to 0xFFE7E7E7E7 (rpf_fly/radio/broadcast.py): nobody
    acknowledges it, the dongle makes its ARC + 1 attempts, and each reaches every drone listening on the channel."""
    from rpf_fly.emulator.crazyradio_timing import CRAZYRADIO_PA, radio_s
    from rpf_fly.radio.broadcast import CflibBroadcast
    from rpf_fly.radio.packed_extpos import BROADCAST_COPIES, HEADER, drone_id, encode

    world = FakeWorld(
        {address(i): FakeDroneConfig.at(0.5 * i, 0.0) for i in range(3)}
        | {address(9): FakeDroneConfig.at(0.0, 1.0, channel=90)}
    )
    worlds.append(world)
    plug = crazyradio.plug(world, radio="crazyradio_pa")
    sender = CflibBroadcast(0, 80, "2M")
    try:
        packet = bytes((HEADER,)) + encode([(drone_id(address(i)), (0.5 * i, 0.0, 0.0)) for i in range(3)])
        start = time.monotonic()
        assert sender.send(packet)
        took = time.monotonic() - start
    finally:
        sender.close()
    counters = plug.dongles[0].counters
    assert counters.broadcasts == 1 and counters.acked == 0
    assert took >= radio_s(CRAZYRADIO_PA, 2, len(packet), 0, BROADCAST_COPIES, False, 500e-6)
    port, channel = (HEADER >> 4) & 0x0F, HEADER & 0x03
    for i in range(3):
        assert world.snapshot(address(i)).packets_received.get((port, channel)) == BROADCAST_COPIES
    assert not world.snapshot(address(9)).packets_received.get((port, channel))  # on channel 90: hears none
