"""Benchmark: CPU cost of the flight log at flight rates, in percent of one core.

Simulates the logging of a flight in real time: every tick (``--rate`` Hz) each of ``--drones`` drones logs its
mocap pose, its setpoint and its planner step (by default through the batch calls the flight's recorder makes, one
per topic kind and tick; ``--per-message``: one call per message), ``/tf`` gets one message at 20 Hz (as the flight
writes it), and every ``--status-every`` ticks each drone logs its status. Measured:

- enqueue: CPU time (``time.thread_time``) of the calling thread inside the ``FlightLog`` calls;
- writer: CPU time of the writer thread (building, ``json.dumps``, chunking, zstd, flushing, finishing);
- process: CPU time of the whole process (``time.process_time``; includes the pacing loop and the interpreter);

each divided by the wall time of the run. Goal: enqueue + writer <= 5 % of one core at 10 drones x 100 Hz.

    python tools/bench_log.py                      # 10 drones, 100 Hz, 10 s
    python tools/bench_log.py --drones 20 --seconds 5 --json
"""

from __future__ import annotations

import argparse
import json
import math
import os
import tempfile
import time
from pathlib import Path

from rpf_fly.log.writer import FlightLog


def run(drones: int, rate: float, seconds: float, status_every: int, path: Path, batched: bool = True) -> dict:
    names = [f"cf{i + 1}" for i in range(drones)]
    period_ns = int(1e9 / rate)
    tf_every = max(1, round(rate / 20))
    ticks = int(seconds * rate)
    enqueue_cpu = 0.0
    mission = {"name": "bench", "yaml": "", "rpf_fly_version": "", "planner": "apf", "policy_sha256": "", "seed": "0"}
    cpu0 = time.process_time()
    wall0 = time.perf_counter()
    start_ns = time.time_ns()
    log = FlightLog(path, mission, {"json": "{}"})
    next_tick = time.perf_counter()
    for k in range(ticks):
        t = start_ns + k * period_ns
        # what the flight loop has at hand each tick (not counted: the loop computes it anyway)
        poses = []
        for i, _ in enumerate(names):
            a = 0.01 * k + i
            poses.append(((math.cos(a), math.sin(a), 0.6), (0.0, 0.0, math.sin(a / 2), math.cos(a / 2))))
        c0 = time.thread_time()
        if batched:  # as the flight's recorder calls it: one call per topic kind and tick
            frame = dict(zip(names, poses))
            log.poses(t, frame)
            log.setpoints([(name, t, (p[0] + 0.05, p[1], 0.6), 0.3) for name, (p, _) in frame.items()])
            log.planner_steps(
                t,
                {
                    name: dict(
                        tick=k,
                        position=p,
                        goal=(1.0, 1.0),
                        mode="apf",
                        eta=0.05,
                        lam=2.0,
                        f_a=0.7 + 0.7j,
                        f_r=-0.1j,
                        f_in=0.05 + 0j,
                        direction=0.6 + 0.8j,
                        heading=0.93,
                        neighbours=2,
                        obstacle_distance=0.8,
                        goal_distance=1.2,
                    )
                    for name, (p, _) in frame.items()
                },
            )
            if k % tf_every == 0:  # the flight writes /tf at 20 Hz (rpf_fly/flight/recording.py)
                log.tf(t, frame)
        else:  # one call per message
            for i, name in enumerate(names):
                position, quaternion = poses[i]
                log.pose(name, t, position, quaternion)
                log.setpoint(name, t, (position[0] + 0.05, position[1], 0.6), 0.3)
                log.planner_step(
                    name,
                    t,
                    tick=k,
                    position=position,
                    goal=(1.0, 1.0),
                    mode="apf",
                    eta=0.05,
                    lam=2.0,
                    f_a=0.7 + 0.7j,
                    f_r=-0.1j,
                    f_in=0.05 + 0j,
                    direction=0.6 + 0.8j,
                    heading=0.93,
                    neighbours=2,
                    obstacle_distance=0.8,
                    goal_distance=1.2,
                )
            if k % tf_every == 0:
                log.tf(t, {name: poses[i] for i, name in enumerate(names)})
        if k % status_every == 0:
            for name in names:
                log.status(name, t, state="planning", battery_v=3.9, link_quality=0.97, latency_ms=5.0)
        enqueue_cpu += time.thread_time() - c0
        next_tick += 1.0 / rate
        delay = next_tick - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
    run_wall = time.perf_counter() - wall0
    c0 = time.thread_time()
    log.close()
    enqueue_cpu += time.thread_time() - c0
    wall = time.perf_counter() - wall0
    cpu = time.process_time() - cpu0
    messages = log.written
    return {
        "drones": drones,
        "calls": "batched" if batched else "per message",
        "rate_hz": rate,
        "seconds": round(wall, 3),
        "messages": messages,
        "messages_per_s": round(messages / run_wall, 1),
        "dropped": log.dropped,
        "queue_peak": log.queue_peak,
        "file_bytes": path.stat().st_size,
        "enqueue_cpu_pct": round(100 * enqueue_cpu / wall, 2),
        "enqueue_us_per_msg": round(1e6 * enqueue_cpu / max(messages, 1), 2),
        "writer_cpu_pct": round(100 * log.writer_cpu_s / wall, 2),
        "writer_us_per_msg": round(1e6 * log.writer_cpu_s / max(messages, 1), 2),
        "logging_cpu_pct": round(100 * (enqueue_cpu + log.writer_cpu_s) / wall, 2),
        "process_cpu_pct": round(100 * cpu / wall, 2),
        "goal_pct": 5.0,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--drones", type=int, default=10)
    parser.add_argument("--rate", type=float, default=100.0, help="ticks per second")
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--status-every", type=int, default=10, help="status every N ticks (10: 10 Hz at 100 Hz)")
    parser.add_argument("--out", type=Path, default=None, help="keep the log here (default: a temporary file)")
    parser.add_argument(
        "--per-message",
        action="store_true",
        help="one FlightLog call per message (default: the batch calls the flight's recorder makes)",
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = args.out or Path(tmp) / "bench.mcap"
        result = run(args.drones, args.rate, args.seconds, args.status_every, path, not args.per_message)
    result["cpus"] = os.cpu_count()
    if args.json:
        print(json.dumps(result))
        return
    print(
        f"{result['drones']} drones x {result['rate_hz']:g} Hz for {result['seconds']:.1f} s, {result['calls']} calls: "
        f"{result['messages']} messages ({result['messages_per_s']:.0f}/s), {result['dropped']} dropped, "
        f"queue peak {result['queue_peak']}, file {result['file_bytes'] / 1e6:.2f} MB"
    )
    print(f"  enqueue  {result['enqueue_cpu_pct']:5.2f} % of a core  ({result['enqueue_us_per_msg']:.2f} us/message)")
    print(f"  writer   {result['writer_cpu_pct']:5.2f} % of a core  ({result['writer_us_per_msg']:.2f} us/message)")
    verdict = "ok" if result["logging_cpu_pct"] <= result["goal_pct"] else "OVER GOAL"
    print(
        f"  logging  {result['logging_cpu_pct']:5.2f} % of a core (goal <= {result['goal_pct']:g} %: {verdict}); "
        f"whole process {result['process_cpu_pct']:.2f} %"
    )


if __name__ == "__main__":
    main()
