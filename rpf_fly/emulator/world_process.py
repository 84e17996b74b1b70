"""The dry run's simulated drones and Motive emulator in a process of their own.

Why: a real flight's process holds the flight loop, the NatNet client, cflib with its radio driver and the log
writer; the drones and Motive are other machines. In a dry run the simulated firmwares (stepped at 100 Hz, about
0.4 ms of Python for 10 drones), the packet handling of every radio transaction and the NatNet emulator would
otherwise run on threads of the flight's process and hold its GIL at random moments, delaying setpoints in a way
no real flight sees. So the dry run starts them here, in a child process, and reaches them over 127.0.0.1 (a
distributed flight's coordinator: over the address it listens on, so workers on other hosts reach them too):

- the radio: each fake link (``fake_radio.FakeLink``, in the flight's process, emulating cflib's Crazyradio driver
  thread) performs each transaction as one UDP request to the child and waits for its reply, as the real driver
  waits on the USB dongle; lost attempts, unreachable drones and the firmware's answers are decided in the child;
- the mocap: the child runs the NatNet server emulator, which the flight's NatNet client receives as from Motive;
- the fault hooks and firmware snapshots of tests and demos, and the truth samples of the dry run's log
  (:meth:`WorldProcess.truth_samples`, fetched in batches: rpf_fly/flight/truth.py), go over a
  `multiprocessing.connection` to 127.0.0.1 (:class:`WorldProcess`).

The child ignores SIGINT (a Ctrl-C in a terminal reaches the whole process group: the drones must stay up while
the flight lands them) and exits when the parent closes it (`WorldProcess.close`: at once, the parent landed the
drones). When the parent dies without closing it (SIGKILL, a crash), the control connection reaches its end (the
kernel closes a dead process's sockets) or the parent pid changes (the child was re-parented); the drones are
then where real ones would be: no ground station, no more setpoints. The child keeps simulating them in real time
until every drone's motors are off and it rests on the floor (a streaming drone: levels out 0.5 s after its last
setpoint, motors cut at 2 s, falls; a drone flying a high-level plan flies it on, as the firmware does, and hovers
at its end), at most `ORPHAN_CAP_S`, writes an exit report (JSON, `exit_report`) and exits.

Radio wire format, little-endian: request ``op u8, seq u32, address u64, channel u8, flags u8`` then, for a
transaction with an uplink packet (flags bit 0), the CRTP header byte and payload; reply ``seq u32, ok u8, retry
u8, more u8, down u8`` then, when ``down``, port u8, channel u8 and the payload. ``more``: the drone still has
downlink packets queued (the link polls again at once). An ``open`` reply carries ``latency_s f64, rssi i32``.
"""

from __future__ import annotations

import json
import logging
import math
import os
import pickle
import queue
import random
import secrets
import select
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Mapping, Sequence
from multiprocessing.connection import Client, Listener
from typing import Any, Optional

from rpf_fly.mission.model import Obstacle

from .fake_firmware import FirmwareSnapshot, Packet
from .host_lag import HostLag, ahead_of_the_ground_station, host_lag
from .mocap_noise import MocapNoise, turned
from .fake_world import DongleAir, DronePort, FakeDroneConfig, FakeWorld, LinkFaults, RadioCounters, RadioTiming, TruthSample

logger = logging.getLogger(__name__)

OPEN, TRANSACT, CLOSE, BROADCAST = 1, 2, 3, 4
"""Requests of a fake link to the child; BROADCAST (a packed extpos: no acknowledgement) carries its copies in the
flags byte and reaches every drone (`FakeWorld.broadcast`)."""
_REQUEST = struct.Struct("<BIQBB")
_REPLY = struct.Struct("<IBBBB")
_INFO = struct.Struct("<di")
REPLY_TIMEOUT_S = 0.5
"""A transaction whose reply has not come back by then is a lost ack. A loopback round trip takes well under 1 ms;
the margin is for a loaded machine, because a reply given up on is lost with the downlink packet it carried (the
real radio's safelink loses none). A child that died fails at once instead: the closed port answers the connected
socket with ECONNREFUSED."""
START_TIMEOUT_S = 60.0
ORPHAN_CAP_S = 10.0
"""The longest the child simulates its drones after its parent died without closing it: the firmware's watchdog
cuts a streaming drone's motors 2 s after its last setpoint and a fall from 3 m takes 0.8 s, so every streaming
drone lies on the floor well within it; a drone flying a high-level plan hovers on (the firmware's high-level
commander has no watchdog) and would never come down: the cap bounds how long an orphaned process lingers."""
PARENT_POLL_S = 0.1
"""How often the child checks that its parent is still the process that started it (a death the control
connection did not show: while the child still waits for the parent to connect)."""
ORPHAN_POLL_S = 0.05
"""How often an orphaned child reads the world's truth samples to see whether every drone is down (the samples
carry each step's time, so the report's figures have the world step's resolution, not this one's)."""
ORPHAN_KILL_MARGIN_S = 5.0
"""Beyond the cap, a last timer ends the child whatever it is doing (a report write blocked on a full disk or
pipe): an orphan must never linger."""

