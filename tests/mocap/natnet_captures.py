"""Readers for the real NatNet captures in tests/data/natnet: a small pcapng reader (Ethernet/IPv4/UDP) and a
parser for the NatNet SDK SampleClient printout of the same session."""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass, field
from pathlib import Path

DATA = Path(__file__).resolve().parents[1] / "data" / "natnet"

_SHB = 0x0A0D0D0A
_IDB = 0x00000001
_SPB = 0x00000003
_EPB = 0x00000006
_BYTE_ORDER_MAGIC = 0x1A2B3C4D


@dataclass(frozen=True)
class UdpDatagram:
    """One UDP datagram from the capture."""

    timestamp_us: int
    src: tuple[str, int]
    dst: tuple[str, int]
    payload: bytes


def read_pcapng_packets(path: Path) -> list[tuple[int, int, bytes]]:
    """(interface link type, timestamp in capture units, frame bytes) of every packet block in a pcapng file."""
    data = path.read_bytes()
    off = 0
    endian = "<"
    link_types: list[int] = []
    packets: list[tuple[int, int, bytes]] = []
    while off + 12 <= len(data):
        (block_type,) = struct.unpack_from("<I", data, off)
        if block_type == _SHB:
            (magic,) = struct.unpack_from("<I", data, off + 8)
            endian = "<" if magic == _BYTE_ORDER_MAGIC else ">"
            link_types = []  # interface ids restart per section
        (block_len,) = struct.unpack_from(endian + "I", data, off + 4)
        if block_len < 12 or off + block_len > len(data):
            raise ValueError(f"corrupt pcapng block at {off}")
        body = off + 8
        if block_type == _IDB:
            (link_type,) = struct.unpack_from(endian + "H", data, body)
            link_types.append(link_type)
        elif block_type == _EPB:
            iface, ts_high, ts_low, captured, _original = struct.unpack_from(endian + "5I", data, body)
            packets.append((link_types[iface], (ts_high << 32) | ts_low, data[body + 20 : body + 20 + captured]))
        elif block_type == _SPB:
            (original,) = struct.unpack_from(endian + "I", data, body)
            captured = min(original, block_len - 16)
            packets.append((link_types[0], 0, data[body + 4 : body + 4 + captured]))
        off += block_len
    return packets


def read_udp_datagrams(path: Path) -> list[UdpDatagram]:
    """Every IPv4/UDP datagram on Ethernet in a pcapng file (no fragments expected; asserted)."""
    out: list[UdpDatagram] = []
    for link_type, ts, frame in read_pcapng_packets(path):
        assert link_type == 1, "only Ethernet captures are expected"
        ether_type = struct.unpack_from(">H", frame, 12)[0]
        ip = 14
        if ether_type == 0x8100:  # VLAN tag
            ether_type = struct.unpack_from(">H", frame, 16)[0]
            ip = 18
        if ether_type != 0x0800:
            continue
        ihl = (frame[ip] & 0x0F) * 4
        protocol = frame[ip + 9]
        flags_fragment = struct.unpack_from(">H", frame, ip + 6)[0]
        assert flags_fragment & 0x3FFF == 0, "IP fragments are not expected in this capture"
        if protocol != 17:
            continue
        src_ip = ".".join(map(str, frame[ip + 12 : ip + 16]))
        dst_ip = ".".join(map(str, frame[ip + 16 : ip + 20]))
        udp = ip + ihl
        src_port, dst_port, length = struct.unpack_from(">HHH", frame, udp)
        out.append(UdpDatagram(ts, (src_ip, src_port), (dst_ip, dst_port), bytes(frame[udp + 8 : udp + length])))
    return out


@dataclass
class PrintedFrame:
    """What the SampleClient printed for one FrameID (numbers kept as the printed strings)."""

    frame_id: int
    timestamp: str = ""
    software_latency_ms: str = ""
    system_latency_ms: str = ""
    timecode: str = ""
    counts: dict[str, int] = field(default_factory=dict)
    other_markers: list[tuple[str, str, str]] = field(default_factory=list)
    rigid_bodies: list[dict] = field(default_factory=list)
    labeled_markers: list[dict] = field(default_factory=list)


@dataclass
class PrintedSession:
    """The SampleClient printout: server info, data descriptions and frames."""

    application: str = ""
    application_version: str = ""
    natnet_version: str = ""
    frame_rate: str = ""
    analog_samples: str = ""
    rigid_body_descriptions: list[dict] = field(default_factory=list)
    marker_sets: dict[str, list[str]] = field(default_factory=dict)
    frames: dict[int, PrintedFrame] = field(default_factory=dict)


