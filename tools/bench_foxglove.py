"""What the live view costs the flight: dry runs with and without ``--foxglove``, interleaved, in one run.

    python tools/bench_foxglove.py [--drones 10] [--rate 100] [--planner apf|rpf] [--pairs 3] [--air-time-ms 0] [--json]

Each pair flies the mission of tools/bench_flight.py twice, once without the live view and once with it (the order
alternates from pair to pair, so a machine that gets busier does not favour one side). With it, a WebSocket client in
its own process (as the Foxglove app would be) connects before the drones do, subscribes to every channel the server
advertises and reads every message until the flight ends. Measured by the flight loop itself (``LoopStats``, as
bench_flight measures it): latency from a mocap frame's receipt to each setpoint handed to the radio driver, p50 and
p99; tick jitter p99; overruns. Also: the writer thread's CPU time (it now hands every message to the server, so the
live view's own cost on our side shows there), the flight process's CPU time (with the server's own threads), the
client's, and the messages the client received against those served.

The dry run's radio air time is off by default (``--air-time-ms 0``): at a Crazyradio's 1 ms a transaction, 10 drones
at 100 Hz ask one dongle for more than it carries, extpos reaches some drones late and their supervisors cut their
motors mid-flight (docs/radio.md, "Over budget in the dry run"), so the two sides of a pair would not fly the same
flight.

Not a test: the machine is shared, read the medians of the pairs.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_flight import mission_text  # noqa: E402

from rpf_fly.flight.dry_run import DryRun  # noqa: E402
from rpf_fly.flight.session import run_flight  # noqa: E402
from rpf_fly.mission import parse_mission  # noqa: E402
from rpf_fly.planning.factory import make_planner  # noqa: E402
from rpf_fly.sim.scenario import obstacle_set  # noqa: E402

CLIENT = r"""
import asyncio, json, sys, time
import websockets

async def main(port):
    deadline = time.monotonic() + 30
    while True:
        try:
            ws = await websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"], max_size=None)
            break
        except OSError:
            if time.monotonic() > deadline:
                raise
            await asyncio.sleep(0.05)
    print("connected", flush=True)
    messages = size = 0
    channels = set()
    try:
        async for frame in ws:
            if isinstance(frame, str):
                advert = json.loads(frame)
                if advert.get("op") == "advertise":
                    fresh = [c["id"] for c in advert["channels"] if c["id"] not in channels]
                    channels.update(fresh)
                    await ws.send(json.dumps({"op": "subscribe",
                                              "subscriptions": [{"id": c, "channelId": c} for c in fresh]}))
            else:
                messages += 1
                size += len(frame)
    except websockets.ConnectionClosed:
        pass
    print(json.dumps({"messages": messages, "bytes": size, "channels": len(channels),
                      "cpu_s": time.process_time()}), flush=True)