Pose = tuple[tuple[float, float, float], tuple[float, float, float, float], bool]
TruePoses = dict[int, tuple[tuple[float, float, float], tuple[float, float, float, float]]]

MOCAP_HISTORY_S = 2.0
"""Seconds of true poses `SimulatedBodies` keeps for `mocap_delay` (the longest delay it can serve)."""


class SimulatedBodies:
    """The drones' true poses as the mocap sees them, keyed by rigid-body name, with tracking faults: a body hidden
    for a while (occlusion), every body lost (blackout), a body reported in the wrong place (pose jump) or turned
    (orientation flip), every pose late (mocap delay). Durations are seconds from the call, on
    `time.monotonic()`. Thread-safe.

    Every pose served carries the jitter and the single-frame dropouts of a real mocap (`noise`, default
    `MocapNoise.default()`: rpf_fly/emulator/mocap_noise.py), seeded by ``seed``."""

    def __init__(self, world: FakeWorld, bodies: Mapping[int, str], noise: Optional[MocapNoise] = None,
                 seed: int = 0) -> None:
        self._world = world
        self._noise = MocapNoise.default() if noise is None else noise
        self._rng = random.Random(f"mocap-noise-{seed}")
        self._bodies = dict(bodies)  # radio address -> rigid-body name
        self._hidden: dict[str, float] = {}
        self._blackout_until = -math.inf
        self._jumps: dict[str, tuple[tuple[float, float, float], float]] = {}
        self._flips: dict[str, tuple[tuple[float, float, float, float], float]] = {}
        self._delay: tuple[float, float] | None = None  # (delay_s, until)
        self._history: deque[tuple[float, TruePoses]] = deque()
        self._lock = threading.Lock()

    def poses(self) -> dict[str, Pose]:
        """Each body's pose as this frame reports it: the true pose (or the one `mocap_delay` ago), plus a pose
        jump's offset, tracked unless hidden or blacked out."""
        now = time.monotonic()
        true = self._world.true_poses()
        with self._lock:
            served = self._served(now, true)
            blackout = now < self._blackout_until
            hidden = {name for name, until in self._hidden.items() if now < until}
            jumps = {name: offset for name, (offset, until) in self._jumps.items() if now < until}
            flips = {name: turn for name, (turn, until) in self._flips.items() if now < until}
        poses: dict[str, Pose] = {}
        for address, name in self._bodies.items():
            position, quaternion = served[address]
            jump = jumps.get(name)
            if jump is not None:
                position = (position[0] + jump[0], position[1] + jump[1], position[2] + jump[2])
            flip = flips.get(name)
            if flip is not None:
                quaternion = turned(flip, quaternion)
            position, quaternion, tracked = self._noise.apply(self._rng, position, quaternion)
            poses[name] = (position, quaternion, tracked and not blackout and name not in hidden)
        return poses

    def _served(self, now: float, true: TruePoses) -> TruePoses:
        """Record ``true`` in the history and return the poses this frame serves (call with the lock held)."""
        history = self._history
        history.append((now, true))
        while len(history) > 1 and history[1][0] <= now - MOCAP_HISTORY_S:
            history.popleft()
        if self._delay is None:
            return true
        delay_s, until = self._delay
        if now >= until:
            self._delay = None
            return true
        cutoff = now - delay_s
        served = history[0][1]  # younger than the delay only right after the world started: the oldest there is
        for stamp, poses in history:
            if stamp > cutoff:
                break
            served = poses
        return served

    def extra_latency_s(self) -> float:
        """How much older than the truth the served poses are now (``mocap_delay``; 0 without one)."""
        with self._lock:
            delay = self._delay
        return delay[0] if delay is not None and time.monotonic() < delay[1] else 0.0

    def hide(self, body: str, seconds: float) -> None:
        """Report ``body`` as not tracked for ``seconds`` (occlusion)."""
        with self._lock:
            self._hidden[body] = time.monotonic() + seconds

    def blackout(self, seconds: float) -> None:
        """Report every body as not tracked for ``seconds`` (mocap lost)."""
        with self._lock:
            self._blackout_until = time.monotonic() + seconds

    def pose_jump(self, body: str, offset_m: tuple[float, float, float], seconds: float) -> None:
        """Report ``body`` ``offset_m`` metres from where it is for ``seconds``, as tracked (valid): a marker swap
        or a wrong fit of the rigid-body model. The drone itself does not move; a flight that sends this pose as
        extpos moves it the other way."""
        offset = (float(offset_m[0]), float(offset_m[1]), float(offset_m[2]))
        with self._lock:
            self._jumps[body] = (offset, time.monotonic() + seconds)

    def orientation_flip(self, body: str, deg: float, seconds: float) -> None:
        """Report ``body`` turned by ``deg`` about the vertical for ``seconds``, as tracked (valid), where it is: the
        wrong fit Motive makes of a nearly symmetric marker set. The drone itself does not turn; a flight that
        sends this orientation as extpose turns its yaw estimate, and its position controller then flies it off."""
        half = math.radians(float(deg)) / 2.0
        with self._lock:
            self._flips[body] = ((0.0, 0.0, math.sin(half), math.cos(half)), time.monotonic() + seconds)

    def mocap_delay(self, delay_s: float, seconds: float) -> None:
        """For ``seconds`` every frame carries poses ``delay_s`` old (at most `MOCAP_HISTORY_S`): latency (a
        loaded Motive host or network), not a frame-rate drop, so frames keep coming at the rate and the frame's
        own latency figure does not show it. The poses served are the ones recorded at earlier frames (the
        resolution is the frame period)."""
        if not 0.0 <= delay_s <= MOCAP_HISTORY_S:
            raise ValueError(f"delay_s must be in [0, {MOCAP_HISTORY_S:g}], not {delay_s}")
        with self._lock:
            self._delay = (float(delay_s), time.monotonic() + seconds)


