"""The mocap relay's frames on Zenoh: one signed message per mocap frame (docs/distributed.md, "Mocap relay").

Workers fly on these frames, so a frame is obeyed like a command: only when it is signed with the flight's secret
(HMAC-SHA256 of the value's bytes, hex, as the sample's attachment: rpf_fly/runtime/auth.py), names this flight and
carries a sequence number above every one taken before (the relay counts up from 1; a replayed or reordered old
frame is refused). Key ``rpf_fly/<flight>/mocap_frames``; the value is one JSON object::

    {"flight": ID, "seq": N, "frame_number": N, "capture_time_s": S, "latency_s": S | null,
     "relay_receive_ns": NS, "relay_publish_ns": NS,
     "bodies": [{"name", "id", "position": [x, y, z], "quaternion": [qx, qy, qz, qw], "valid", "marker_error"}]}

``capture_time_s`` and ``latency_s`` are the mocap source's (:class:`~rpf_fly.mocap.frame.MocapFrame`);
``relay_receive_ns`` is when the relay received the frame from the mocap system and ``relay_publish_ns`` when it
published it, both in ns since the Unix epoch (the relay host's clock), so a worker on a host whose clock agrees
measures the relay's hop. Poses are in the Z-up world frame, metres, as every :class:`MocapSource` delivers them.
"""

from __future__ import annotations

import math
import time
from typing import Any, NamedTuple

import orjson

from rpf_fly.mocap.frame import MocapFrame, RigidBodyPose
from rpf_fly.runtime.auth import mac, signed_by


def _floats(value: Any, n: int, what: str) -> tuple[float, ...]:
    if not isinstance(value, list) or len(value) != n:
        raise ValueError(f"{what}: expected {n} numbers")
    out = tuple(float(v) for v in value if isinstance(v, (int, float)) and not isinstance(v, bool))
    if len(out) != n or not all(math.isfinite(v) for v in out):
        raise ValueError(f"{what}: expected {n} finite numbers")
    return out


def _vec3(value: Any, what: str) -> tuple[float, float, float]:
    x, y, z = _floats(value, 3, what)
    return x, y, z


def _quat(value: Any, what: str) -> tuple[float, float, float, float]:
    x, y, z, w = _floats(value, 4, what)
    return x, y, z, w


def _int(value: Any, what: str) -> int:
    if not isinstance(value, int) or isinstance(value, bool):
        raise ValueError(f"{what}: expected an integer")
    return value


def _number(value: Any, what: str) -> float:
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
        raise ValueError(f"{what}: expected a finite number")
    return float(value)


class FrameSigner:
    """The relay's side: each frame as a signed message, numbered from 1."""

    def __init__(self, secret: str, flight: str):
        self._key = secret.encode()
        self._flight = flight
        self.seq = 0
        self._offset_ns = time.time_ns() - time.monotonic_ns()
        """Unix-epoch ns minus monotonic ns: the frame's receive time (monotonic s) as a wall-clock stamp."""

    def sign(self, frame: MocapFrame) -> tuple[bytes, bytes]:
        """The payload and its attachment (signature) of one frame."""
        self.seq += 1
        bodies = [
            {
                "name": b.name,
                "id": int(b.id),
                "position": [float(v) for v in b.position],
                "quaternion": [float(v) for v in b.quaternion],
                "valid": bool(b.valid),
                "marker_error": float(b.marker_error),
            }
            for b in frame.bodies.values()
        ]
        payload = orjson.dumps(
            {
                "flight": self._flight,
                "seq": self.seq,
                "frame_number": int(frame.frame_number),
                "capture_time_s": float(frame.capture_time_s),
                "latency_s": None if frame.latency_s is None else float(frame.latency_s),
                "relay_receive_ns": round(frame.receive_time_s * 1e9) + self._offset_ns,
                "relay_publish_ns": time.time_ns(),
                "bodies": bodies,
            }
        )
        return payload, mac(self._key, payload)


class Verdict(NamedTuple):
    """One message's verdict: the frame (None: refused, ``why``), and when the relay received it (Unix ns)."""

    frame: MocapFrame | None
    why: str = ""
    malformed: bool = False
    relay_receive_ns: int = 0


class FrameVerifier:
    """The worker's side: signature, flight, shape, sequence. Not thread-safe (one subscriber callback at a time)."""

    def __init__(self, secret: str, flight: str):
        self._key = secret.encode()
        self._flight = flight
        self.last_seq = 0

    def verify(self, payload: bytes, attachment: bytes | None, receive_time_s: float) -> Verdict:
        """The frame (its ``receive_time_s`` the caller's receipt time) or why it is refused."""
        if not attachment:
            return Verdict(None, "unsigned mocap frame (no signature)")
        if not signed_by(self._key, payload, attachment):
            return Verdict(None, "mocap frame with a wrong signature (not this flight's secret)")
        try:
            body = orjson.loads(payload)
            if type(body) is not dict:
                raise ValueError("not a JSON object")
            flight, seq = body["flight"], _int(body["seq"], "seq")
            latency = body["latency_s"]
            bodies = {}
            for item in body["bodies"]:
                name = item["name"]
                if not isinstance(name, str) or not name:
                    raise ValueError("body name: expected text")
                bodies[name] = RigidBodyPose(
                    name,
                    _int(item["id"], "id"),
                    _vec3(item["position"], "position"),
                    _quat(item["quaternion"], "quaternion"),
                    bool(item["valid"]),
                    _number(item["marker_error"], "marker_error"),
                )
            frame = MocapFrame(
                _int(body["frame_number"], "frame_number"),
                _number(body["capture_time_s"], "capture_time_s"),
                receive_time_s,
                None if latency is None else _number(latency, "latency_s"),
                bodies,
            )
            relay_ns = _int(body["relay_receive_ns"], "relay_receive_ns")
        except KeyError as err:
            return Verdict(None, f"malformed mocap frame (no {err.args[0]!r})", malformed=True)
        except (ValueError, TypeError) as err:
            return Verdict(None, f"malformed mocap frame ({err})", malformed=True)
        if flight != self._flight:
            return Verdict(None, f"mocap frame of flight {flight!r} refused")
        if seq <= self.last_seq:
            return Verdict(None, f"replayed mocap frame (sequence {seq} after {self.last_seq})")
        self.last_seq = seq
        return Verdict(frame, relay_receive_ns=relay_ns)
