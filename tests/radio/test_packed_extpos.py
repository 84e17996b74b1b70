"""Packed extpos: the layout the firmware reads (crtp_localization_service.c), the ids, the groups, and the
simulated firmware taking its own position out of a packed packet (synthetic time, packet level)."""

from __future__ import annotations

import math
import struct

import pytest

from rpf_fly.emulator.fake_firmware import FakeFirmware
from rpf_fly.emulator.fake_vehicle import VehicleConfig
from rpf_fly.radio.packed_extpos import HEADER, decode, drone_id, encode, packed_groups, parse_link, shared_ids, to_mm


def test_the_layout_is_the_firmwares_item_four_a_packet() -> None:
    data = encode([(0x01, (1.0, -2.5, 0.0305)), (0xE7, (-32.768, 32.767, 0.0004))])
    # extPositionPackedItem: uint8 id, int16 x, y, z in mm, little-endian, packed (7 bytes)
    assert data == bytes([0x01, 0xE8, 0x03, 0x3C, 0xF6, 0x1E, 0x00, 0xE7, 0x00, 0x80, 0xFF, 0x7F, 0x00, 0x00])
    assert HEADER == 0x6E  # port 6, channel 2 (EXT_POSITION_PACKED), cflib's link bits
    assert len(encode([(k, (0.0, 0.0, 0.0)) for k in range(4)])) == 28  # 4 items fit the 30 data bytes
    with pytest.raises(ValueError, match="1 to 4"):
        encode([(k, (0.0, 0.0, 0.0)) for k in range(5)])
    with pytest.raises(ValueError, match="int16 millimetres"):
        to_mm(32.8)
    assert decode(data + b"\x05\x00") == [(1, (1.0, -2.5, 0.030)), (0xE7, (-32.768, 32.767, 0.0))]  # tail ignored


def test_a_drones_id_is_its_addresss_last_byte_and_groups_follow_dongle_channel_and_rate() -> None:
    assert drone_id(parse_link("radio://0/80/2M/E7E7E7E70A?rate_limit=40").address) == 0x0A
    uris = {f"cf{i}": f"radio://{0 if i <= 6 else 1}/80/2M/E7E7E7E7{i:02X}" for i in range(1, 9)}
    uris["cf9"] = "radio://0/90/2M/E7E7E7E709"
    groups = packed_groups(uris)
    assert [(g.dongle, g.channel, g.names) for g in groups] == [
        (0, 80, ("cf1", "cf2", "cf3", "cf4")),
        (0, 80, ("cf5", "cf6")),
        (1, 80, ("cf7", "cf8")),
        (0, 90, ("cf9",)),
    ]
    assert groups[0].ids == (1, 2, 3, 4)
    assert shared_ids(uris) == []
    uris["cf10"] = "radio://1/80/2M/A1A1A1A101"  # cf1's id on cf1's channel (another dongle: the same air)
    assert shared_ids(uris) == [(80, 1, ("cf1", "cf10"))]


def test_each_simulated_firmware_takes_its_own_position_from_a_packed_packet() -> None:
    firmwares = {
        address: FakeFirmware(
            VehicleConfig(position=(0.0, 0.0, 0.0), positioning="extpos"), radio_address=address, seed=k
        )
        for k, address in enumerate((0xE7E7E7E701, 0xE7E7E7E702, 0xE7E7E7E703, 0xE7E7E7E704, 0xE7E7E7E705))
    }
    truth = {0x01: (1.0, 0.5, 0.0), 0x02: (-1.25, 2.0, 0.0), 0x03: (0.0, -3.0, 0.0), 0x04: (2.5, 2.5, 0.0)}
    packet = encode(list(truth.items()))
    for fw in firmwares.values():
        fw.handle(6, 2, packet, 0.01)
    for address, fw in firmwares.items():
        estimate = fw.snapshot().estimate
        if address & 0xFF in truth:  # power-on variance 1 m^2: the first measurement is taken almost whole
            assert estimate == pytest.approx(truth[address & 0xFF], abs=1e-3), hex(address)
        else:  # not in the packet: nothing moved its estimate (only the IMU, micrometres)
            assert estimate == pytest.approx((0.0, 0.0, 0.0), abs=1e-3)
    # an id another drone's own unicast extpos never confuses: channel 0 still takes three floats
    fw = firmwares[0xE7E7E7E705]
    fw.handle(6, 0, struct.pack("<fff", 0.25, 0.25, 0.0), 0.02)
    assert fw.snapshot().estimate == pytest.approx((0.25, 0.25, 0.0), abs=1e-3)


