"""A simulated mocap source: poses from a callable, with noise, latency, a frame rate and dropouts.

It implements :class:`~rpf_fly.mocap.frame.MocapSource` without threads or sockets, for simulation and
``fly --dry-run``. Frames exist on a fixed grid ``t_k = t_0 + k / rate_hz`` of the injected monotonic clock; a
frame becomes visible ``latency_s`` after it was sampled. Because nothing runs between calls, ``poses()`` is
sampled when ``receive()`` runs (at most once per frame slot) and a sample is delivered once it is ``latency_s``
old: the effective latency is ``latency_s`` rounded up to the caller's polling period, which is what a flight loop
polling a real source at its own rate sees too. ``poses()`` is only ever called from the caller's thread.

Noise: zero-mean Gaussian with standard deviation ``noise_m`` (metres) on each position axis and ``noise_rad``
(radians) on a random small rotation, from a seeded :class:`numpy.random.Generator`. Dropouts: each body of each
frame is independently reported as not tracked (``valid=False``) with probability ``dropout``; a dropped body
repeats its last delivered pose (or the origin with the identity orientation if it never had one), like a lost
rigid body in Motive, so code that ignores ``valid`` flies on stale data rather than on the truth.
"""

from __future__ import annotations

import collections
import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from types import TracebackType

import numpy as np

from rpf_fly.mocap.frame import MocapFrame, MocapStats, PoseCallable, RigidBodyPose

__all__ = ["SimulatedMocap"]


