"""The simulated drones' poses as a dry run's mocap sees them, with a real mocap's jitter and dropouts and the
tracking faults of tests and campaigns (occlusion, blackout, pose jump, orientation flip, latency); the NatNet
emulator serves them (rpf_fly/emulator/world_process.py).
"""

from __future__ import annotations

import math
import random
import threading
import time
from collections import deque
from collections.abc import Mapping

from .fake_world import FakeWorld
from .mocap_noise import MocapNoise, turned

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

    def __init__(
        self, world: FakeWorld, bodies: Mapping[int, str], noise: MocapNoise | None = None, seed: int = 0
    ) -> None:
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