# ------------------------------------------------------------------------------------------ flight's process


class RemotePort:
    """A drone of the child's world, reached over UDP (the fake link's `DronePort`). Thread-safe."""

    def __init__(self, server: tuple[str, int], address: int, timing: RadioTiming) -> None:
        self._address = address
        self._retries = timing.arc_retries
        self._lock = threading.Lock()
        self._seq = 0
        self._more = False
        self._open = False
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.connect(server)
        self._sock.settimeout(REPLY_TIMEOUT_S)
        reply = self._call(OPEN, 0, b"")
        if reply is None or not reply[1]:
            self._sock.close()
            raise LookupError(f"no simulated drone at address {address:010X}")
        self._open = True
        latency_s, rssi = _INFO.unpack_from(reply[5])
        self.faults = LinkFaults(latency_s=latency_s)
        self.rssi_dbm = rssi

    def _call(self, op: int, channel: int, body: bytes) -> Optional[tuple[int, int, int, int, int, bytes]]:
        with self._lock:
            self._seq = (self._seq + 1) & 0xFFFFFFFF
            seq = self._seq
            try:
                self._sock.send(_REQUEST.pack(op, seq, self._address, channel, 1 if body else 0) + body)
                while True:
                    data = self._sock.recv(2048)
                    if len(data) >= _REPLY.size and _REPLY.unpack_from(data)[0] == seq:
                        return (*_REPLY.unpack_from(data), data[_REPLY.size:])  # type: ignore[return-value]
            except OSError:  # timeout (a lost ack), or the drones' process is gone
                return None

    def transact(self, channel: int, uplink: tuple[int, bytes] | None) -> tuple[bool, int, Packet | None]:
        body = b"" if uplink is None else bytes((uplink[0],)) + uplink[1]
        reply = self._call(TRANSACT, channel, body)
        if reply is None:
            return False, self._retries, None
        _, ok, retry, more, has_down, rest = reply
        self._more = bool(more)
        down = (rest[0], rest[1], bytes(rest[2:])) if has_down else None
        return bool(ok), retry, down

    def has_downlink(self) -> bool:
        return self._more

    def attach(self, waker: threading.Event) -> None:
        """Attached at open (the child queues downlink packets only while a link is open); polls find them."""

    def detach(self, waker: threading.Event) -> None:
        if self._open:
            self._open = False
            self._call(CLOSE, 0, b"")
            self._sock.close()