asyncio.run(main(int(sys.argv[1])))
"""


def run_once(drones: int, rate: float, planner: str, live: bool, air_time_s: float = 0.0) -> dict:
    """One dry run (the simulated drones in their own process, truth and log on, as ``rpf-fly fly --dry-run``)."""
    mission = parse_mission(mission_text(drones, rate, planner))
    obstacles = obstacle_set(mission.obstacles)
    loops: list = []
    view = client = None
    if live:
        from rpf_fly.log.live import LiveView

        view = LiveView(0)
        client = subprocess.Popen([sys.executable, "-c", CLIENT, str(view.port)], stdout=subprocess.PIPE, text=True)
        assert client.stdout is not None and client.stdout.readline().strip() == "connected"
    try:
        with tempfile.TemporaryDirectory() as tmp, DryRun(mission, air_time_s=air_time_s) as rig:
            wall0, cpu0 = time.perf_counter(), time.process_time()
            report = run_flight(
                mission,
                lambda d: make_planner(mission.planner, obstacles),
                Path(tmp) / "bench.mcap",
                rig=rig,
                on_loop=loops.append,
                live=view,
            )
            wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    finally:
        if view is not None:
            view.close()
    summary = report.stats.summary()
    log = loops[0].recorder.log
    result = {
        "live": live,
        "success": report.success,
        "latency_p50_ms": summary["latency_p50_s"] * 1e3,
        "latency_p99_ms": summary["latency_p99_s"] * 1e3,
        "tick_jitter_p99_ms": summary["tick_jitter_p99_s"] * 1e3,
        "overruns": summary["overruns"],
        "ticks": summary["ticks"],
        "log_dropped": log.dropped,
        "writer_cpu_pct": 100 * log.writer_cpu_s / wall,
        "log_messages": log.written,
        "process_cpu_pct": 100 * cpu / wall,
        "wall_s": wall,
    }
    if view is not None and client is not None:
        out, _ = client.communicate(timeout=30)
        received = json.loads(out.strip().splitlines()[-1])
        result.update(
            live_published=view.published,
            live_received=received["messages"],
            client_cpu_pct=100 * received["cpu_s"] / wall,
            live_bytes=received["bytes"],
            live_channels=received["channels"],
            live_slow_client_reports=view.slow_client_reports,
            live_failed=view.failed,
        )
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--drones", type=int, default=10)
    parser.add_argument("--rate", type=float, default=100.0)
    parser.add_argument("--planner", default="apf", choices=("apf", "rpf"))
    parser.add_argument("--pairs", type=int, default=3)
    parser.add_argument(
        "--air-time-ms",
        type=float,
        default=0.0,
        help="the dry run's radio air time a transaction (default 0: every drone flies the whole way)",
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    runs = []
    for pair in range(args.pairs):
        for live in (False, True) if pair % 2 == 0 else (True, False):
            runs.append(run_once(args.drones, args.rate, args.planner, live, args.air_time_ms / 1e3))
            if not args.json:
                r = runs[-1]
                print(
                    f"  pair {pair + 1}, {'with' if live else 'without'} --foxglove: p50 {r['latency_p50_ms']:.3f} "
                    f"ms, p99 {r['latency_p99_ms']:.3f} ms",
                    file=sys.stderr,
                )

    def med(live: bool, key: str) -> float:
        return statistics.median(r[key] for r in runs if r["live"] == live)

    if args.json:
        print(json.dumps({"drones": args.drones, "rate_hz": args.rate, "planner": args.planner, "runs": runs}))
        return 0
    print(
        f"{args.drones} drones, planning at {args.rate:g} Hz, planner {args.planner}, radio air time "
        f"{args.air_time_ms:g} ms, {args.pairs} interleaved pairs; latency: mocap frame -> setpoint handed to the radio"
    )
    print(
        "| pair | --foxglove | p50 | p99 | tick jitter p99 | overruns | all reached | writer thread | flight process "
        "| client process | client received / served |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for k, r in enumerate(runs):
        client = f"{r['client_cpu_pct']:.1f} % | {r['live_received']} / {r['live_published']}" if r["live"] else "- | -"
        print(
            f"| {k // 2 + 1} | {'yes' if r['live'] else 'no'} | {r['latency_p50_ms']:.3f} ms | "
            f"{r['latency_p99_ms']:.3f} ms | {r['tick_jitter_p99_ms']:.2f} ms | {r['overruns']} | "
            f"{'yes' if r['success'] else 'no'} | {r['writer_cpu_pct']:.2f} % | {r['process_cpu_pct']:.1f} % | "
            f"{client} |"
        )
    for live in (False, True):
        client = f"{med(live, 'client_cpu_pct'):.1f} % | " if live else "- | "
        print(
            f"| median | {'yes' if live else 'no'} | {med(live, 'latency_p50_ms'):.3f} ms | "
            f"{med(live, 'latency_p99_ms'):.3f} ms | {med(live, 'tick_jitter_p99_ms'):.2f} ms | "
            f"{med(live, 'overruns'):.0f} | | {med(live, 'writer_cpu_pct'):.2f} % | "
            f"{med(live, 'process_cpu_pct'):.1f} % | {client} |"
        )
    diffs = {
        key: [
            next(r for r in pair if r["live"])[key] - next(r for r in pair if not r["live"])[key]
            for pair in zip(runs[::2], runs[1::2])
        ]
        for key in ("latency_p50_ms", "latency_p99_ms")
    }
    for key, label in (("latency_p50_ms", "p50"), ("latency_p99_ms", "p99")):
        print(
            f"{label} with minus without, per pair: {', '.join(f'{d:+.3f}' for d in diffs[key])} ms; "
            f"median {statistics.median(diffs[key]):+.3f} ms"
        )
    print(
        f"every run succeeded: {all(r['success'] for r in runs)}; log drops: {sum(r['log_dropped'] for r in runs)}; "
        f"slow-client reports: {sum(r.get('live_slow_client_reports', 0) for r in runs)}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
