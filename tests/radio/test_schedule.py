"""The radio schedule: extpos at its own rate, each drone in its own slots, spread over the period across the
drones of a dongle; setpoints every tick. Pure, then through real cflib to the fake firmware's uplink packets, and
against the budget's figures (rpf_fly/radio/schedule.py, docs/radio.md "Radio schedule")."""

from __future__ import annotations

import random
import struct
import threading
from collections.abc import Callable
from pathlib import Path

from rpf_fly.emulator.fake_world import FakeWorld
from rpf_fly.mission import parse_mission
from rpf_fly.radio.budget import LINK_PING_HZ, dongle_of, radio_loads
from rpf_fly.radio.cflib_backend import CflibBackend
from rpf_fly.radio.schedule import ExtposSchedule, extpos_phases, frame_share

MakeWorld = Callable[..., FakeWorld]


def address(index: int) -> int:
    return 0xE7E7E7E700 + index


def run(schedule: ExtposSchedule, names: list[str], times: list[float]) -> dict[str, list[int]]:
    """The frames (indices into ``times``) on which each drone's extpos goes out."""
    sent: dict[str, list[int]] = {n: [] for n in names}
    for k, t in enumerate(times):
        for name in names:
            if schedule.due(name, t):
                sent[name].append(k)
    return sent


def test_each_drone_sends_exactly_its_rate_spread_over_the_period_across_its_dongle() -> None:
    uris = {f"cf{i}": f"radio://{0 if i < 10 else 1}/80/2M/E7E7E7E7{i:02X}" for i in range(12)}
    assert extpos_phases(uris) == {**{f"cf{i}": (i + 0.5) / 10 for i in range(10)}, "cf10": 0.25, "cf11": 0.75}
    names = list(uris)
    jitter = random.Random(4)
    for times in (
        [k / 100 for k in range(300)],  # 3 s of 100 Hz mocap, on time ...
        [k / 100 + jitter.uniform(-0.003, 0.003) for k in range(300)],
    ):  # ... and jittered by +-3 ms
        sent = run(ExtposSchedule.for_uris(30.0, uris), names, times)
        for name in names:
            assert abs(len(sent[name]) - 90) <= 1, (name, len(sent[name]))  # 30 Hz: not 25 (every 4th frame)
            gaps = {b - a for a, b in zip(sent[name][1:], sent[name][2:])}  # after the first (on the first frame)
            assert gaps <= ({3, 4} if times[1] == 0.01 else {2, 3, 4, 5}), gaps  # a slot is 3.3 frames
        for dongle, members in ((0, names[:10]), (1, names[10:])):
            per_frame = [sum(k in sent[n] for n in members) for k in range(1, 300)]  # frame 0: every drone's first
            longest = max(b - a for a, b in zip(times, times[1:]))  # a late frame carries the slots it waited for
            assert max(per_frame) <= frame_share(len(members), 30.0, 1.0 / longest), (dongle, max(per_frame))
        if times[1] == 0.01:
            assert max(sum(k in sent[n] for n in names[:10]) for k in range(1, 300)) == 3  # of 10, never 10
    assert frame_share(10, 30.0, 100.0) == 3 and frame_share(3, 100.0, 100.0) == 3 and frame_share(4, 30.0, 100.0) == 2


def test_what_the_firmware_receives_is_the_schedule_and_the_budget(make_world: MakeWorld, toc_cache: Path) -> None:
    """Five drones (four on dongle 0, one on dongle 1) through real cflib: one synthetic second of 100 Hz mocap
    frames, a setpoint to every drone at each 10 Hz tick and extpos on the schedule (its x carries the frame's
    index). Each firmware receives exactly the frames the schedule planned, at most two of dongle 0's drones a
    frame, and per dongle the setpoints and extpos the budget counts for a mission of these rates. The frames come
    as fast as the radio carries them (the backend's outbox keeps only the newest setpoint and extpos of a drone
    whose radio lags, rpf_fly/radio/outbox.py)."""
    world = make_world(5)
    uris = {f"cf{i}": world.uri(a, devid=0 if i < 4 else 1) for i, a in enumerate(world.addresses)}
    mission = parse_mission(
        "name: sched\narena: {x: [-3, 3], y: [-3, 3]}\nflight: {rate_hz: 10}\n"
        "radio: {extpos_rate_hz: 30}\ndrones:\n"
        + "".join(
            f"  - {{name: cf{i}, uri: radio://{dongle_of(u)}/80/2M/E7E7E7E70{i}, "
            f"start: [{i * 0.5}, 0], goal: [{i * 0.5}, 1]}}\n"
            for i, u in enumerate(uris.values())
        )
    )
    seen: dict[str, list[tuple[int, float]]] = {n: [] for n in uris}
    lock = threading.Lock()

    def observer(name: str) -> Callable[[int, int, bytes, float], None]:
        def on_packet(port: int, channel: int, payload: bytes, stamp: float) -> None:
            if port in (6, 7) and channel == 0:
                with lock:
                    seen[name].append((port, struct.unpack_from("<f", payload, 0 if port == 6 else 1)[0]))

        return on_packet

    backend = CflibBackend(cache_dir=toc_cache)
    try:
        assert backend.connect(uris) == {}
        for name, a in zip(uris, world.addresses):
            world.add_packet_observer(a, observer(name))
        schedule = ExtposSchedule.for_uris(30.0, uris)
        planned: dict[str, list[int]] = {n: [] for n in uris}
        for k in range(100):
            t = k / 100
            if k % 10 == 0:  # a planning tick: every drone's setpoint (x = the tick's frame)
                for name in uris:
                    assert backend.send_position_setpoint(name, float(k), 0.0, 0.5, 0.0)
            for name in uris:
                if schedule.due(name, t):
                    planned[name].append(k)
                    assert backend.send_extpos(name, (float(k), 0.0, 0.0))
            assert backend.wait_sent(timeout_s=2.0)  # each frame's packets out before the next, as at 100 Hz
        expected = sum(len(p) for p in planned.values()) + 10 * len(uris)
        assert world.wait_until(lambda w: sum(len(s) for s in seen.values()) >= expected, 10.0)
    finally:
        backend.close()
    extpos = {n: [round(x) for port, x in s if port == 6] for n, s in seen.items()}
    setpoints = {n: [round(x) for port, x in s if port == 7] for n, s in seen.items()}
    assert extpos == planned  # what the firmware got is what the schedule planned, in order
    assert all(s == list(range(0, 100, 10)) for s in setpoints.values())  # setpoints: every tick
    assert all(abs(len(p) - 30) <= 1 for p in planned.values())
    dongle0 = [n for n in uris if dongle_of(uris[n]) == 0]
    assert max(sum(k in extpos[n] for n in dongle0) for k in range(1, 100)) <= 2  # spread: 2 of 4 a frame at most
    for load in radio_loads(mission):  # the budget counts what was sent (pings: cflib's, counted separately)
        names = [n for n in uris if dongle_of(uris[n]) == load.dongle]
        assert load.drones == tuple(names)
        assert sum(len(setpoints[n]) for n in names) == load.setpoints
        assert abs(sum(len(extpos[n]) for n in names) - load.extpos) <= len(names)
        assert load.pings == LINK_PING_HZ * len(names)