def _quat_multiply(a: Sequence[float], b: Sequence[float]) -> tuple[float, float, float, float]:
    """Hamilton product a * b of (x, y, z, w) quaternions."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def _rotation_quat(rotation_vector: Sequence[float] | np.ndarray) -> tuple[float, float, float, float]:
    """Quaternion (x, y, z, w) of a rotation vector (axis * angle, radians)."""
    rx, ry, rz = rotation_vector
    angle = math.sqrt(rx * rx + ry * ry + rz * rz)
    if angle < 1e-12:
        return (0.5 * rx, 0.5 * ry, 0.5 * rz, 1.0)
    s = math.sin(0.5 * angle) / angle
    return (rx * s, ry * s, rz * s, math.cos(0.5 * angle))


class SimulatedMocap:
    """Mocap frames from ``poses()`` on a fixed-rate grid, with seeded noise, latency and dropouts.

    Args:
        poses: returns ``{name: (position_xyz, quaternion_xyzw, valid)}`` in the Z-up world frame (metres).
        rate_hz: frame rate (frames per second).
        noise_m: standard deviation of the Gaussian position noise per axis, metres.
        noise_rad: standard deviation of the Gaussian orientation noise per axis, radians.
        latency_s: delay between sampling a frame and delivering it, seconds.
        dropout: probability that a body is reported as not tracked in a frame.
        seed: seed of the noise and dropout generator.
        clock: monotonic clock in seconds (injectable for deterministic tests).
        sleep: sleeps the given seconds (injectable with ``clock``).
    """

    def __init__(
        self,
        poses: PoseCallable,
        *,
        rate_hz: float = 120.0,
        noise_m: float = 0.0,
        noise_rad: float = 0.0,
        latency_s: float = 0.0,
        dropout: float = 0.0,
        seed: int = 0,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        if rate_hz <= 0:
            raise ValueError("rate_hz must be positive")
        if noise_m < 0 or noise_rad < 0 or latency_s < 0:
            raise ValueError("noise_m, noise_rad and latency_s must be non-negative")
        if not 0.0 <= dropout <= 1.0:
            raise ValueError("dropout is a probability in [0, 1]")
        self._poses = poses
        self._period = 1.0 / rate_hz
        self._noise_m = noise_m
        self._noise_rad = noise_rad
        self._latency_s = latency_s
        self._dropout = dropout
        self._rng = np.random.default_rng(seed)
        self._clock = clock
        self._sleep = sleep
        self._t0 = clock()
        self._last_slot = -1
        self._last_delivered = -1
        self._queue: collections.deque[tuple[int, float, dict[str, RigidBodyPose]]] = collections.deque()
        self._held: dict[str, RigidBodyPose] = {}
        self._ids: dict[str, int] = {}
        self._stats = MocapStats()
        self._closed = False

    @property
    def stats(self) -> MocapStats:
        """A snapshot of the counters: ``packets``/``frames`` count sampled frames."""
        return dataclasses.replace(self._stats)

    def receive(self, timeout_s: float) -> MocapFrame | None:
        """Newest frame that is at least ``latency_s`` old and newer than the last one returned; None on timeout."""
        if self._closed:
            return None
        deadline = self._clock() + max(0.0, timeout_s)
        while True:
            now = self._clock()
            if self._sample(now):
                now = self._clock()  # poses() may have taken a while (a remote world): stamp after it
            frame = self._pop_ready(now)
            if frame is not None:
                return frame
            wake = self._next_event(now)
            if now >= deadline:
                return None
            self._sleep(max(0.0, min(deadline, wake) - now))

    def close(self) -> None:
        """Stop delivering frames; idempotent."""
        self._closed = True

    def __enter__(self) -> SimulatedMocap:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # ------------------------------------------------------------------------------------------ internals

    def _slot(self, now: float) -> int:
        return int(math.floor((now - self._t0) / self._period + 1e-9))

    def _next_event(self, now: float) -> float:
        """When the next frame is sampled or the oldest queued one becomes deliverable."""
        wake = self._t0 + (self._slot(now) + 1) * self._period
        if self._queue:
            wake = min(wake, self._queue[0][1] + self._latency_s)
        return wake

    def _sample(self, now: float) -> bool:
        """Sample ``poses()`` for the current frame slot if it has not been sampled yet (True if it did). The sample
        is stamped when ``poses()`` returned: a remote world (the dry run's) answers after a loopback round trip,
        which on a loaded machine takes a while, and a stamp taken before the call would make the motion between
        two frames look faster than it was."""
        slot = self._slot(now)
        if slot <= self._last_slot:
            return False
        self._last_slot = slot
        bodies: dict[str, RigidBodyPose] = {}
        poses = self._poses()
        now = self._clock()
        for name, (position, quaternion, valid) in poses.items():
            body_id = self._ids.setdefault(name, len(self._ids) + 1)
            if self._dropout > 0.0 and self._rng.random() < self._dropout:
                valid = False
            if valid:
                bodies[name] = self._noisy(name, body_id, position, quaternion)
            else:
                held = self._held.get(name)
                if held is None:
                    held = RigidBodyPose(name, body_id, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), False, 0.0)
                bodies[name] = dataclasses.replace(held, valid=False)
        self._queue.append((slot, now, bodies))
        self._stats.packets += 1
        self._stats.frames += 1
        return True

    def _noisy(self, name: str, body_id: int, position: Sequence[float], quaternion: Sequence[float]) -> RigidBodyPose:
        x, y, z = (float(v) for v in position)
        qx, qy, qz, qw = (float(v) for v in quaternion)
        q = (qx, qy, qz, qw)
        if self._noise_m > 0.0:
            dx, dy, dz = self._rng.normal(0.0, self._noise_m, 3)
            x, y, z = x + dx, y + dy, z + dz
        if self._noise_rad > 0.0:
            q = _quat_multiply(_rotation_quat(self._rng.normal(0.0, self._noise_rad, 3)), q)
            norm = math.sqrt(sum(c * c for c in q))
            q = (q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm)
        return RigidBodyPose(name, body_id, (x, y, z), q, True, 0.0)

    def _pop_ready(self, now: float) -> MocapFrame | None:
        """Deliver the newest queued frame whose latency has elapsed; older ready ones are superseded."""
        ready = None
        while self._queue and self._queue[0][1] + self._latency_s <= now + 1e-12:
            if ready is not None:
                self._stats.superseded += 1
            ready = self._queue.popleft()
        if ready is None:
            return None
        slot, sampled_at, bodies = ready
        for pose in bodies.values():
            if pose.valid:
                self._held[pose.name] = pose
            else:
                self._stats.body_dropouts += 1
        self._stats.delivered += 1
        self._last_delivered = slot
        return MocapFrame(slot, sampled_at - self._t0, now, now - sampled_at, bodies)