class RemoteWorld:
    """What the fake radio needs of a world (`fake_radio.RadioWorld`) for the drones of a child process."""

    def __init__(self, radio: tuple[str, int], addresses: tuple[int, ...], timing: RadioTiming | None = None) -> None:
        self._radio = radio
        self._addresses = tuple(addresses)
        self.timing = timing or RadioTiming()
        self._dongles: dict[int, DongleAir] = {}
        self._lock = threading.Lock()
        self._sock: Optional[socket.socket] = None
        self._seq = 0

    @property
    def addresses(self) -> tuple[int, ...]:
        return self._addresses

    def start(self) -> RemoteWorld:
        return self  # the child started its world before it reported ready

    def port(self, address: int) -> RemotePort | None:
        if address not in self._addresses:
            return None
        try:
            return RemotePort(self._radio, address, self.timing)
        except LookupError:
            return None

    def dongle(self, devid: int) -> DongleAir:
        with self._lock:
            return self._dongles.setdefault(devid, DongleAir())

    def uri(self, address: int) -> str:
        return f"fake://0/80/2M/{address:010X}"

    def broadcast(self, channel: int, uplink: tuple[int, bytes], copies: int) -> bool:
        """`FakeWorld.broadcast` in the child: one request, answered once its drones have heard it (False when the
        child did not answer in time)."""
        with self._lock:
            if self._sock is None:
                self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                self._sock.connect(self._radio)
                self._sock.settimeout(REPLY_TIMEOUT_S)
            self._seq = (self._seq + 1) & 0xFFFFFFFF
            try:
                request = _REQUEST.pack(BROADCAST, self._seq, 0, channel, copies)
                self._sock.send(request + bytes((uplink[0],)) + uplink[1])
                while True:
                    data = self._sock.recv(2048)
                    if len(data) >= _REPLY.size and _REPLY.unpack_from(data)[0] == self._seq:
                        return True
            except OSError:
                return False


class WorldCalls:
    """The fault hooks and snapshots of a simulated world reached over a control connection, by the names of
    `FakeWorld`'s and `SimulatedBodies`'s methods: `WorldProcess` (a dry run's private world) and
    `rpf_fly.flight.lab.LabClient` (a running lab's)."""

    def call(self, method: str, *args: Any) -> Any:
        raise NotImplementedError

    def drop_link(self, address: int) -> None:
        self.call("drop_link", address)

    def restore_link(self, address: int) -> None:
        self.call("restore_link", address)

    def disturb(self, address: int, offset_m: tuple[float, float, float]) -> None:
        self.call("disturb", address, offset_m)

    def set_battery(self, address: int, open_circuit_v: float) -> None:
        self.call("set_battery", address, open_circuit_v)

    def reboot(self, address: int) -> None:
        self.call("reboot", address)

    def packet_loss(self, address: int, rate: float, seconds: float) -> None:
        self.call("packet_loss", address, rate, seconds)

    def gust(self, address: int, accel_m_s2: tuple[float, float, float], seconds: float) -> None:
        self.call("gust", address, accel_m_s2, seconds)

    def estimator_divergence(self, address: int, rate_m_s: float) -> None:
        self.call("estimator_divergence", address, rate_m_s)

    def radio_counters(self, address: int) -> RadioCounters:
        return self.call("radio_counters", address)

    def radio_bursts(self, address: int, start_s: float, end_s: float) -> list[tuple[float, float]]:
        return self.call("radio_bursts", address, start_s, end_s)

    def host_lag(self) -> HostLag:
        """How far the host let the simulated world fall behind its own time (`rpf_fly.emulator.host_lag`)."""
        return self.call("host_lag")

    def time_s(self) -> float:
        """The child world's clock (seconds since it started)."""
        return self.call("time_s")

    def snapshot(self, address: int) -> FirmwareSnapshot:
        return self.call("snapshot", address)

    def true_poses(self) -> dict[int, tuple[tuple[float, float, float], tuple[float, float, float, float]]]:
        return self.call("true_poses")

    def truth_samples(self) -> list[TruthSample]:
        """The world's truth samples since the previous call (`FakeWorld.truth_samples`): one round trip."""
        return self.call("truth_samples")

    def poses(self) -> dict[str, Pose]:
        """The bodies as the mocap sees them (`SimulatedBodies.poses`)."""
        return self.call("poses")

    def hide(self, body: str, seconds: float) -> None:
        self.call("hide", body, seconds)

    def blackout(self, seconds: float) -> None:
        self.call("blackout", seconds)

    def pose_jump(self, body: str, offset_m: tuple[float, float, float], seconds: float) -> None:
        self.call("pose_jump", body, offset_m, seconds)

    def orientation_flip(self, body: str, deg: float, seconds: float) -> None:
        self.call("orientation_flip", body, deg, seconds)

    def mocap_delay(self, delay_s: float, seconds: float) -> None:
        self.call("mocap_delay", delay_s, seconds)



