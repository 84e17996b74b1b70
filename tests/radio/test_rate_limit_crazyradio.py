"""What the budget asks of cflib 0.1.34, done by cflib's own radio driver on an emulated Crazyradio PA (cflib's
RadioDriver, _SharedRadio and Crazyradio unchanged, each USB transfer and radio attempt taking its figure's time):
a link opened with ``?rate_limit=N`` makes at most N transactions a second, and a packed broadcast through cflib's
RadioManager goes to the broadcast address, unanswered, in the time of four attempts."""

from __future__ import annotations

import time
from collections.abc import Iterator

import cflib.crtp
import pytest
from cflib.crtp.radiodriver import RadioManager

from rpf_fly.emulator import crazyradio
from rpf_fly.emulator.crazyradio_timing import CRAZYRADIO_PA, DR_2M, ard_s, radio_s
from rpf_fly.emulator.fake_world import FakeDroneConfig, FakeWorld
from rpf_fly.radio.broadcast import CflibBroadcast
from rpf_fly.radio.packed_extpos import BROADCAST_ADDRESS, HEADER, encode

ADDRESSES = (0xE7E7E7E701, 0xE7E7E7E702, 0xE7E7E7E703)


@pytest.fixture
def plugged() -> Iterator[crazyradio.Plugged]:
    saved = list(cflib.crtp.CLASSES)
    cflib.crtp.CLASSES[:] = []
    cflib.crtp.init_drivers()
    world = FakeWorld({a: FakeDroneConfig.at(0.5 * k, 0.0) for k, a in enumerate(ADDRESSES)}).start()
    plug = crazyradio.plug(world, radio="crazyradio_pa")
    yield plug
    deadline = time.monotonic() + 2.0  # cflib's shared radio closes the dongle on its own thread
    while (
        time.monotonic() < deadline
        and len(RadioManager._radios)
        and RadioManager._radios[0] is not None
        and RadioManager._radios[0]._radio is not None
    ):
        time.sleep(0.01)
    crazyradio.unplug()
    world.close()
    cflib.crtp.CLASSES[:] = saved


def transactions(plug: crazyradio.Plugged, address: int) -> int:
    counters = plug.dongles[0].counters
    return counters.packets[address] + counters.polls[address]


def test_rate_limited_links_keep_their_limit_and_a_broadcast_takes_four_unanswered_attempts(
    plugged: crazyradio.Plugged,
) -> None:
    links = [cflib.crtp.get_link_driver(f"radio://0/80/2M/{a:010X}?rate_limit=40") for a in ADDRESSES]
    try:
        assert all(link is not None and link.rate_limit == 40 for link in links)
        time.sleep(0.3)
        before = {a: transactions(plugged, a) for a in ADDRESSES}
        start = time.monotonic()
        time.sleep(1.5)
        rates = {a: (transactions(plugged, a) - before[a]) / (time.monotonic() - start) for a in ADDRESSES}
        # each link: a transaction, then cflib sleeps 1/40 s: under 40 a second, and near it on a quiet dongle
        assert all(20 <= rate <= 40 for rate in rates.values()), rates
        broadcast = CflibBroadcast(0, 80, "2M")
        try:
            packet = bytes((HEADER,)) + encode([(1, (0.5, 0.0, 0.0)), (2, (1.0, 0.0, 0.0)), (3, (1.5, 0.0, 0.0))])
            counters = plugged.dongles[0].counters
            unacked = counters.unacked
            start = time.monotonic()
            for _ in range(10):
                assert broadcast.send(packet)
            elapsed = time.monotonic() - start
        finally:
            broadcast.close()
        assert counters.packets[BROADCAST_ADDRESS] == 10 and counters.unacked - unacked >= 10
        four = radio_s(CRAZYRADIO_PA, DR_2M, len(packet), 0, 4, False, ard_s(0x80 | 32, DR_2M))
        assert elapsed >= 10 * (CRAZYRADIO_PA.control_s + CRAZYRADIO_PA.bulk_out_s + four)
    finally:
        for link in links:
            if link is not None:
                link.close()
