"""Logged mocap poses served again, at their logged times: ``rpf-fly mocap emulate --replay LOG``.

Why: ``mocap watch``, ``check`` and any NatNet client (a lab's own scripts, Motive's SampleClient) can then be tried
on the mocap of a real flight (its rates, gaps, occlusions and glitches) instead of the emulator's circles. The
frames come from the log (:func:`rpf_fly.log.mocap_frames.mocap_frames`, passed in as plain values: this package
does not read logs), the server is :class:`~rpf_fly.emulator.natnet_server.NatNetServer` with ``rate_hz=0``, and
:meth:`PosePlayback.play` sends frame ``k`` at ``start + (t_k - t_0) / speed``: relative timing kept, frame for
frame. A body missing from a logged frame (untracked then) is streamed as not tracked in it, as Motive does.

What goes over the wire is NatNet's float32: a client reads each logged coordinate rounded to float32 (a dry
run's poses came in as float32, so they come back exactly).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol

Position = tuple[float, float, float]
Quaternion = tuple[float, float, float, float]
PoseSample = tuple[Position, Quaternion, bool]


class FrameSender(Protocol):
    def send_frame(self) -> int: ...


@dataclass
class PosePlayback:
    """Frames ``(seconds, {body: (position, quaternion)})`` (times relative to anything; Z-up world frame) to
    serve in order. :meth:`poses` is the server's pose callable: the frame being sent."""

    frames: Sequence[tuple[float, Mapping[str, tuple[Position, Quaternion]]]]
    speed: float = 1.0
    sent: list[int] = field(default_factory=list)
    """The server's frame number of each logged frame sent, in order."""
    max_late_s: float = 0.0
    """The latest a frame went out after its due time (a busy machine)."""
    _current: int = 0

    def __post_init__(self) -> None:
        if self.speed <= 0:
            raise ValueError(f"playback speed must be positive, not {self.speed}")

    @property
    def bodies(self) -> list[str]:
        """Every body of any frame, in order of first appearance (the streamed set, ids 1, 2, ...)."""
        seen: dict[str, None] = {}
        for _, poses in self.frames:
            seen.update(dict.fromkeys(poses))
        return list(seen)

    @property
    def duration_s(self) -> float:
        """Wall time of the whole playback at :attr:`speed`."""
        return (self.frames[-1][0] - self.frames[0][0]) / self.speed if self.frames else 0.0

    def poses(self) -> dict[str, PoseSample]:
        """The current frame's poses, every body tracked (bodies not in it are streamed untracked)."""
        if not self.frames:
            return {}
        return {name: (p, q, True) for name, (p, q) in self.frames[self._current][1].items()}

    def play(
        self,
        server: FrameSender,
        stop: threading.Event | None = None,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
    ) -> int:
        """Send every frame at its time (blocking); returns how many were sent (fewer when ``stop`` is set)."""
        if not self.frames:
            return 0
        t0 = self.frames[0][0]
        start = clock()
        for i, (t, _) in enumerate(self.frames):
            due = start + (t - t0) / self.speed
            while (wait := due - clock()) > 0:
                if stop is not None and stop.is_set():
                    return len(self.sent)
                sleep(min(wait, 0.05))
            if stop is not None and stop.is_set():
                return len(self.sent)
            self.max_late_s = max(self.max_late_s, clock() - due)
            self._current = i
            self.sent.append(server.send_frame())
        return len(self.sent)