class WorldProcess(WorldCalls):
    """Starts the child process and speaks to it: the fault hooks and snapshots of `FakeWorld` and
    `SimulatedBodies`, by the same names. ``natnet``: the NatNet server's settings (``version``, ``rate_hz``,
    ``up_axis``, optionally ``multicast``), None for no NatNet server. ``obstacles``: the mission's obstacles, for
    the world's contacts.

    The child is ``python -m rpf_fly.emulator.world_process``, not a multiprocessing spawn (which re-imports the
    caller's main script: a user's unguarded script would run again in it). It reads its settings as one pickle on
    stdin, answers with one JSON line on stdout (its ports), then serves calls on a `multiprocessing.connection`
    to 127.0.0.1, authenticated with a random key."""

    def __init__(
        self,
        drones: Mapping[int, FakeDroneConfig],
        bodies: Mapping[int, str],
        *,
        seed: int = 0,
        natnet: Optional[Mapping[str, Any]] = None,
        obstacles: Sequence[Obstacle] = (),
        names: Optional[Mapping[int, str]] = None,
        exit_report: Optional[str | os.PathLike[str]] = None,
        orphan_cap_s: float = ORPHAN_CAP_S,
        host: str = "127.0.0.1",
        mocap_noise: Optional[MocapNoise] = None,
    ) -> None:
        """``names``: the drones' names (radio address -> name) for the exit report (else their addresses).
        ``exit_report``: where the child writes its exit report if this process dies without closing it (None:
        no report); ``orphan_cap_s``: how long it simulates the drones at most then (`ORPHAN_CAP_S`). ``host``: the
        IPv4 address its radio server and NatNet server bind (default loopback; a distributed flight's coordinator
        gives its Zenoh listen address, so workers on other hosts reach the drones: docs/distributed.md); the
        control connection stays on loopback."""
        self._lock = threading.Lock()
        self._conn: Any = None
        key = secrets.token_bytes(32)
        settings = {"drones": dict(drones), "bodies": dict(bodies), "seed": seed, "obstacles": tuple(obstacles),
                    "natnet": dict(natnet) if natnet else None, "authkey": key, "names": dict(names or {}),
                    "exit_report": os.fspath(exit_report) if exit_report is not None else None,
                    "orphan_cap_s": float(orphan_cap_s), "host": host,
                    "mocap_noise": MocapNoise.default() if mocap_noise is None else mocap_noise}
        self._process = subprocess.Popen(
            [sys.executable, "-m", "rpf_fly.emulator.world_process"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
        )
        try:
            assert self._process.stdin is not None and self._process.stdout is not None
            self._process.stdin.write(pickle.dumps(settings))
            self._process.stdin.close()
            line = _read_line(self._process.stdout, START_TIMEOUT_S)
            if line is None:
                raise RuntimeError(f"the simulated drones' process did not start within {START_TIMEOUT_S:g} s")
            ready = json.loads(line)
            if "error" in ready:
                raise RuntimeError(f"the simulated drones' process failed to start: {ready['error']}")
            self._conn = Client(tuple(ready["control"]), authkey=key)
        except BaseException:
            self.close()
            raise
        self.pid: int = self._process.pid
        """The child's process id (a test watches it outlive a killed parent)."""
        self.radio: tuple[str, int] = (ready["radio"][0], ready["radio"][1])
        self.natnet_command_port: Optional[int] = ready["natnet_command_port"]
        self.addresses: tuple[int, ...] = tuple(drones)

    def call(self, method: str, *args: Any) -> Any:
        with self._lock:
            if self._conn is None:
                raise RuntimeError(f"simulated drones: {method} after close")
            self._conn.send((method, args))
            status, value = self._conn.recv()
        if status != "ok":
            raise RuntimeError(f"simulated drones: {method} failed: {value}")
        return value

    def close(self) -> None:
        """Stop the child (its world powers the drones off) and wait for it; idempotent."""
        if self._conn is not None:
            try:
                self.call("close")
            except (OSError, EOFError, RuntimeError):
                pass
            with self._lock:
                self._conn.close()
                self._conn = None
        try:
            self._process.wait(5.0)
        except subprocess.TimeoutExpired:
            self._process.kill()
            self._process.wait(2.0)
        if self._process.stdout is not None:
            self._process.stdout.close()


def _read_line(stream: Any, timeout_s: float) -> Optional[bytes]:
    """One line from a pipe; None after ``timeout_s`` or at its end (a thread: portable, unlike select on pipes)."""
    lines: queue.Queue[bytes] = queue.Queue()
    threading.Thread(target=lambda: lines.put(stream.readline()), daemon=True).start()
    try:
        line = lines.get(timeout=timeout_s)
    except queue.Empty:
        return None
    return line or None


# ------------------------------------------------------------------------------------------------ child


class _RadioServer:
    """The child's end of the fake links: one UDP socket, one thread, every link's transactions in turn."""

    def __init__(self, world: FakeWorld, host: str = "127.0.0.1") -> None:
        self._world = world
        self._ports: dict[int, DronePort | None] = {}
        self._wakers: dict[tuple[Any, int], threading.Event] = {}
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, 0))
        self._thread = threading.Thread(target=self._run, name="fake-radio-server", daemon=True)

    def start(self) -> _RadioServer:
        self._thread.start()
        return self

    def close(self) -> None:
        self.sock.close()

    def _port(self, address: int) -> DronePort | None:
        if address not in self._ports:
            self._ports[address] = self._world.port(address)
        return self._ports[address]

    def _run(self) -> None:
        while True:
            try:
                data, peer = self.sock.recvfrom(2048)
            except OSError:
                return  # closed
            try:
                reply = self._handle(data, peer)
            except Exception:  # noqa: BLE001 - a bad request loses one transaction, never the radio
                logger.exception("fake radio server: bad request")
                continue
            try:
                self.sock.sendto(reply, peer)
            except OSError:
                pass

    def _handle(self, data: bytes, peer: Any) -> bytes:
        op, seq, address, channel, flags = _REQUEST.unpack_from(data)
        if op == BROADCAST:
            body = data[_REQUEST.size:]
            self._world.broadcast(channel, (body[0], bytes(body[1:])), flags)
            return _REPLY.pack(seq, 1, 0, 0, 0)
        port = self._port(address)
        if op == OPEN:
            if port is None:
                return _REPLY.pack(seq, 0, 0, 0, 0)
            port.attach(self._wakers.setdefault((peer, address), threading.Event()))
            return _REPLY.pack(seq, 1, 0, 0, 0) + _INFO.pack(port.faults.latency_s, port.rssi_dbm)
        if op == CLOSE:
            waker = self._wakers.pop((peer, address), None)
            if port is not None and waker is not None:
                port.detach(waker)
            return _REPLY.pack(seq, 1, 0, 0, 0)
        if port is None:
            return _REPLY.pack(seq, 0, self._world.timing.arc_retries, 0, 0)
        body = data[_REQUEST.size:]
        uplink = (body[0], bytes(body[1:])) if flags & 1 else None
        ok, retry, down = port.transact(channel, uplink)
        more = port.has_downlink()
        if down is None:
            return _REPLY.pack(seq, ok, retry, more, 0)
        return _REPLY.pack(seq, ok, retry, more, 1) + bytes((down[0] & 0xFF, down[1] & 0xFF)) + bytes(down[2])


