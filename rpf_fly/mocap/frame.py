"""What every motion-capture source delivers: rigid-body poses in the Z-up world frame, and the source protocol.

Conventions (docs/architecture.md, *Conventions*): right-handed world, Z up, metres, seconds; quaternions are (qx, qy,
qz, qw), rotating body coordinates into world coordinates. Sources convert from their native axes (NatNet streams Y-up
by default) before filling these objects, so nothing downstream ever sees another frame.

The :class:`MocapSource` protocol is deliberately small (newest frame or None, close, stats) so that the NatNet
client, the simulated source and the source over the ``motioncapture`` package (Vicon, Qualisys, VRPN; blocking
``waitForNextFrame()`` without frame numbers or latency: ``motioncapture_source.py``) can all implement it: fields a
backend cannot know are optional (``latency_s``) or are synthesised (``frame_number`` as a counter,
``capture_time_s`` as the receive time).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType, TracebackType
from typing import Protocol, runtime_checkable

__all__ = ["RigidBodyPose", "MocapFrame", "MocapStats", "MocapSource", "PoseSample", "PoseCallable", "NO_UNSEEN"]

PoseSample = tuple[Sequence[float], Sequence[float], bool]
"""A true pose as simulators supply it: (position x, y, z in metres, quaternion qx, qy, qz, qw, tracking valid),
Z-up world frame."""
PoseCallable = Callable[[], Mapping[str, PoseSample]]
"""``poses() -> {rigid body name: PoseSample}``: what the simulated source and the NatNet emulator stream."""


@dataclass(frozen=True, slots=True)
class RigidBodyPose:
    """One tracked rigid body in the Z-up world frame.

    ``valid`` is False when the mocap system did not track the body in this frame (occluded, out of view); the
    pose fields then hold whatever the source reported and must not be flown on. ``marker_error`` is the mean
    marker residual in metres (0.0 when the source has none).
    """

    name: str
    id: int
    position: tuple[float, float, float]
    """x, y, z in metres, Z-up world frame."""
    quaternion: tuple[float, float, float, float]
    """qx, qy, qz, qw (unit quaternion, body to world)."""
    valid: bool
    marker_error: float = 0.0
    """Mean marker error in metres."""


@dataclass(frozen=True, slots=True)
class MocapFrame:
    """All rigid bodies of one mocap frame.

    ``bodies`` is keyed by rigid-body name; a source that does not (yet) know a body's name keys it by
    ``str(id)`` (the NatNet client does this until MODELDEF arrives).
    """

    frame_number: int
    capture_time_s: float
    """Server timestamp of the frame in seconds (source clock, not comparable with ``receive_time_s``)."""
    receive_time_s: float
    """``time.monotonic()`` when the frame was received, seconds."""
    latency_s: float | None
    """Camera-to-server latency in seconds when the source measures it (NatNet high-resolution clock), else None."""
    bodies: dict[str, RigidBodyPose] = field(default_factory=dict)
    unseen_untracked_s: Mapping[str, float] = field(default_factory=lambda: NO_UNSEEN)
    """Bodies that went untracked and came back entirely within frames the caller never got (it was busy: a
    stalled loop reads only the newest frame of those the socket queued), tracked in the caller's previous frame
    and in this one: body name -> the longest such stretch (source clock, seconds). Empty unless the source
    knows (the NatNet client); without it an occlusion or a blackout during a loop stall leaves no trace."""


NO_UNSEEN: Mapping[str, float] = MappingProxyType({})


@dataclass(slots=True)
class MocapStats:
    """Counters of a mocap source; ``stats`` properties return a snapshot copy.

    Invariant for packet sources: ``packets == frames + messages + dropped``.
    """

    packets: int = 0
    """Datagrams (or simulated frames) received from the source."""
    frames: int = 0
    """Frames decoded successfully."""
    messages: int = 0
    """Other valid protocol messages handled (server info, model definitions, responses, ...)."""
    delivered: int = 0
    """Frames returned by ``receive()``."""
    superseded: int = 0
    """Decoded frames never returned because a newer frame was available (drained, duplicate or reordered)."""
    dropped: int = 0
    """Packets discarded for any reason: malformed, from an unexpected sender, unknown or premature messages."""
    malformed: int = 0
    """Packets that failed to decode (included in ``dropped``)."""
    body_dropouts: int = 0
    """Rigid bodies reported as not tracked (``valid`` False) in delivered frames."""


@runtime_checkable
class MocapSource(Protocol):
    """A source of mocap frames: the NatNet client, the simulated source, other backends later.

    ``receive(timeout_s)`` returns the NEWEST frame that arrived since the previous call (older queued frames
    are discarded and counted as superseded), waiting up to ``timeout_s`` seconds for one; None on timeout.
    Sources are context managers that close on exit.
    """

    def receive(self, timeout_s: float) -> MocapFrame | None:
        """Newest frame since the last call, waiting at most ``timeout_s`` seconds; None on timeout."""
        ...

    def close(self) -> None:
        """Release sockets and other resources; idempotent."""
        ...

    @property
    def stats(self) -> MocapStats:
        """A snapshot of the source's counters."""
        ...

    def __enter__(self) -> MocapSource: ...

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None: ...
