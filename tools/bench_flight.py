"""Flight-loop benchmark: a dry run of 10 drones planning at 100 Hz through the whole stack.

    python tools/bench_flight.py [--drones 10] [--rate 100] [--planner apf|rpf] [--runs 3] [--json]

Measured by the flight loop itself (rpf_fly.flight.loop.LoopStats) while the drones fly a circle swap:
- latency: a mocap frame's receipt by the NatNet client (its receive timestamp) to each setpoint handed to the
  radio driver (``CflibBackend.send_position_setpoint`` returned), p50 and p99 over all drones and the ticks fired
  by a frame (every tick but the ``frameless`` ones, which fire at a window's end when no frame came);
- tick interval and jitter: |interval - median interval|, p99; overruns (ticks later than one period); the longest
  tick interval and latency of all runs (a stall, e.g. a full garbage collection, shows there, not in a p99);
- planner time per drone;
- the flight log's CPU time (the loop thread inside the recorder's calls plus the writer thread) over the whole
  flight, take-off and landing included, in percent of a core (tools/bench_log.py measures it at a steady rate);
  the dry run's truth feed (``/truth``, rpf_fly/flight/truth.py) separately: its thread's CPU time, and the
  writer's share of its messages is in the log's figure (``--no-truth`` flies without it, for comparison).
Goals: latency p50 <= 0.5 ms, p99 <= 2 ms. The machine is shared: read medians over runs.

    python tools/bench_flight.py --floor [--planner apf|rpf]

measures, in the same run, the floor beside the stack, with the dry run's radio air time on (1 ms a transaction,
a Crazyradio's) and off: the floor receives the same NatNet frames with the same client and sends one position
setpoint per drone and frame at the planning rate through cflib (``Crazyflie.commander``), with nothing of ours in
between (no loop, planner, supervisor, commander or log). Goal (docs/performance.md): the stack's p50 and p99 at
most 1.5x the floor's.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import tempfile
import time
from pathlib import Path

from rpf_fly.flight.dry_run import DryRun
from rpf_fly.flight.recording import McapRecorder
from rpf_fly.flight.session import run_flight
from rpf_fly.mission import parse_mission
from rpf_fly.planning.factory import make_planner
from rpf_fly.sim.scenario import obstacle_set

ROOT = Path(__file__).resolve().parents[1]


PER_DRONE_PACKETS_S = 10.0 + 30.0  # cflib's ping and the extpos at 30 Hz, beside the setpoints (radio/budget.py)
DONGLE_BUDGET_S = 1000.0


def dongles_for(drones: int, rate: float) -> int:
    """As many dongles as keep each within a Crazyradio's ~1000 transactions a second (rpf_fly/radio/budget.py):
    10 drones at 100 Hz need 1400 a second, two dongles. A faithful radio blocks cflib's send when a dongle is
    over (docs/radio.md), so an over-budget bench would measure the radio's queue, not the stack."""
    return max(1, math.ceil(drones * (rate + PER_DRONE_PACKETS_S) / DONGLE_BUDGET_S))


def mission_text(drones: int, rate: float, planner: str) -> str:
    """A circle swap of radius 3 m (as `formation: circle_swap`), its drones spread over `dongles_for` dongles."""
    policy = f", policy: {ROOT / 'policies' / 'rpf.onnx'}" if planner == "rpf" else ""
    dongles = dongles_for(drones, rate)
    rows = []
    for i in range(drones):
        t = 2.0 * math.pi * i / drones
        dx, dy = 3.0 * math.cos(t), 3.0 * math.sin(t)
        rows.append(
            f"  - {{name: cf{i + 1}, uri: radio://{i % dongles}/80/2M/E7E7E7E7{i + 1:02X}, "
            f"start: [{dx:.4f}, {dy:.4f}], goal: [{-dx:.4f}, {-dy:.4f}]}}"
        )
    return (
        f"""
name: bench-{drones}
arena: {{x: [-4.5, 4.5], y: [-4.5, 4.5], z: [0.0, 2.0]}}
flight: {{height: 1.0, speed: 0.5, rate_hz: {rate}, goal_tolerance: 0.1, takeoff_s: 1.0, land_s: 1.0, timeout_s: 60}}
planner: {{kind: {planner}{policy}}}
mocap: {{kind: sim, rate_hz: 100}}
radio: {{extpos_rate_hz: 30}}
drones:
"""
        + "\n".join(rows)
        + "\n"
    )


