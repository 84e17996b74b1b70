"""How many drones one Crazyradio carries at a mission's rates, per-drone extpos against packed: the budget's figures
(rpf_fly/radio/budget.py and its model of cflib's shared radio) and, with ``--measure``, the same traffic through
real cflib on one emulated dongle (rpf_fly/emulator/crazyradio.py: cflib's own radio:// driver and _SharedRadio,
each USB transfer and radio attempt taking its figure's time).

What is measured per swarm size and extpos mode: `CflibBackend` connects the drones on the floor (``radio://``
links with the budget's ``?rate_limit=N``, its status log block, cflib's pings), arms their keep-alives, then for
``--seconds`` streams a position setpoint to every drone at each planning tick and their extpos on the mocap frames
(each drone in its slots, or packed: the groups' broadcasts through cflib's RadioManager). The setpoint latency is
from the tick to the simulated firmware receiving the setpoint (a packet observer on the world, this process's
clock); extpos the same from the frame to the first copy carrying the drone's own position (the emulated dongle
passes a broadcast to every drone on its channel at each of its four attempts: rpf_fly/emulator/crazyradio_air.py).
The drones stand on the floor, which the radio does not care about.

Usage:
    python tools/bench_radio_budget.py [--radio crazyradio_pa] [--rate-hz 10] [--mocap-hz 50] [--extpos-hz 50]
        [--drones 4,6,8,10,12,14] [--measure] [--seconds 5] [--markdown]
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import threading
import time
from collections import defaultdict

from rpf_fly.mission import parse_mission
from rpf_fly.mission.model import Mission
from rpf_fly.radio.budget import DongleLoad, radio_loads
from rpf_fly.radio.packed_extpos import BROADCAST_COPIES, decode

BASE_ADDRESS = 0xE7E7E7E700


def mission_of(drones: int, radio: str, mode: str, rate_hz: float, mocap_hz: float, extpos_hz: float) -> Mission:
    lines = [
        f"name: budget-{drones}",
        "arena: {x: [-10, 10], y: [-10, 10]}",
        f"flight: {{rate_hz: {rate_hz}}}",
        f"mocap: {{kind: sim, rate_hz: {mocap_hz}}}",
        f"radio: {{dongle_type: {radio}, extpos: {mode}, extpos_rate_hz: {extpos_hz}}}",
        "drones:",
    ]
    for k in range(drones):
        x = -9.0 + 0.5 * k
        lines.append(
            f"  - {{name: cf{k + 1}, uri: radio://0/80/2M/{BASE_ADDRESS + k + 1:010X}, start: [{x}, 0], "
            f"goal: [{x}, 1]}}"
        )
    return parse_mission("\n".join(lines) + "\n")


def quantile(values: list[float], q: float) -> float:
    if not values:
        return math.nan
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, max(0, math.ceil(q * len(ordered)) - 1))]


def measure(mission: Mission, seconds: float, cache_dir: str) -> dict[str, float]:
    """The mission's traffic through real cflib on one emulated dongle (module docstring)."""
    from rpf_fly.emulator import crazyradio
    from rpf_fly.emulator.fake_world import FakeDroneConfig, FakeWorld
    from rpf_fly.flight.session import FLIGHT_SWITCH_INTERVAL_S
    from rpf_fly.radio.budget import link_rate_limits
    from rpf_fly.radio.cflib_backend import CflibBackend
    from rpf_fly.radio.packed_extpos import PACKED_EXT_POS_STD_DEV_M
    from rpf_fly.radio.schedule import ExtposSchedule

    sys.setswitchinterval(FLIGHT_SWITCH_INTERVAL_S)  # as a flight's process runs (`run_flight`)
    packed = mission.radio.extpos == "packed"
    addresses = {d.name: int(d.uri.rsplit("/", 1)[1], 16) for d in mission.drones}
    world = FakeWorld(
        {
            addresses[d.name]: FakeDroneConfig.at(d.start[0], d.start[1], 0.0, positioning="extpos")
            for d in mission.drones
        }
    ).start()
    plug = crazyradio.plug(world, dongles=1, radio=mission.radio.dongle_type)
    received: dict[tuple[str, int, int], list[float]] = defaultdict(list)
    lock = threading.Lock()
    for name, address in addresses.items():

        def observer(
            port: int, channel: int, payload: bytes, stamp: float, name: str = name, ident: int = address & 0xFF
        ) -> None:
            if (port, channel) == (6, 2) and all(i != ident for i, _ in decode(payload)):
                return  # another group's packet: not this drone's position
            with lock:
                received[(name, port, channel)].append(stamp)

        world.add_packet_observer(address, observer)
    backend = CflibBackend(
        cache_dir=cache_dir,
        packed_extpos=packed,
        ext_pos_std_dev=PACKED_EXT_POS_STD_DEV_M if packed else None,
        rate_limits=link_rate_limits(mission),
        connect_timeout_s=60.0,
    )  # many links, one dongle
    uris = {d.name: d.uri for d in mission.drones}
    try:
        errors = backend.connect(uris)
        if errors:
            raise RuntimeError(f"connect: {errors}")
        for name in uris:
            backend.arm_watchdog(name)
        schedule = ExtposSchedule.for_uris(mission.radio.extpos_rate_hz, uris, packed=packed)
        frame_s, tick_every = 1.0 / mission.mocap.rate_hz, round(mission.mocap.rate_hz / mission.flight.rate_hz)
        ticks: list[float] = []
        frames: list[tuple[float, list[str]]] = []
        dongle = plug.dongles[0]
        time.sleep(0.5)
        with dongle._lock:
            busy0 = dongle.counters.busy_s
        start = time.monotonic()
        k = 0
        while True:
            due = start + k * frame_s
            now = time.monotonic()
            if due > now:
                time.sleep(due - now)
            now = time.monotonic()
            if now - start >= seconds:
                break
            if k % tick_every == 0:
                ticks.append(now)
                for d in mission.drones:
                    backend.send_position_setpoint(d.name, d.start[0], d.start[1], 0.0, 0.0)
            sent = [d.name for d in mission.drones if schedule.due(d.name, now)]
            frames.append((now, sent))
            for d in mission.drones:
                if d.name in sent:
                    backend.send_extpos(d.name, (d.start[0], d.start[1], 0.0))
            k += 1
        elapsed = time.monotonic() - start
        with dongle._lock:  # the dongle's time over the same window (it goes on polling while the last packets land)
            busy1 = dongle.counters.busy_s
        time.sleep(0.3)
    finally:
        backend.close()
        crazyradio.unplug()
        world.close()
    setpoint_latency = _latencies(ticks, {n: received[(n, 7, 0)] for n in uris}, list(uris))
    extpos = (6, 2) if packed else (6, 0)
    extpos_latency: list[float] = []
    for name in uris:
        stamps = sorted(received[(name, *extpos)])
        for t, sent in frames:
            if name in sent:
                later = next((s for s in stamps if s >= t), None)
                if later is not None and later - t < 1.0:
                    extpos_latency.append(later - t)
    made = sum(len(s) for _, s in frames) * (BROADCAST_COPIES if packed else 1)  # each copy heard when packed
    delivered = sum(len([s for s in received[(n, *extpos)] if start <= s <= start + elapsed]) for n in uris)
    return {
        "setpoint_p50_s": quantile(setpoint_latency, 0.5),
        "setpoint_p99_s": quantile(setpoint_latency, 0.99),
        "setpoints_missing": len(ticks) * len(uris) - len(setpoint_latency),
        "extpos_p99_s": quantile(extpos_latency, 0.99),
        "extpos_delivered": delivered / made if made else math.nan,
        "busy": (busy1 - busy0) / elapsed,
    }


