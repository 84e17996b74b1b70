"""Benchmark: what the crash isolation of the motioncapture source costs in latency, against our NatNet client.

The NatNet emulator multicasts a frame on 127.0.0.1 (``--bodies`` rigid bodies, bitstream 4.1, markers as Motive
streams them) every ``1/--rate`` seconds; one reader at a time waits for it in ``receive()``, as the flight loop
does, and the time from just before ``sendto`` to ``receive()`` returning is measured:

- ``natnet``: our NatNet client (decodes in the caller's process);
- ``motioncapture``: :class:`MotioncaptureSource` with type ``optitrack``: libmotioncapture's decoder in the child
  process, then the record over the pipe. Split into ``library`` (send to the child's ``waitForNextFrame()``
  returning: the frame's ``receive_time_s``) and ``pipe`` (from there to the parent's ``receive()`` returning:
  the child's conversion and write, the pipe, the parent's wake-up and decode).

    python tools/bench_motioncapture.py [--frames 2000] [--bodies 10] [--rate 100] [--json]

Median, p90 and p99 in microseconds. The figure in docs/mocap.md ("Crash isolation: what it costs") is from here.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from collections.abc import Callable
from typing import Any

from rpf_fly.emulator.natnet_server import NatNetServer
from rpf_fly.mocap.motioncapture_source import MotioncaptureSource
from rpf_fly.mocap.natnet_client import NatNetClient


def _percentiles(samples: list[float]) -> dict[str, float]:
    ordered = sorted(samples)
    pick = lambda q: ordered[min(len(ordered) - 1, int(q * len(ordered)))]  # noqa: E731
    return {"p50_us": statistics.median(ordered) * 1e6, "p90_us": pick(0.9) * 1e6, "p99_us": pick(0.99) * 1e6}


def _run(
    server: NatNetServer, receive: Callable[[float], Any], frames: int, rate: float
) -> list[tuple[float, float, float]]:
    """(sent, library-side receipt, returned) per frame, monotonic seconds."""
    out = []
    period = 1.0 / rate
    next_send = time.monotonic()
    for _ in range(frames + 20):
        time.sleep(max(0.0, next_send - time.monotonic()))
        next_send += period
        sent = time.monotonic()
        server.send_frame()
        frame = receive(1.0)
        returned = time.monotonic()
        if frame is None:
            raise RuntimeError("a frame was not received within 1 s")
        out.append((sent, frame.receive_time_s, returned))
    return out[20:]  # the first frames warm the sockets, the pipe and the caches up


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=2000)
    parser.add_argument("--bodies", type=int, default=10)
    parser.add_argument("--rate", type=float, default=100.0)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    names = [f"cf{i + 1}" for i in range(args.bodies)]
    poses = {n: ((0.1 * i, 1.0, 0.5), (0.0, 0.0, 0.0, 1.0), True) for i, n in enumerate(names)}
    results: dict[str, dict[str, float]] = {}
    with NatNetServer(lambda: poses, version="4.1", multicast=True, rate_hz=0, up_axis="z", bodies=names) as server:
        with NatNetClient(
            "127.0.0.1", multicast=True, local_ip="127.0.0.1", command_port=server.command_port, data_port=None
        ) as client:
            if not client.wait_for_server(5.0):
                raise SystemExit("the emulator did not answer")
            natnet = _run(server, client.receive, args.frames, args.rate)
        results["natnet"] = _percentiles([r - s for s, _, r in natnet])
        with MotioncaptureSource("optitrack", "127.0.0.1", {"port_command": server.command_port}) as source:
            library = _run(server, source.receive, args.frames, args.rate)
        results["motioncapture"] = _percentiles([r - s for s, _, r in library])
        results["motioncapture library"] = _percentiles([c - s for s, c, _ in library])
        results["motioncapture pipe"] = _percentiles([r - c for _, c, r in library])
    added = results["motioncapture"]["p50_us"] - results["natnet"]["p50_us"]
    if args.json:
        print(
            json.dumps(
                {
                    "frames": args.frames,
                    "bodies": args.bodies,
                    "rate_hz": args.rate,
                    "results": results,
                    "added_p50_us": added,
                }
            )
        )
        return
    print(f"{args.frames} frames of {args.bodies} rigid bodies at {args.rate:g} Hz, send to receive() returning:")
    for name, r in results.items():
        print(f"  {name:<22} p50 {r['p50_us']:8.1f} us   p90 {r['p90_us']:8.1f} us   p99 {r['p99_us']:8.1f} us")
    print(f"  added by the child process (p50): {added:.1f} us")


if __name__ == "__main__":
    main()