def floor_once(drones: int, rate: float, air_time_s: float, seconds: float = 8.0) -> dict:
    """The floor: NatNet frames in, one cflib position setpoint per drone out at the planning rate, nothing else."""
    import contextlib

    from cflib.crazyflie import Crazyflie
    from cflib.crazyflie.syncCrazyflie import SyncCrazyflie

    mission = parse_mission(mission_text(drones, rate, "apf"))
    latencies: list[float] = []
    with DryRun(mission, air_time_s=air_time_s, truth=False) as rig, contextlib.ExitStack() as stack:
        cfs = []
        for d in mission.drones:
            scf = stack.enter_context(SyncCrazyflie(rig.uris[d.name], cf=Crazyflie(rw_cache=str(rig.cache_dir))))
            cfs.append((scf.cf, d.start))
        period, due = 1.0 / rate, 0.0
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            frame = rig.mocap.receive(0.05)
            if frame is None or frame.receive_time_s < due:
                continue
            due = frame.receive_time_s + 0.5 * period  # the planning rate, fired by a frame as the loop does
            for cf, start in cfs:
                cf.commander.send_position_setpoint(start[0], start[1], 0.0, 0.0)
                latencies.append(time.monotonic() - frame.receive_time_s)
    ordered = sorted(latencies)
    pick = lambda q: ordered[min(len(ordered) - 1, int(q * len(ordered)))]  # noqa: E731
    return {"latency_p50_s": pick(0.5), "latency_p99_s": pick(0.99), "sends": len(latencies)}


def floor_table(drones: int, rate: float, planner: str) -> None:
    """Floor and stack side by side, air time on and off (interleaved, one run each)."""
    rows = []
    for air in (0.001, 0.0):
        floor = floor_once(drones, rate, air)
        stack = run_once(drones, rate, planner, True, air_time_s=air)
        rows.append((air, floor, stack))
    print(f"{drones} drones, {rate:g} Hz, planner {planner}: mocap frame -> setpoint handed to cflib")
    print("| radio air time | floor p50 | floor p99 | stack p50 | stack p99 | p50 ratio | p99 ratio |")
    print("|---|---|---|---|---|---|---|")
    for air, floor, stack in rows:
        f50, f99 = floor["latency_p50_s"] * 1e3, floor["latency_p99_s"] * 1e3
        s50, s99 = stack["latency_p50_s"] * 1e3, stack["latency_p99_s"] * 1e3
        print(
            f"| {air * 1e3:g} ms | {f50:.3f} ms | {f99:.3f} ms | {s50:.3f} ms | {s99:.3f} ms | {s50 / f50:.2f}x | "
            f"{s99 / f99:.2f}x |"
        )


