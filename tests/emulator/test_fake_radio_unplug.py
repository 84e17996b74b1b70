"""A Crazyradio pulled out (`fake_radio.unplug`, the ``dongle_unplug`` fault) through the real cflib stack: every link
on that dongle fails at once with cflib's link error and the radio driver's USB message, the links of the other
dongles go on, a link opened on it later fails, and `unregister` / `register` put it back."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from cflib.crazyflie import Crazyflie
from cflib.crazyflie.log import LogConfig
from cflib.crazyflie.swarm import CachedCfFactory, Swarm
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie

from rpf_fly.emulator import fake_radio
from rpf_fly.emulator.fake_world import FakeDroneConfig, FakeWorld

MakeWorld = Callable[..., FakeWorld]


def address(index: int) -> int:
    return 0xE7E7E7E700 + index


def test_unplugging_a_dongle_fails_its_links_at_once_and_leaves_the_others(
    make_world: MakeWorld, toc_cache: Path
) -> None:
    configs = {address(i): FakeDroneConfig.at(0.5 * i, 0.0) for i in range(4)}
    world = make_world(configs)
    uris = [world.uri(a, devid=0 if i % 2 == 0 else 1) for i, a in enumerate(configs)]  # cf0, cf2 on 0; cf1, cf3 on 1
    lost: dict[str, tuple[str, float]] = {}
    samples: dict[str, int] = {}
    with Swarm(uris, factory=CachedCfFactory(rw_cache=str(toc_cache))) as swarm:

        def watch(scf: SyncCrazyflie) -> None:
            uri = scf.cf.link_uri
            scf.cf.connection_lost.add_callback(lambda u, msg: lost.setdefault(u, (msg, time.monotonic())))
            config = LogConfig(name="z", period_in_ms=50)
            config.add_variable("stateEstimate.z", "float")
            config.data_received_cb.add_callback(lambda *a: samples.__setitem__(uri, samples.get(uri, 0) + 1))
            scf.cf.log.add_config(config)
            config.start()

        swarm.parallel_safe(watch)
        time.sleep(0.3)
        unplugged_at = time.monotonic()
        assert fake_radio.unplug(1) == 2
        assert fake_radio.unplugged() == {1}
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline and len(lost) < 2:
            time.sleep(0.005)
        assert set(lost) == {uris[1], uris[3]}, lost
        for uri in (uris[1], uris[3]):
            message, when = lost[uri]
            assert message == fake_radio.UNPLUGGED and "probably been unplugged" in message
            # at once: the USB error's message, not cflib's "Too many packets lost" after 100 failed transactions
            # (0.2 s on the fake link's timing); the time bar leaves a loaded host its scheduling delays
            assert when - unplugged_at < 0.5, when - unplugged_at
        before = dict(samples)
        time.sleep(0.4)
        assert samples[uris[0]] - before[uris[0]] >= 4 and samples[uris[2]] - before[uris[2]] >= 4
        assert samples[uris[1]] == before[uris[1]] and samples[uris[3]] == before[uris[3]]
        assert set(lost) == {uris[1], uris[3]}

        # a link opened on the pulled-out dongle fails too, with the same message
        failed: list[str] = []
        cf = Crazyflie(rw_cache=str(toc_cache))
        cf.connection_failed.add_callback(lambda u, msg: failed.append(msg))
        cf.open_link(world.uri(address(1), devid=1))
        deadline = time.monotonic() + 1.0
        while time.monotonic() < deadline and not failed:
            time.sleep(0.005)
        assert failed == [fake_radio.UNPLUGGED]
        cf.close_link()

    # registering again (every dry run does) plugs it back in: a new link on dongle 1 connects
    fake_radio.register(world)
    assert fake_radio.unplugged() == frozenset()
    with SyncCrazyflie(world.uri(address(1), devid=1), cf=Crazyflie(rw_cache=str(toc_cache))) as scf:
        assert scf.is_link_open()


def test_unregister_and_replug_put_the_dongles_back(make_world: MakeWorld) -> None:
    make_world(1)
    fake_radio.unplug(0)
    fake_radio.unplug(2)
    fake_radio.replug(2)
    assert fake_radio.unplugged() == {0}
    fake_radio.unregister()
    assert fake_radio.unplugged() == frozenset()
