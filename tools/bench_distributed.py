"""Distributed against single-process flight: latency and CPU, side by side in one run (docs/performance.md).

    python tools/bench_distributed.py [--drones 10,20,40] [--json] [--kill worker|coordinator|logger|relay]
                                      [--mocap-relay auto|on|off|both] [--no-single]

For each swarm size N, the first N drones of missions/lanes-40-4dongles.yaml (10 a dongle: N/10 dongles) fly a dry
run twice, first in one process (``run_flight``, as ``rpf-fly fly --dry-run``), then distributed (the coordinator
in this process, one ``rpf-fly worker`` process per dongle and the logger process, as ``rpf-fly fly --dry-run
--distributed``). Reported per run:

- latency: a mocap frame's receipt by the NatNet client to each setpoint handed to the radio driver, p50 and p99
  over every drone and tick (the loop's own `LoopStats.latencies`; distributed: every worker's, merged);
- CPU: the single process's CPU time in percent of a core over the whole flight (connection included);
  distributed: each worker's process CPU time from the coordinator's go to its end, and the logger's from its first
  message to its end (`time.process_time()`, reported by each as it ends), in percent of a core; and within each
  worker, what its logging costs from its recorder's start to its end (rpf_fly/runtime/worker.py ``logging_cpu``):
  the flight loop's hand-over, the log writer thread's encoding and publishing, Zenoh's own threads, and the total;
- outcome: drones that reached their goals;
- the mocap relay (docs/distributed.md, "Mocap relay"; the mission's NatNet is unicast, so ``auto`` flies with it):
  its process's CPU from its first frame to its end, and the hop from its receipt of a frame to each worker's
  (p50 and p99 over every worker's frames from the go). ``--mocap-relay both`` flies each size distributed twice,
  through the relay and direct (each worker its own NatNet client), side by side; ``--no-single`` leaves out the
  single process. With the relay, the latency starts at the worker's receipt of the relayed frame, so compare it
  with the direct run's plus the relay's hop.

``--kill worker``: a distributed run of the largest N only, SIGKILLing dongle 1's worker once its drones plan;
reports how long the coordinator took to name it, and the others' outcomes. ``--kill relay``: the same with the
mocap relay killed: how long until it was named, and how many drones ended on the floor. ``--kill coordinator`` runs the
coordinator as ``rpf-fly fly --distributed`` in a child and SIGKILLs it mid-flight: every worker must land its
drones (read from the log). ``--kill logger``: the logger killed mid-flight: the flight goes on, the log is salvaged.

The machine is shared: the figures of one run are side by side, compare within a run.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FULL = ROOT / "missions" / "lanes-40-4dongles.yaml"


def mission_file(n: int, out_dir: Path, relay: str = "auto") -> Path:
    """The first ``n`` drones of the 40-drone mission, as a mission file of its own (``runtime.mocap_relay``:
    ``relay``)."""
    text = FULL.read_text()
    head, drones = text.split("drones:\n")
    lines = [line for line in drones.splitlines() if line.strip().startswith("- {name:")][:n]
    path = out_dir / (f"lanes-{n}.yaml" if relay == "auto" else f"lanes-{n}-relay-{relay}.yaml")
    path.write_text(
        head.replace("name: lanes-40-4dongles", f"name: lanes-{n}").replace("../policies/", f"{ROOT}/policies/")
        + "drones:\n"
        + "\n".join(lines)
        + "\n"
        + ("" if relay == "auto" else f"runtime: {{mocap_relay: '{relay}'}}\n")
    )
    return path


def pct(values: list[float], q: float) -> float | None:
    if not values:
        return None
    values = sorted(values)
    return values[min(len(values) - 1, int(round(q * (len(values) - 1))))]


def factory_of(mission):  # type: ignore[no-untyped-def]
    from rpf_fly.planning.factory import make_planner
    from rpf_fly.sim.scenario import obstacle_set

    obstacles = obstacle_set(mission.obstacles)
    return lambda drone: make_planner(mission.planner, obstacles)


def single(path: Path, out: Path) -> dict:
    from rpf_fly.flight.dry_run import DryRun
    from rpf_fly.flight.session import run_flight
    from rpf_fly.mission import load_mission

    mission = load_mission(path)
    cpu0, t0 = time.process_time(), time.monotonic()
    with DryRun(mission) as rig:
        report = run_flight(mission, factory_of(mission), out / f"single-{len(mission.drones)}.mcap", rig=rig)
    cpu, wall = time.process_time() - cpu0, time.monotonic() - t0
    lat = report.stats.latencies
    return {
        "mode": "single",
        "drones": len(mission.drones),
        "reached": sum(o.value == "reached" for o in report.outcomes.values()),
        "latency_p50_ms": _ms(pct(lat, 0.5)),
        "latency_p99_ms": _ms(pct(lat, 0.99)),
        "cpu_pct": {"flight process": round(100 * cpu / wall, 1)},
    }


def _ms(v: float | None) -> float | None:
    return None if v is None else round(v * 1e3, 2)


def distributed(path: Path, out: Path, kill: str = "") -> dict:
    from rpf_fly.mission import load_mission
    from rpf_fly.runtime.coordinator import Coordinator

    mission = load_mission(path)
    lines: list[str] = []
    log = out / f"distributed-{len(mission.drones)}-{path.stem}{'-kill-' + kill if kill else ''}.mcap"
    coordinator = Coordinator(mission, path, log, dry_run=True, say=lines.append)
    result: dict = {}
    thread = threading.Thread(target=lambda: result.update(code=coordinator.run()), daemon=True)
    cpu0 = time.process_time()
    thread.start()
    killed_at = None
    if kill:
        victim_drones = coordinator.workers["dongle-1"].drones
        while thread.is_alive() and coordinator.drones[victim_drones[0]].state != "planning":
            time.sleep(0.05)
        time.sleep(1.0)
        if kill == "worker":
            process = coordinator.workers["dongle-1"].process
        elif kill == "relay":
            process = coordinator.relay_process
        else:
            process = coordinator.logger_process
        killed_at = time.monotonic()
        os.kill(process.pid, signal.SIGKILL)  # type: ignore[union-attr]
    thread.join()
    flight_s = (coordinator.ended_s or time.monotonic()) - (coordinator.started_s or 0.0)
    latencies = [v * 1e-6 for w in coordinator.workers.values() for v in w.info.get("latencies_us", [])]
    cpu = {w.name: w.info.get("cpu_pct") for w in coordinator.workers.values() if "cpu_s" in w.info}
    for w in coordinator.workers.values():
        if w.info.get("logging_cpu") is not None:
            cpu[f"{w.name}: logging"] = w.info["logging_cpu"]
    if "cpu_s" in coordinator.logger_info:
        cpu["logger"] = coordinator.logger_info.get("cpu_pct")
    cpu["coordinator (+ truth feed)"] = round(100 * (time.process_time() - cpu0) / flight_s, 1)
    if coordinator.relay_info.get("cpu_pct") is not None:
        cpu["mocap relay"] = coordinator.relay_info["cpu_pct"]
    hops = [v * 1e-6 for w in coordinator.workers.values() for v in w.info.get("relay_transit_us", [])]
    row = {
        "mode": "distributed, " + ("relay" if coordinator.relayed else "direct mocap"),
        "drones": len(mission.drones),
        "reached": sum(v.outcome == "reached" for v in coordinator.drones.values()),
        "latency_p50_ms": _ms(pct(latencies, 0.5)),
        "latency_p99_ms": _ms(pct(latencies, 0.99)),
        "cpu_pct": cpu,
        "exit": result.get("code"),
    }
    if hops:
        row.update(
            relay_hop_p50_ms=_ms(pct(hops, 0.5)),
            relay_hop_p99_ms=_ms(pct(hops, 0.99)),
            relay_frames=coordinator.relay_info.get("frames"),
        )
    if killed_at is not None:
        lost = [e for e in coordinator.events.history if e.kind == "worker_lost"]
        row["killed"] = kill
        if kill == "worker":
            row["noticed_after_s"] = round(lost[0].time_s - killed_at, 3) if lost else None
            dead = set(coordinator.workers["dongle-1"].drones)
            row["others_reached"] = sum(v.outcome == "reached" for n, v in coordinator.drones.items() if n not in dead)
            row["others"] = len(coordinator.drones) - len(dead)
        if kill == "relay":
            lost = [e for e in coordinator.events.history if e.kind == "relay_lost"]
            row["noticed_after_s"] = round(lost[0].time_s - killed_at, 3) if lost else None
            row["down"] = sum(v.state in ("landed", "failed") for v in coordinator.drones.values())
        row["log"] = str(log)
    return row


def kill_coordinator(path: Path, out: Path) -> dict:
    """``rpf-fly fly --distributed`` in a child, SIGKILLed once the drones plan: the log must show every drone landed
    (the workers land on their own; the logger writes on until they are gone)."""
    from rpf_fly.log.reader import read_log, salvage

    log = out / "kill-coordinator.mcap"
    child = subprocess.Popen(
        [sys.executable, "-m", "rpf_fly", "fly", str(path), "--dry-run", "--distributed", "--log", str(log)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    assert child.stdout is not None
    for line in child.stdout:
        if "swarm: flying" in line:
            break
    time.sleep(3.0)
    child.send_signal(signal.SIGKILL)
    child.wait()
    time.sleep(15.0)  # the workers land; the logger finishes once they are gone
    data = read_log(log)
    if data.truncated:
        salvage(log, out / "kill-coordinator-salvaged.mcap")
        data = read_log(out / "kill-coordinator-salvaged.mcap")
    finals = {
        t.split("/")[1]: msgs[-1].data["state"] for t, msgs in data.topics.items() if t.endswith("/status") and msgs
    }
    return {
        "killed": "coordinator",
        "drones": len(finals),
        "final_states": sorted(set(finals.values())),
        "landed": sum(s == "landed" for s in finals.values()),
        "log_truncated": data.truncated,
        "log": str(log),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--drones", default="10,20,40")
    parser.add_argument("--kill", choices=("worker", "coordinator", "logger", "relay"))
    parser.add_argument(
        "--mocap-relay",
        choices=("auto", "on", "off", "both"),
        default="auto",
        help="the distributed runs' runtime.mocap_relay (auto: the relay, the mission's NatNet being "
        "unicast); both: one run each way",
    )
    parser.add_argument("--no-single", action="store_true", help="leave out the single-process runs")
    parser.add_argument(
        "--mission",
        type=Path,
        default=None,
        help="--kill: fly this mission (its dongle 1's worker is the one killed) instead",
    )
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--out", type=Path, default=None, help="where the logs go (default: a temporary folder)")
    args = parser.parse_args()
    sizes = [int(v) for v in args.drones.split(",")]
    out = args.out or Path(tempfile.mkdtemp(prefix="rpf-bench-distributed-"))
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    target = args.mission.resolve() if args.mission else None
    if args.kill == "coordinator":
        rows.append(kill_coordinator(target or mission_file(max(sizes), out), out))
    elif args.kill:
        rows.append(distributed(target or mission_file(max(sizes), out), out, kill=args.kill))
    else:
        ways = ("on", "off") if args.mocap_relay == "both" else (args.mocap_relay,)
        for n in sizes:
            if not args.no_single:
                rows.append(single(mission_file(n, out), out))
            for way in ways:
                rows.append(distributed(mission_file(n, out, way), out))
    if args.json:
        print(json.dumps(rows, indent=1))
    else:
        for row in rows:
            print(json.dumps(row))
    print(f"logs: {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