def _latencies(ticks: list[float], stamps: dict[str, list[float]], names: list[str]) -> list[float]:
    """Each tick's setpoint to each drone: from the tick to the first receipt after it (before the next tick)."""
    out = []
    for name in names:
        got = sorted(stamps[name])
        for k, t in enumerate(ticks):
            following = ticks[k + 1] if k + 1 < len(ticks) else math.inf
            first = next((s for s in got if t <= s < following + 1.0), None)
            if first is not None:
                out.append(first - t)
    return out


def row(load: DongleLoad, measured: dict[str, float] | None) -> list[str]:
    cells = [
        f"{len(load.drones)}",
        "packed" if load.broadcasts else "per drone",
        f"{load.needed:.0f}",
        f"{load.budget:.0f}",
        f"{load.use:.0%}",
        str(sorted(set(load.rate_limits.values()))[0]),
        f"{load.setpoint_p50_s * 1e3:.0f} / {load.setpoint_p99_s * 1e3:.0f}",
        f"{load.extpos_p99_s * 1e3:.0f}",
        f"{load.extpos_delivered:.0%}",
        "no" if load.over else "yes",
    ]
    if measured is not None:
        cells += [
            f"{measured['busy']:.0%}",
            f"{measured['setpoint_p50_s'] * 1e3:.0f} / {measured['setpoint_p99_s'] * 1e3:.0f}",
            f"{measured['setpoints_missing']:.0f}",
            f"{measured['extpos_p99_s'] * 1e3:.0f}",
            f"{measured['extpos_delivered']:.0%}",
        ]
    return cells


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--radio", default="crazyradio_pa", choices=("crazyradio_pa", "crazyradio_2"))
    parser.add_argument("--rate-hz", type=float, default=10.0, help="setpoints (flight.rate_hz)")
    parser.add_argument("--mocap-hz", type=float, default=50.0)
    parser.add_argument("--extpos-hz", type=float, default=50.0, help="radio.extpos_rate_hz")
    parser.add_argument("--drones", default="4,6,8,10,12,14")
    parser.add_argument("--measure", action="store_true", help="also through real cflib on an emulated dongle")
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--markdown", action="store_true")
    args = parser.parse_args()
    header = [
        "drones",
        "extpos",
        "needed/s",
        "carries/s",
        "use",
        "rate_limit",
        "setpoint ms p50 / p99 (model)",
        "extpos ms p99",
        "extpos out",
        "within budget",
    ]
    if args.measure:
        header += [
            "dongle busy (measured)",
            "setpoint ms p50 / p99 (measured)",
            "setpoints missing",
            "extpos ms p99 (measured)",
            "extpos out (measured)",
        ]
    rows = []
    with tempfile.TemporaryDirectory(prefix="rpf-fly-toc-") as cache:
        for mode in ("extpos", "packed"):
            for n in (int(x) for x in args.drones.split(",")):
                mission = mission_of(n, args.radio, mode, args.rate_hz, args.mocap_hz, args.extpos_hz)
                (load,) = radio_loads(mission)
                measured = measure(mission, args.seconds, cache) if args.measure else None
                rows.append(row(load, measured))
                if not args.markdown:
                    print("  ".join(rows[-1]), flush=True)
    if args.markdown:
        print("| " + " | ".join(header) + " |")
        print("|" + "---|" * len(header))
        for cells in rows:
            print("| " + " | ".join(cells) + " |")
    else:
        print("  ".join(header))


if __name__ == "__main__":
    main()
