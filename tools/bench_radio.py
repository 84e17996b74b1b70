"""Fake-radio benchmark: swarm connection time and position-setpoint round trips through real cflib.

Measures, with the fake radio (no faults):
1. connect time of N drones (default 10) with a warm TOC cache: `Swarm.open_links()` (TOCs from the cache, cflib's
   "connected") and until every drone's parameter values are read (`wait_for_params`, "fully connected"); median
   over repeats;
2. the round trip of one position setpoint: from `cf.commander.send_position_setpoint` to the fake firmware having
   decoded it (a packet observer on the firmware), and to cflib receiving the `ctrltarget.x` log value that shows it
   (a 10 ms log block: radio up, firmware, log period, radio down, cflib's receive thread); p50 and p99.
   The estimate itself follows the setpoint with the model's 0.25 s time constant, which is the model, not the
   radio, so it is not timed.

Usage:
    python tools/bench_radio.py [--drones 10] [--repeats 5] [--samples 500] [--json]
"""

from __future__ import annotations

import argparse
import json
import random
import statistics
import struct
import tempfile
import threading
import time
from functools import partial

from cflib.crazyflie import Crazyflie
from cflib.crazyflie.log import LogConfig
from cflib.crazyflie.swarm import CachedCfFactory, Swarm
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie

from rpf_fly.emulator import fake_radio
from rpf_fly.emulator.fake_world import FakeDroneConfig, FakeWorld

BASE_ADDRESS = 0xE7E7E7E700


def percentile(values: list[float], q: float) -> float:
    """Nearest-rank percentile (q in 0-100)."""
    ordered = sorted(values)
    rank = max(1, min(len(ordered), round(q / 100.0 * len(ordered) + 0.5)))
    return ordered[rank - 1]


def float32(value: float) -> float:
    return struct.unpack("<f", struct.pack("<f", value))[0]


def bench_connect(drones: int, repeats: int, cache_dir: str) -> dict[str, float]:
    """Median seconds to connect `drones` drones (TOCs from a warm cache) and to read all their parameters."""
    world = FakeWorld({BASE_ADDRESS + i: FakeDroneConfig.at(0.5 * i, 0.0) for i in range(drones)})
    fake_radio.register(world)
    uris = [world.uri(a) for a in world.addresses]
    connected, fully = [], []
    try:
        with Swarm(uris[:1], factory=CachedCfFactory(rw_cache=cache_dir)):
            pass  # warm the TOC cache
        for _ in range(repeats):
            swarm = Swarm(uris, factory=CachedCfFactory(rw_cache=cache_dir))
            start = time.perf_counter()
            swarm.open_links()
            connected.append(time.perf_counter() - start)
            swarm.parallel_safe(lambda scf: scf.wait_for_params())
            fully.append(time.perf_counter() - start)
            swarm.close_links()
    finally:
        fake_radio.unregister()
        world.close()
    return {"connect_median_s": statistics.median(connected), "fully_connected_median_s": statistics.median(fully)}


def bench_round_trip(samples: int, cache_dir: str) -> dict[str, float]:
    """p50/p99 in milliseconds from `send_position_setpoint` to decode in the firmware and to the log showing it."""
    world = FakeWorld({BASE_ADDRESS: FakeDroneConfig()})
    fake_radio.register(world)
    decoded: dict[float, float] = {}
    logged: dict[float, float] = {}
    condition = threading.Condition()

    def on_packet(port: int, channel: int, payload: bytes, stamp: float) -> None:
        if port == 7 and channel == 0 and payload and payload[0] == 7:
            with condition:
                decoded[struct.unpack("<f", payload[1:5])[0]] = stamp
                condition.notify_all()

    def on_log(_ts: int, data: dict[str, float], _conf: LogConfig) -> None:
        stamp = time.perf_counter()
        with condition:
            logged.setdefault(data["ctrltarget.x"], stamp)
            condition.notify_all()

    def seen(x: float) -> bool:
        return x in decoded and x in logged

    world.add_packet_observer(BASE_ADDRESS, on_packet)
    to_decode, to_log = [], []
    try:
        uri = world.uri(BASE_ADDRESS)
        with SyncCrazyflie(uri, cf=Crazyflie(rw_cache=cache_dir)) as scf:
            cf = scf.cf
            scf.wait_for_params()
            config = LogConfig(name="target", period_in_ms=10)
            config.add_variable("ctrltarget.x", "float")
            cf.log.add_config(config)
            config.data_received_cb.add_callback(on_log)
            config.start()
            time.sleep(0.2)
            pauses = random.Random(0)
            for i in range(samples):
                time.sleep(pauses.uniform(0.0, 0.01))  # random phase against the 10 ms log period
                x = float32(0.001 * (i + 1))
                start_mono, start = time.monotonic(), time.perf_counter()
                cf.commander.send_position_setpoint(x, 0.0, 0.5, 0.0)
                with condition:
                    if not condition.wait_for(partial(seen, x), timeout=1.0):
                        raise RuntimeError(f"setpoint {i} not seen within 1 s")
                to_decode.append((decoded[x] - start_mono) * 1000.0)
                to_log.append((logged[x] - start) * 1000.0)
            config.stop()
            cf.commander.send_notify_setpoint_stop()
            cf.high_level_commander.land(0.0, 0.5)
            time.sleep(0.6)
    finally:
        fake_radio.unregister()
        world.close()
    return {
        "setpoint_to_decode_p50_ms": percentile(to_decode, 50),
        "setpoint_to_decode_p99_ms": percentile(to_decode, 99),
        "setpoint_to_log_p50_ms": percentile(to_log, 50),
        "setpoint_to_log_p99_ms": percentile(to_log, 99),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--drones", type=int, default=10, help="drones to connect (default 10)")
    parser.add_argument("--repeats", type=int, default=5, help="connection repeats (default 5)")
    parser.add_argument("--samples", type=int, default=500, help="setpoint round trips (default 500)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="rpf-toc-") as cache_dir:
        results = {"drones": args.drones, "repeats": args.repeats, "samples": args.samples}
        results.update(bench_connect(args.drones, args.repeats, cache_dir))
        results.update(bench_round_trip(args.samples, cache_dir))
    if args.json:
        print(json.dumps(results))
        return
    print(f"fake radio, {args.drones} drones, warm TOC cache, median of {args.repeats}:")
    print(f"  connected (Swarm.open_links)       {results['connect_median_s'] * 1000:8.1f} ms")
    print(f"  fully connected (all param values) {results['fully_connected_median_s'] * 1000:8.1f} ms")
    print(f"position setpoint round trip, {args.samples} samples (p50 / p99):")
    print(
        f"  send -> firmware decoded           {results['setpoint_to_decode_p50_ms']:6.2f} / "
        f"{results['setpoint_to_decode_p99_ms']:6.2f} ms"
    )
    print(
        f"  send -> ctrltarget log at cflib    {results['setpoint_to_log_p50_ms']:6.2f} / "
        f"{results['setpoint_to_log_p99_ms']:6.2f} ms  (10 ms log period)"
    )


if __name__ == "__main__":
    main()
