"""What the dry run's truth (``/truth/<drone>``) and contact model cost, and why the truth is polled in batches.

    python tools/bench_truth.py [--drones 10] [--seconds 10]

Measured in this (the flight's) process, over ``--seconds`` of a world of hovering drones in a child process:
- ``poll 10 Hz`` (what the dry run does, rpf_fly/flight/truth.py): a thread fetches the samples that accumulated
  in the world process (one round trip over the locked control connection, ``WorldProcess.truth_samples``) every
  0.1 s and hands each sample to the flight log (``FlightLog.truth``, one queue entry per sample of all drones);
- ``poll 50 Hz``: the same thread fetching every 0.02 s;
- ``push 100 Hz``: a prototype of the other design, the world process sending every sample as one UDP datagram
  (pickle) the moment it is taken, a thread here receiving them.
For each: the CPU time of that thread (time.thread_time) in percent of one core, its wake-ups a second, and the
samples it delivered. Then, once for all (the messages are the same): the log writer's CPU time for the /truth
messages alone. And in the world process's own terms (in this process, no threads): one world step's contact
check and truth sample (``FakeWorld._after_step``) next to the firmwares' step.
"""

from __future__ import annotations

import argparse
import pickle
import socket
import subprocess
import sys
import tempfile
import textwrap
import threading
import time
from pathlib import Path

from rpf_fly.emulator.fake_world import FakeDroneConfig, FakeWorld
from rpf_fly.emulator.world_process import WorldProcess
from rpf_fly.flight.truth import TruthFeed
from rpf_fly.log.writer import FlightLog

BASE = 0xE7E7E7E700


def drones(n: int) -> dict[int, FakeDroneConfig]:
    return {BASE + i: FakeDroneConfig.at(0.5 * (i % 5), 0.5 * (i // 5)) for i in range(n)}


def poll(n: int, seconds: float, period_s: float) -> dict:
    """The dry run's design at one fetch period; also the writer's cost of the messages."""
    process = WorldProcess(drones(n), {BASE + i: f"cf{i}" for i in range(n)}, natnet=None)
    names = {BASE + i: f"cf{i}" for i in range(n)}
    offset = time.time() - time.monotonic()
    with tempfile.TemporaryDirectory() as tmp:
        log = FlightLog(Path(tmp) / "truth.mcap", {}, {})

        def fetch():  # type: ignore[no-untyped-def]
            return [(t, {names[a]: s for a, s in states.items()}) for t, states in process.truth_samples()]

        feed = TruthFeed(fetch, lambda t, states: log.truth(int((t + offset) * 1e9), states), period_s)
        try:
            process.truth_samples()
            feed.start()
            time.sleep(seconds)
            feed.stop()
        finally:
            process.close()
            log.close()
    return {
        "cpu_pct": 100 * feed.cpu_s / seconds,
        "wakeups_per_s": feed.fetches / seconds,
        "samples_per_s": feed.samples / seconds,
        "writer_cpu_pct": 100 * log.writer_cpu_s / seconds,
        "messages": log.written,
    }


PUSHER = textwrap.dedent("""
    import pickle, socket, sys, time
    from rpf_fly.emulator.fake_world import FakeDroneConfig, FakeWorld
    n, port, seconds = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
    world = FakeWorld({0xE7E7E7E700 + i: FakeDroneConfig.at(0.5 * (i % 5), 0.5 * (i // 5)) for i in range(n)}).start()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        for sample in world.truth_samples():
            sock.sendto(pickle.dumps(sample, protocol=pickle.HIGHEST_PROTOCOL), ("127.0.0.1", port))
        time.sleep(0.002)
    sock.sendto(b"", ("127.0.0.1", port))
    world.close()
""")


def push(n: int, seconds: float) -> dict:
    """The alternative: the world process pushes each sample; a thread here receives it and logs it."""
    names = {BASE + i: f"cf{i}" for i in range(n)}
    offset = time.time() - time.monotonic()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    result: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        log = FlightLog(Path(tmp) / "truth.mcap", {}, {})

        def receive() -> None:
            wakeups = samples = 0
            while True:
                data = sock.recv(65536)
                if not data:
                    break
                wakeups += 1
                t, states = pickle.loads(data)
                log.truth(int((t + offset) * 1e9), {names[a]: s for a, s in states.items()})
                samples += 1
            result.update(cpu_s=time.thread_time(), wakeups=wakeups, samples=samples)

        thread = threading.Thread(target=receive, daemon=True)
        thread.start()
        child = subprocess.Popen([sys.executable, "-c", PUSHER, str(n), str(sock.getsockname()[1]), str(seconds)])
        child.wait()
        thread.join(5)
        log.close()
    sock.close()
    return {
        "cpu_pct": 100 * result["cpu_s"] / seconds,
        "wakeups_per_s": result["wakeups"] / seconds,
        "samples_per_s": result["samples"] / seconds,
    }


def world_step_cost(n: int, steps: int = 2000) -> dict:
    """Microseconds per world step: the firmwares' step, and the contact check with the truth sample after it."""
    from rpf_fly.mission.model import CircleObstacle

    world = FakeWorld(drones(n), obstacles=[CircleObstacle((5.0, 5.0), 0.2), CircleObstacle((-3.0, 1.0), 0.1)])
    firmwares = [world.firmware(a) for a in world.addresses]
    t = 0.0
    c0 = time.thread_time()
    for _ in range(steps):
        t += 0.01
        for fw in firmwares:
            fw.step(t)
    stepping = time.thread_time() - c0
    c0 = time.thread_time()
    for _ in range(steps):
        world._after_step(t)  # noqa: SLF001 - the world thread's per-step addition, timed alone
    after = time.thread_time() - c0
    return {"firmware_step_us": 1e6 * stepping / steps, "contact_and_truth_us": 1e6 * after / steps}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--drones", type=int, default=10)
    parser.add_argument("--seconds", type=float, default=10.0)
    args = parser.parse_args()
    n, s = args.drones, args.seconds
    print(f"{n} drones, {s:g} s each; CPU of the receiving thread in the flight's process, % of one core:")
    chosen = poll(n, s, 0.1)
    for name, r in (("poll 10 Hz (chosen)", chosen), ("poll 50 Hz", poll(n, s, 0.02)), ("push 100 Hz", push(n, s))):
        print(
            f"  {name:20s} {r['cpu_pct']:5.2f} %  {r['wakeups_per_s']:6.1f} wake-ups/s  "
            f"{r['samples_per_s']:6.1f} samples/s"
        )
    per_message = 1e6 * chosen["writer_cpu_pct"] / 100 * s / max(chosen["messages"], 1)
    print(
        f"  log writer, /truth only: {chosen['writer_cpu_pct']:.2f} % ({per_message:.1f} us a message, "
        f"{chosen['messages'] / s:.0f} messages/s)"
    )
    cost = world_step_cost(n)
    print(
        f"world process, one step: firmwares {cost['firmware_step_us']:.0f} us, contact check + truth sample "
        f"{cost['contact_and_truth_us']:.0f} us"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