class _Orphan:
    """What the child does once its parent died without closing it (module doc): simulate on until every drone is
    down or `ORPHAN_CAP_S` passed, then write the exit report. The first caller (the control connection's end, or
    the parent watch) runs it; a second one waits until it is done."""

    def __init__(self, world: FakeWorld, parent_pid: int, names: Mapping[int, str], report: Optional[str],
                 cap_s: float) -> None:
        self._world = world
        self._parent_pid = parent_pid
        self._names = dict(names)
        self._report = report
        self._cap_s = cap_s
        self._lock = threading.Lock()
        self._started = False
        self._done = threading.Event()

    def watch_parent(self) -> None:
        """Start the thread that notices a parent that is gone before the control connection says so."""
        threading.Thread(target=self._watch, name="parent-watch", daemon=True).start()

    def _watch(self) -> None:
        while os.getppid() == self._parent_pid:
            time.sleep(PARENT_POLL_S)
        if self.run("the parent process is gone (the child was re-parented)"):
            os._exit(0)  # the main thread may still wait for the parent to connect: nothing else ends it

    def closing(self) -> None:
        """The parent closes the child (it landed the drones): no orphan from now on, whatever the parent does."""
        with self._lock:
            self._started = True
        self._done.set()

    def run(self, how: str) -> bool:
        """Simulate the drones down and write the report; False if another caller already did (after waiting)."""
        with self._lock:
            first, self._started = not self._started, True
        if not first:
            self._done.wait()
            return False
        try:
            last_resort = threading.Timer(self._cap_s + ORPHAN_KILL_MARGIN_S, os._exit, (3,))
            last_resort.daemon = True  # never what keeps the process up
            last_resort.start()
            report = self._fall(how)
            self._write(report)
        finally:
            self._done.set()
        return True

    def _fall(self, how: str) -> dict[str, Any]:
        """Follow every world step (the world's truth samples: motors and true height at each 10 ms step, whenever
        this thread gets to read them) until every drone's motors are off and it rests on its floor, or the cap;
        what each drone did, in seconds from the parent's death."""
        world = self._world
        world.truth_samples()  # the parent's log no longer takes them: from now on they are this report's
        dead_at, dead_world_s = time.monotonic(), world.time_s()
        addresses = world.addresses
        at_death = {a: world.snapshot(a) for a in addresses}
        floors = {a: world.firmware(a).vehicle.floor_z for a in addresses}
        motors_off = {a: 0.0 for a in addresses if not at_death[a].motors_on}
        cut_z = {a: at_death[a].position[2] for a in motors_off}
        at_rest = {a: 0.0 for a in addresses if not world.firmware(a).body().airborne}
        while True:
            for stamp, states in world.truth_samples():
                after = max(0.0, stamp - dead_at)
                for address, (position, _yaw, motors, _crashed, _estimate) in states.items():
                    if address not in floors:
                        continue
                    if motors:
                        motors_off.pop(address, None)  # spinning again (a high-level plan): not off yet
                    elif address not in motors_off:
                        motors_off[address], cut_z[address] = after, position[2]
                    if motors or position[2] > floors[address] + 1e-6:
                        at_rest.pop(address, None)
                    else:
                        at_rest.setdefault(address, after)
            elapsed = time.monotonic() - dead_at
            down = len(at_rest) == len(addresses)
            if down or elapsed >= self._cap_s:
                break
            time.sleep(ORPHAN_POLL_S)
        drones = {}
        for address in addresses:
            snap, before = world.snapshot(address), at_death[address]
            setpoint = before.last_crtp_setpoint_s
            drones[self._names.get(address, f"{address:010X}")] = {
                "address": f"{address:010X}",
                "position": list(snap.position),
                "z": snap.position[2],
                "floor_z": floors[address],
                "motors_on": snap.motors_on,
                "at_rest": address in at_rest,
                "crashed": snap.crashed,
                "supervisor_state": snap.supervisor_state,
                "locked": snap.locked,
                "flying": snap.flying,
                "control_source": snap.control_source,
                "hl_state": snap.hl_state,
                "motors_on_at_death": before.motors_on,
                "z_at_death": before.position[2],
                "control_source_at_death": before.control_source,
                "setpoint_age_at_death_s": None if setpoint is None else dead_world_s - setpoint,
                "motors_off_after_s": motors_off.get(address),
                "z_at_motors_off": cut_z.get(address),
                "at_rest_after_s": at_rest.get(address),
            }
        return {
            "what": "the simulated drones after the flight's process died without closing the dry run",
            "detected_by": how,
            "parent_pid": self._parent_pid,
            "world_pid": os.getpid(),
            "parent_death_monotonic_s": dead_at,
            "parent_death_world_s": dead_world_s,
            "cap_s": self._cap_s,
            "capped": not down,
            "elapsed_s": elapsed,
            "all_down": down,
            "drones": drones,
        }

    def _write(self, report: dict[str, Any]) -> None:
        """Write the report whole (a reader never sees half of it), then tell the terminal in one line: only if
        stderr can take it at once, as nobody may read that pipe any more."""
        where = "no report path given"
        if self._report is not None:
            partial = f"{self._report}.partial"
            try:
                with open(partial, "w", encoding="utf-8") as f:
                    json.dump(report, f, indent=2)
                    f.write("\n")
                os.replace(partial, self._report)
                where = f"report {self._report}"
            except OSError as err:
                where = f"report not written: {err}"
        down = sum(d["at_rest"] for d in report["drones"].values())
        line = (f"rpf-fly dry run: the flight's process died; {down} of {len(report['drones'])} simulated drones "
                f"down after {report['elapsed_s']:.1f} s ({where})\n")
        try:
            if select.select([], [2], [], 0.5)[1]:
                os.write(2, line.encode()[:4096])  # a pipe that polls writable takes 4096 bytes without blocking
        except (OSError, ValueError):
            pass