def test_the_sender_broadcasts_each_groups_positions_through_the_fake_radio_to_every_drone() -> None:
    """Six drones on one fake dongle (two packets: four and two) and one on another channel that hears nothing of
    the first channel's broadcasts; each estimator gets its own position, each position four times (cflib's
    broadcast is sent ARC + 1 times, unacknowledged)."""
    import time

    from rpf_fly.emulator import fake_radio
    from rpf_fly.emulator.fake_world import FakeDroneConfig, FakeWorld, RadioTiming
    from rpf_fly.radio.broadcast import PackedExtposSender

    addresses = {f"cf{i}": 0xE7E7E7E700 + i for i in range(1, 8)}
    channels = {name: 90 if name == "cf7" else 80 for name in addresses}
    world = FakeWorld(
        {a: FakeDroneConfig.at(0.0, 0.0, 0.0, positioning="extpos", channel=channels[n]) for n, a in addresses.items()},
        timing=RadioTiming(transaction_s=0.001),
    ).start()
    heard: dict[str, int] = {name: 0 for name in addresses}
    for name, address in addresses.items():
        world.add_packet_observer(
            address,
            lambda port, ch, data, stamp, name=name: heard.__setitem__(name, heard[name] + (port == 6 and ch == 2)),
        )
    fake_radio.register(world)
    uris = {name: f"fake://0/{channels[name]}/2M/{address:010X}" for name, address in addresses.items()}
    sender = PackedExtposSender({n: u for n, u in uris.items() if n != "cf7"})
    try:
        assert sender.start() == {}
        truth = {name: (0.5 * k, -0.25 * k, 0.0) for k, name in enumerate(addresses, start=1)}
        assert sender.put("cf7", truth["cf7"]) is False  # not in this sender's groups
        assert sender.sent_s("cf1") is None  # no broadcast carried it yet
        for _ in range(30):  # 0.3 s of 100 Hz mocap: each estimate settles on its own drone's position
            for name in addresses:
                if name != "cf7":
                    assert sender.put(name, truth[name])
            time.sleep(0.01)
        time.sleep(0.05)
        assert sender.failed == 0 and sender.positions == 6 * sender.packets // 2
        assert 2 * 25 <= sender.packets <= 2 * 30  # two a frame (a frame or two may fall in one packet)
        for name in addresses:  # when a broadcast with its position went out (the estimate check reads it)
            sent = sender.sent_s(name)
            assert sent is None if name == "cf7" else time.monotonic() - 0.2 < sent <= time.monotonic(), (name, sent)
        for name, address in addresses.items():
            estimate = world.snapshot(address).estimate
            if name == "cf7":
                assert heard[name] == 0 and math.dist(estimate, truth[name]) > 3.0  # its IMU's drift only
            else:  # every packet on its channel (both groups'), four copies each (no loss in a bare world)
                assert heard[name] == 4 * sender.packets
                assert estimate == pytest.approx(truth[name], abs=0.005)
    finally:
        sender.close()
        fake_radio.unregister()
        world.close()


def test_the_schedule_brings_a_packed_groups_drones_due_together_and_spreads_the_groups() -> None:
    from rpf_fly.radio.schedule import ExtposSchedule

    uris = {f"cf{i}": f"radio://0/80/2M/E7E7E7E7{i:02X}" for i in range(1, 11)}  # groups of 4, 4 and 2
    schedule = ExtposSchedule.for_uris(30.0, uris, packed=True)
    due_frames: dict[str, list[int]] = {name: [] for name in uris}
    for frame in range(300):  # 3 s of 100 Hz mocap
        for name in uris:
            if schedule.due(name, frame / 100.0):
                due_frames[name].append(frame)
    groups = (("cf1", "cf2", "cf3", "cf4"), ("cf5", "cf6", "cf7", "cf8"), ("cf9", "cf10"))
    for group in groups:
        assert len({tuple(due_frames[name]) for name in group}) == 1  # one packet a slot for the whole group
        assert 89 <= len(due_frames[group[0]]) <= 91  # 30 Hz
    firsts = [set(due_frames[group[0]]) - {0} for group in groups]  # (every drone's first frame is due)
    assert not (firsts[0] & firsts[1]) and not (firsts[1] & firsts[2]) and not (firsts[0] & firsts[2])  # spread