def run_once(
    drones: int,
    rate: float,
    planner: str,
    log: bool,
    in_process: bool = False,
    truth: bool = True,
    air_time_s: float | None = None,
) -> dict:
    mission = parse_mission(mission_text(drones, rate, planner))
    obstacles = obstacle_set(mission.obstacles)
    loops = []
    recorder_cpu = [0.0]

    def time_the_recorder(loop) -> None:  # type: ignore[no-untyped-def]
        """CPU time of the loop thread inside the recorder's high-rate calls (the flight code does not time them)."""
        loops.append(loop)
        for name in ("poses", "setpoints", "planner_steps", "status"):
            call = getattr(loop.recorder, name)

            def timed(*args, _call=call):  # type: ignore[no-untyped-def]
                c0 = time.thread_time()
                _call(*args)
                recorder_cpu[0] += time.thread_time() - c0

            setattr(loop.recorder, name, timed)

    with (
        tempfile.TemporaryDirectory() as tmp,
        DryRun(mission, process=not in_process, truth=truth, air_time_s=air_time_s) as rig,
    ):
        wall0 = time.perf_counter()
        report = run_flight(
            mission,
            lambda d: make_planner(mission.planner, obstacles),
            Path(tmp) / "bench.mcap" if log else None,
            rig=rig,
            on_loop=time_the_recorder,
        )
        wall = time.perf_counter() - wall0
    summary = report.stats.summary()
    summary["success"] = report.success
    recorder = loops[0].recorder
    if isinstance(recorder, McapRecorder):  # the log's CPU time: the loop thread in the recorder + the writer thread
        summary["log_messages_per_s"] = recorder.log.written / wall
        summary["log_cpu_pct"] = 100 * (recorder_cpu[0] + recorder.log.writer_cpu_s) / wall
        summary["log_recorder_pct"] = 100 * recorder_cpu[0] / wall
        feed = recorder.truth_feed
        summary["truth_cpu_pct"] = 100 * feed.cpu_s / wall if feed is not None else None
        summary["truth_messages_per_s"] = feed.samples * drones / wall if feed is not None else None
    return summary


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--drones", type=int, default=10)
    parser.add_argument("--rate", type=float, default=100.0)
    parser.add_argument("--planner", default="apf", choices=("apf", "rpf"))
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--no-log", action="store_true", help="fly without the MCAP log")
    parser.add_argument(
        "--in-process",
        action="store_true",
        help="simulated drones and NatNet emulator on threads of this process (default: their own)",
    )
    parser.add_argument("--no-truth", action="store_true", help="fly without the dry run's /truth in the log")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--floor", action="store_true", help="the floor beside the stack, radio air time on and off")
    args = parser.parse_args()
    if args.floor:
        floor_table(args.drones, args.rate, args.planner)
        return 0
    runs = [
        run_once(args.drones, args.rate, args.planner, not args.no_log, args.in_process, not args.no_truth)
        for _ in range(args.runs)
    ]

    def med(key: str) -> float:
        values = [r[key] for r in runs if r[key] is not None]
        return statistics.median(values) if values else float("nan")

    result = {
        "drones": args.drones,
        "rate_hz": args.rate,
        "planner": args.planner,
        "runs": runs,
        "latency_p50_ms": med("latency_p50_s") * 1e3,
        "latency_p99_ms": med("latency_p99_s") * 1e3,
        "tick_interval_p50_ms": med("tick_interval_p50_s") * 1e3,
        "tick_jitter_p99_ms": med("tick_jitter_p99_s") * 1e3,
        "tick_interval_max_ms": max(r["tick_interval_max_s"] or 0.0 for r in runs) * 1e3,
        "latency_max_ms": max(r["latency_max_s"] or 0.0 for r in runs) * 1e3,
        "gc_collections_median": med("gc_collections"),
        "planner_p50_us": med("planner_p50_s") * 1e6,
        "overruns_median": med("overruns"),
        "frameless_ticks_median": med("frameless_ticks"),
        "ticks_median": med("ticks"),
    }
    if not args.no_log:
        result.update(
            log_cpu_pct=med("log_cpu_pct"),
            log_recorder_pct=med("log_recorder_pct"),
            log_messages_per_s=med("log_messages_per_s"),
        )
        if not args.no_truth:
            result.update(truth_cpu_pct=med("truth_cpu_pct"), truth_messages_per_s=med("truth_messages_per_s"))
    if args.json:
        print(json.dumps(result))
        return 0
    print(f"{args.drones} drones, planning at {args.rate:g} Hz, planner {args.planner}, {args.runs} runs (medians):")
    print(
        f"  mocap frame -> setpoint handed to the radio: p50 {result['latency_p50_ms']:.3f} ms "
        f"(goal <= 0.5), p99 {result['latency_p99_ms']:.3f} ms (goal <= 2)"
    )
    print(
        f"  tick interval p50 {result['tick_interval_p50_ms']:.2f} ms, "
        f"jitter p99 {result['tick_jitter_p99_ms']:.2f} ms, "
        f"overruns {result['overruns_median']:.0f} per run"
    )
    print(
        f"  worst of all runs: tick interval {result['tick_interval_max_ms']:.1f} ms, latency "
        f"{result['latency_max_ms']:.2f} ms; garbage collections in the loop's gaps: "
        f"{result['gc_collections_median']:.0f} per run (rpf_fly/flight/gc_pacing.py)"
    )
    print(
        f"  ticks without a fresh frame: {result['frameless_ticks_median']:.0f} "
        f"of {result['ticks_median']:.0f} per run "
        f"(ticks are locked to the frames: rpf_fly/flight/ticks.py)"
    )
    if not args.no_log:
        print(
            f"  flight log: {result['log_cpu_pct']:.2f} % of a core over the whole flight (loop thread in the "
            f"recorder {result['log_recorder_pct']:.2f} %, the rest the writer thread), "
            f"{result['log_messages_per_s']:.0f} messages/s"
        )
        if not args.no_truth:
            print(
                f"  truth feed thread: {result['truth_cpu_pct']:.2f} % of a core, "
                f"{result['truth_messages_per_s']:.0f} /truth messages/s (their writing is in the log's figure)"
            )
    print(
        f"  planner p50 {result['planner_p50_us']:.1f} us per drone; every run succeeded: "
        f"{all(r['success'] for r in runs)}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
