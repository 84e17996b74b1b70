"""Benchmark: NatNet frame parsing rate of rpf_fly vs OptiTrack's Python sample client, on the same bytes.

Frames: 10 rigid bodies, either alone ("rb-only") or as Motive streams them with 4 markers per body ("motive":
a marker set per body, the "all" set and 40 labeled markers), in bitstream 3.0 and 4.1. For each, the median
packets/s over ``--repeats`` timed runs of rpf_fly's ``decode_packet`` (header included) and, with
``--sample-client PATH``, of the sample client's frame-unpacking method on the same packet (its prints are
silenced). The sample client (``NatNetClient.py`` with its ``MoCapData.py`` and ``DataDescriptions.py`` beside it,
from the NatNet SDK's PythonClient) is not part of this repository: point at a copy outside it.

    python tools/bench_natnet.py --sample-client PATH/TO/PythonClient/NatNetClient.py
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import json
import statistics
import sys
import time
import types
from collections.abc import Callable
from pathlib import Path
from typing import Any

from rpf_fly.mocap.natnet_protocol import (
    FrameOfData,
    LabeledMarker,
    MarkerSetData,
    RigidBodyData,
    decode_packet,
    encode_frame,
)

N_BODIES = 10
MARKERS_PER_BODY = 4


def make_frame(kind: str) -> FrameOfData:
    """A 10-rigid-body frame; ``kind`` "motive" adds the markers Motive streams with them."""
    bodies = [
        RigidBodyData(i, 0.1 * i, 1.0 + 0.01 * i, -0.5, 0.01, 0.7, 0.02, 0.71, 0.0004, 1)
        for i in range(1, N_BODIES + 1)
    ]
    frame = FrameOfData(
        frame_number=123456,
        rigid_bodies=bodies,
        timestamp=1234.5,
        camera_mid_exposure=1_000_000,
        camera_data_received=1_040_000,
        transmit=1_045_000,
    )
    if kind == "motive":
        all_markers = []
        for rb in bodies:
            markers = [(rb.x + 0.01 * k, rb.y, rb.z - 0.01 * k) for k in range(MARKERS_PER_BODY)]
            frame.marker_sets.append(MarkerSetData(f"cf{rb.id}", markers))
            all_markers += markers
            frame.labeled_markers += [
                LabeledMarker((rb.id << 16) | (k + 1), *m, 0.014, 0x0A, 0.0002) for k, m in enumerate(markers)
            ]
        frame.marker_sets.append(MarkerSetData("all", all_markers))
    return frame


def measure(fn: Callable[[], Any], repeats: int, min_time_s: float) -> float:
    """Median calls per second of ``fn`` over ``repeats`` runs of at least ``min_time_s`` each."""
    n = 1
    while True:  # calibrate the loop count
        start = time.perf_counter()
        for _ in range(n):
            fn()
        elapsed = time.perf_counter() - start
        if elapsed >= min_time_s / 4:
            break
        n *= 2
    n = max(1, int(n * min_time_s / max(elapsed, 1e-9)))
    rates = []
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(n):
            fn()
        rates.append(n / (time.perf_counter() - start))
    return statistics.median(rates)


def load_sample_client(path: Path) -> Any:
    """Import the SDK's NatNetClient.py (absolute or package-relative imports of MoCapData/DataDescriptions)."""
    directory = path.resolve().parent
    sys.path.insert(0, str(directory))
    package = types.ModuleType("_natnet_sdk_sample")
    package.__path__ = [str(directory)]  # type: ignore[attr-defined]
    sys.modules["_natnet_sdk_sample"] = package
    with contextlib.redirect_stdout(io.StringIO()):
        module = importlib.import_module(f"_natnet_sdk_sample.{path.stem}")
        return module.NatNetClient()


def sample_unpacker(client: Any, packet: bytes, version: tuple[int, int]) -> Callable[[], Any]:
    """A call of the sample client's frame unpacking on ``packet`` (payload after the header, as it does)."""
    unpack = client._NatNetClient__unpack_mocap_data
    payload = packet[4:]
    size = int.from_bytes(packet[2:4], "little")
    major, minor = version
    sink = io.StringIO()

    def run() -> Any:
        with contextlib.redirect_stdout(sink):
            result = unpack(payload, size, major, minor)
        sink.seek(0)
        sink.truncate()
        return result

    return run


def check_agreement(sample_result: Any, ours: FrameOfData) -> bool:
    """The sample client decoded the same rigid bodies (guards against benchmarking a failed parse)."""
    _, mocap = sample_result
    bodies = mocap.rigid_body_data.rigid_body_list
    return [(b.id_num, tuple(b.pos)) for b in bodies] == [(rb.id, (rb.x, rb.y, rb.z)) for rb in ours.rigid_bodies]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sample-client", type=Path, help="path to the NatNet SDK sample NatNetClient.py")
    parser.add_argument("--repeats", type=int, default=7, help="timed runs per figure (median reported)")
    parser.add_argument("--min-time", type=float, default=0.3, help="seconds per timed run")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    args = parser.parse_args(argv)

    sample = None
    if args.sample_client is not None:
        if not args.sample_client.is_file():
            parser.error(f"{args.sample_client} does not exist")
        sample = load_sample_client(args.sample_client)

    rows = []
    for kind in ("rb-only", "motive"):
        for version in ((3, 0), (4, 1)):
            packet = encode_frame(make_frame(kind), version)
            frame = decode_packet(packet, version)[1]  # float32-rounded reference
            assert len(frame.rigid_bodies) == N_BODIES
            row: dict[str, Any] = {
                "frame": kind,
                "version": f"{version[0]}.{version[1]}",
                "bytes": len(packet),
                "rpf_fly_pps": measure(lambda: decode_packet(packet, version), args.repeats, args.min_time),
            }
            if sample is not None:
                run = sample_unpacker(sample, packet, version)
                row["sample_agrees"] = check_agreement(run(), frame)
                row["sample_pps"] = measure(run, args.repeats, args.min_time)
                row["ratio"] = row["rpf_fly_pps"] / row["sample_pps"]
            rows.append(row)

    if args.json:
        print(json.dumps({"python": sys.version.split()[0], "rows": rows}, indent=2))
        return 0
    python = sys.version.split()[0]
    print(f"NatNet frame parsing, {N_BODIES} rigid bodies, median of {args.repeats} runs (Python {python})")
    header = f"{'frame':8} {'ver':4} {'bytes':>6} {'rpf_fly pkt/s':>14}"
    if sample is not None:
        header += f" {'SDK sample pkt/s':>17} {'ratio':>7} agree"
    print(header)
    for row in rows:
        line = f"{row['frame']:8} {row['version']:4} {row['bytes']:>6} {row['rpf_fly_pps']:>14,.0f}"
        if sample is not None:
            line += f" {row['sample_pps']:>17,.0f} {row['ratio']:>6.1f}x {'yes' if row['sample_agrees'] else 'NO'}"
        print(line)
    if sample is None:
        print("(no --sample-client given: OptiTrack's sample client was not measured)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
