"""Cost of the simulated Crazyflie's dynamics (rpf_fly/emulator/cf_drone.py, cf_swarm.py): the CPU time one world
step of 10 ms takes, per drone, and how many drones one core keeps in real time.

Why: a world steps every drone every 10 ms on one thread; the firmware's cascade runs 1 kHz inside each step (10
body ticks, 5 attitude and rate loops, 1 position loop, the high-level commander). Two ways to run it are timed:
`CfDrone` objects stepped one after the other (pure Python), and one `CfSwarm` stepping every drone on numpy
arrays. Each drone hovers settled, then flies under the load of a dry run: "stream" drones get a position setpoint
every 10 ms from their ground station (a point on a circle of 0.5 m at 0.5 m/s); "hl" drones fly high-level go_to
commands (a new one every 2 s), their commanders evaluating the plan every 10 ms. The setpoint sending and the
commands are inside the timed step. CPU time (`time.process_time`, so another process's load on the machine does
not count) of the best of the repeats.

Usage:
    python tools/bench_cf_model.py [--drones 1,10,40,100] [--seconds 2] [--repeats 3] [--mode stream|hl]
"""

from __future__ import annotations

import argparse
import math
import time

from rpf_fly.emulator.cf_drone import CfDrone
from rpf_fly.emulator.cf_swarm import CfSwarm

STEP_S = 0.01
BUDGET_US = STEP_S * 1e6


def _targets(n: int, t: float) -> list[tuple[float, float, float]]:
    return [(0.6 * i + 0.5 * math.cos(t), 0.5 * math.sin(t), 1.0) for i in range(n)]


def _fly(drones: list, advance, seconds: float, mode: str) -> float:  # noqa: ANN001 - drones: CfDrone or views
    """CPU seconds per 10 ms world step over `seconds` of flight."""
    steps = round(seconds / STEP_S)
    start = time.process_time()
    for k in range(steps):
        t = k * STEP_S
        if mode == "stream":
            for d, (x, y, z) in zip(drones, _targets(len(drones), t)):
                d.send_position(x, y, z)
        elif k % 200 == 0:
            for i, d in enumerate(drones):
                d.go_to(0.6 * i + (0.3 if (k // 200) % 2 == 0 else 0.0), 0.2, 1.0, 1.5)
        advance()
    return (time.process_time() - start) / steps


def bench_single(n: int, seconds: float, repeats: int, mode: str) -> float:
    best = math.inf
    for _ in range(repeats):
        drones = [CfDrone.hovering((0.6 * i, 0.0, 1.0), settle_s=0.5) for i in range(n)]
        if mode == "hl":
            for d in drones:
                d.notify_setpoint_stop()

        def advance() -> None:
            for d in drones:
                d.step(STEP_S)

        best = min(best, _fly(drones, advance, seconds, mode))
    return best


def bench_swarm(n: int, seconds: float, repeats: int, mode: str) -> float:
    best = math.inf
    for _ in range(repeats):
        swarm = CfSwarm.hovering([(0.6 * i, 0.0, 1.0) for i in range(n)], settle_s=0.5)
        drones = [swarm.drone(i) for i in range(n)]
        if mode == "hl":
            for d in drones:
                d.notify_setpoint_stop()
        best = min(best, _fly(drones, lambda: swarm.step(STEP_S), seconds, mode))
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drones", default="1,10,40,100")
    parser.add_argument("--seconds", type=float, default=2.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--mode", choices=("stream", "hl"), default="stream")
    args = parser.parse_args()
    print(f"mode {args.mode}: CPU time per 10 ms world step (best of {args.repeats} x {args.seconds:g} s)")
    print("| drones | per-drone CfDrone: us/step | us per drone | swarm CfSwarm: us/step | us per drone "
          "| drones one core keeps in real time (CfDrone / CfSwarm) |")
    print("|---|---|---|---|---|---|")
    for n in (int(v) for v in args.drones.split(",")):
        single = bench_single(n, args.seconds, args.repeats, args.mode) * 1e6
        swarm = bench_swarm(n, args.seconds, args.repeats, args.mode) * 1e6
        print(f"| {n} | {single:.0f} | {single / n:.0f} | {swarm:.0f} | {swarm / n:.1f} "
              f"| {BUDGET_US / (single / n):.0f} / {'yes' if swarm <= BUDGET_US else 'no'} at {n} |", flush=True)


if __name__ == "__main__":
    main()