class WorldServer:
    """The simulated world of a dry run or a lab, with what reaches it from outside: the radio server (UDP), the
    NatNet emulator and the call table of the fault hooks and snapshots (by the names of `WorldProcess`'s methods).
    ``settings``: as `WorldProcess` sends them. The caller serves the calls (`handle`) over its connections."""

    def __init__(self, settings: Mapping[str, Any]) -> None:
        self.world = FakeWorld(settings["drones"], seed=settings["seed"], obstacles=settings.get("obstacles", ()),
                               timing=settings.get("timing")).start()
        self.bodies: dict[int, str] = dict(settings["bodies"])
        self.tracked = SimulatedBodies(self.world, self.bodies, settings.get("mocap_noise"), seed=settings["seed"])
        self.host = settings.get("host", "127.0.0.1")
        self.radio = _RadioServer(self.world, self.host).start()
        self.natnet: Any = None
        natnet = settings.get("natnet")
        if natnet is not None:
            from rpf_fly.emulator.natnet_server import NatNetServer

            self.natnet = NatNetServer(
                self.tracked.poses, version=natnet["version"], multicast=natnet.get("multicast", False),
                local_ip=self.host, rate_hz=natnet["rate_hz"], up_axis=natnet["up_axis"],
                bodies=list(self.bodies.values()), extra_latency_s=self.tracked.extra_latency_s,
            ).start()
        world, tracked = self.world, self.tracked
        self.calls: dict[str, Any] = {
            "drop_link": world.drop_link, "restore_link": world.restore_link, "disturb": world.disturb,
            "set_battery": world.set_battery, "reboot": world.reboot, "snapshot": world.snapshot,
            "true_poses": world.true_poses, "truth_samples": world.truth_samples, "poses": tracked.poses,
            "hide": tracked.hide,
            "blackout": tracked.blackout,
            # fault hooks of a campaign (same names and arguments as on FakeWorld and SimulatedBodies)
            "packet_loss": world.packet_loss, "gust": world.gust, "estimator_divergence": world.estimator_divergence,
            "radio_counters": world.radio_counters, "radio_bursts": world.radio_bursts, "time_s": world.time_s,
            "pose_jump": tracked.pose_jump, "orientation_flip": tracked.orientation_flip,
            "mocap_delay": tracked.mocap_delay, "host_lag": self.host_lag,
        }

    def host_lag(self) -> HostLag:
        """How far the host let this world fall behind its own time so far (`HostLag`)."""
        return host_lag(self.world.lag, self.natnet.lag if self.natnet is not None else None)

    def ports(self) -> dict[str, Any]:
        """Where the world is reached: the radio server's UDP address and the NatNet emulator's command port."""
        return {"radio": list(self.radio.sock.getsockname()),
                "natnet_command_port": self.natnet.command_port if self.natnet is not None else None}

    def handle(self, method: str, args: Sequence[Any]) -> tuple[str, Any]:
        """One call: ``("ok", value)`` or ``("error", "Type: message")`` (the caller stays up)."""
        try:
            return "ok", self.calls[method](*args)
        except Exception as err:  # noqa: BLE001 - reported to the caller
            return "error", f"{type(err).__name__}: {err}"

    def close(self) -> None:
        if self.natnet is not None:
            self.natnet.close()
        self.world.close()
        self.radio.close()