_NUM = r"-?\d+\.\d+"
_COUNT = r"(Other Markers|Rigid Bodies|Skeletons|Labeled Markers|Force Plate|Device) \[Count=(\d+)\]"


def parse_sample_client_output(path: Path) -> PrintedSession:
    """Parse the printout line by line; lines of other threads interleaved in a frame are ignored."""
    session = PrintedSession()
    frame: PrintedFrame | None = None
    rigid_body: dict | None = None
    pending_rb: dict | None = None
    description: dict | None = None
    marker_set: list[str] | None = None
    for raw in path.read_text().splitlines():
        line = raw.rstrip("\n")
        if m := re.fullmatch(r"Application: (\S+) \(ver\. ([\d.]+)\)", line):
            session.application, session.application_version = m.groups()
        elif m := re.fullmatch(r"NatNet Version: ([\d.]+)", line):
            session.natnet_version = m.group(1)
        elif m := re.fullmatch(r"Mocap Framerate : (" + _NUM + ")", line):
            session.frame_rate = m.group(1)
        elif m := re.fullmatch(r"Analog Samples Per Mocap Frame : (\d+)", line):
            session.analog_samples = m.group(1)
        elif m := re.fullmatch(r"RigidBody Name : (.*)", line):
            description = {"name": m.group(1), "markers": []}
            session.rigid_body_descriptions.append(description)
            marker_set = None
        elif description is not None and (m := re.fullmatch(r"RigidBody ID : (-?\d+)", line)):
            description["id"] = int(m.group(1))
        elif description is not None and (m := re.fullmatch(r"RigidBody Parent ID : (-?\d+)", line)):
            description["parent_id"] = int(m.group(1))
        elif description is not None and (m := re.fullmatch(rf"Parent Offset : ({_NUM}),({_NUM}),({_NUM})", line)):
            description["offset"] = m.groups()
        elif description is not None and (m := re.fullmatch(rf"\t\tPosition: ({_NUM}), ({_NUM}), ({_NUM})", line)):
            description["markers"].append(m.groups())
        elif m := re.fullmatch(r"MarkerSet Name : (.*)", line):
            marker_set = session.marker_sets.setdefault(m.group(1), [])
            description = None
        elif m := re.fullmatch(r"FrameID : (\d+)", line):
            frame = PrintedFrame(int(m.group(1)))
            session.frames[frame.frame_id] = frame
            marker_set = description = None
        elif marker_set is not None and re.fullmatch(r"[A-Za-z0-9_]+", line):
            marker_set.append(line)
        elif frame is None:
            continue
        elif m := re.fullmatch(r"Timestamp : (" + _NUM + ")", line):
            frame.timestamp = m.group(1)
        elif m := re.fullmatch(r"Software latency : (" + _NUM + ") milliseconds", line):
            frame.software_latency_ms = m.group(1)
        elif m := re.fullmatch(r"System latency : (" + _NUM + ") milliseconds", line):
            frame.system_latency_ms = m.group(1)
        elif m := re.fullmatch(r"Timecode : (\S+)", line):
            frame.timecode = m.group(1)
        elif m := re.fullmatch(_COUNT, line):
            frame.counts[m.group(1)] = int(m.group(2))
        elif m := re.fullmatch(rf"Other Marker (\d+) : ({_NUM})\t({_NUM})\t({_NUM})", line):
            assert int(m.group(1)) == len(frame.other_markers)
            frame.other_markers.append(m.groups()[1:])
        elif m := re.fullmatch(rf"Rigid Body \[ID=(-?\d+)  Error=({_NUM})  Valid=(\d)\]", line):
            pending_rb = {"id": int(m.group(1)), "error": m.group(2), "valid": m.group(3)}
        elif line == "\tx\ty\tz\tqx\tqy\tqz\tqw":
            rigid_body = pending_rb
        elif rigid_body is not None and (m := re.fullmatch("\t" + "\t".join([f"({_NUM})"] * 7), line)):
            rigid_body["pose"] = m.groups()
            frame.rigid_bodies.append(rigid_body)
            rigid_body = pending_rb = None
        elif m := re.fullmatch(
            r"Labeled Marker \[ModelID=(\d+), MarkerID=(\d+), Occluded=(\d), PCSolved=(\d), ModelSolved=(\d)\] "
            rf"\[size=({_NUM})\] \[pos=({_NUM}),({_NUM}),({_NUM})\]",
            line,
        ):
            model, marker, occluded, pc, ms, size, x, y, z = m.groups()
            frame.labeled_markers.append(
                {
                    "model_id": int(model),
                    "marker_id": int(marker),
                    "occluded": int(occluded),
                    "pc_solved": int(pc),
                    "model_solved": int(ms),
                    "size": size,
                    "pos": (x, y, z),
                }
            )
    return session
