"""Step cost of the fake Crazyflie: the Python time one world step (every drone's `FakeFirmware.step`) takes.

Why: the fake world steps every drone every 10 ms on one thread (in the dry run, in a process of its own), so the
vehicle model must stay cheap. This times that step on synthetic time, without radio or threads: N drones
(default 10) hover under streamed position setpoints at 50 Hz, with extpos at 50 Hz (the mocap) for the
``positioning="extpos"`` drones, and one world step (all drones advanced by 10 ms) is timed. Packets are handed to
the firmwares outside the timed section. Prints the median and p99 over the steps of each repeat, and the best
repeat's median.

Usage:
    python tools/bench_vehicle.py [--drones 10] [--steps 3000] [--repeats 5] [--positioning extpos|onboard]
"""

from __future__ import annotations

import argparse
import statistics
import struct
import time

from rpf_fly.emulator.fake_firmware import FakeFirmware
from rpf_fly.emulator.fake_vehicle import VehicleConfig

DT_S = 0.01


def run(drones: int, steps: int, positioning: str) -> list[float]:
    """Seconds each world step took, for `steps` steps after a 2 s take-off."""
    firmwares = [
        FakeFirmware(VehicleConfig(position=(0.5 * i, 0.0, 0.0), positioning=positioning)) for i in range(drones)
    ]
    t = 0.0
    for fw in firmwares:
        fw.handle(6, 0, struct.pack("<fff", *fw.vehicle.pos), t)
    for _ in range(10):
        t = round(t + DT_S, 6)
        for fw in firmwares:
            fw.step(t)
    for fw in firmwares:
        fw.handle(8, 0, struct.pack("<BBff?f", 7, 0, 0.5, 0.0, True, 1.0), t)
    durations = []
    for tick in range(200 + steps):
        t = round(t + DT_S, 6)
        if tick % 2 == 0:
            for i, fw in enumerate(firmwares):
                x, y, z = fw.vehicle.pos
                fw.handle(6, 0, struct.pack("<fff", x, y, z), t)
                if tick >= 200:
                    fw.handle(7, 0, struct.pack("<Bffff", 7, 0.5 * i + 0.1, 0.1, 0.5, 0.0), t)
        start = time.perf_counter()
        for fw in firmwares:
            fw.step(t)
        if tick >= 200:
            durations.append(time.perf_counter() - start)
    return durations


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drones", type=int, default=10)
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--positioning", choices=("extpos", "onboard"), default="extpos")
    args = parser.parse_args()
    medians = []
    for _ in range(args.repeats):
        durations = sorted(run(args.drones, args.steps, args.positioning))
        median = statistics.median(durations)
        medians.append(median)
        p99 = durations[int(0.99 * (len(durations) - 1))]
        print(
            f"{args.drones} drones ({args.positioning}): world step median {median * 1e6:.0f} us, "
            f"p99 {p99 * 1e6:.0f} us"
        )
    print(
        f"best median {min(medians) * 1e6:.0f} us per world step ({min(medians) * 1e6 / args.drones:.1f} us per drone)"
    )


if __name__ == "__main__":
    main()