def serve(settings: dict[str, Any], out: Any) -> None:
    """The child process: world, radio server, NatNet server; reports its ports as one JSON line on ``out``, then
    answers the parent's calls until it closes them, or until it goes away (then `_Orphan`)."""
    server = WorldServer(settings)
    orphan = _Orphan(server.world, os.getppid(), settings.get("names", {}), settings.get("exit_report"),
                     settings.get("orphan_cap_s", ORPHAN_CAP_S))
    orphan.watch_parent()
    try:
        with Listener(("127.0.0.1", 0), authkey=settings["authkey"]) as listener:
            out.write(json.dumps({"control": list(listener.address), **server.ports()}) + "\n")
            out.flush()
            conn = listener.accept()
        with conn:
            while True:
                try:
                    method, args = conn.recv()
                except (EOFError, OSError):
                    orphan.run("the control connection closed without a close call")
                    return  # the parent is gone
                if method == "close":
                    orphan.closing()
                    conn.send(("ok", None))
                    return
                conn.send(server.handle(method, args))
    finally:
        server.close()


def main() -> None:
    """``python -m rpf_fly.emulator.world_process``: settings as one pickle on stdin (from `WorldProcess` only)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a Ctrl-C reaches the whole process group: the parent lands first
    ahead_of_the_ground_station()
    out = sys.stdout
    sys.stdout = sys.stderr  # nothing else may write on the parent's pipe
    try:
        settings = pickle.loads(sys.stdin.buffer.read())
        serve(settings, out)
    except Exception as err:  # noqa: BLE001 - tell the parent (it waits for this line at startup)
        logger.exception("simulated drones failed")
        try:
            out.write(json.dumps({"error": f"{type(err).__name__}: {err}"}) + "\n")
            out.flush()
        except (OSError, ValueError):
            pass


if __name__ == "__main__":
    main()
