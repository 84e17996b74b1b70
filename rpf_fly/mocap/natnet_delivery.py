"""Which decoded NatNet frame the caller gets, and what it missed: the newest frame since its last read, and the
untracked stretches of its bodies inside the frames it skipped (rpf_fly/mocap/natnet_client.py reads the sockets).

The caller reads only the newest frame of those the socket queued (a stalled flight loop skips frames); a body that
went untracked and came back entirely within skipped frames would go unnoticed, so :class:`NewestFrame` keeps
its runs and reports them with the next delivered frame (``MocapFrame.unseen_untracked_s``). Also here: the
poses of a frame in the Z-up world frame, and the camera latency.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from rpf_fly.mocap.frame import NO_UNSEEN, RigidBodyPose
from rpf_fly.mocap.natnet_protocol import FrameOfData

#: Frames at most this many numbers older than the last one are stale (reordered or duplicated); a bigger jump
#: back means Motive restarted or a take looped, and is accepted as new.
REORDER_WINDOW = 16
#: A body's untracked run inside frames the caller skipped is reported (`MocapFrame.unseen_untracked_s`) from this
#: long: the flight supervisor's ``POSE_LATE_S``, what it says of a pose gap it sees live.
_UNSEEN_S = 0.1


def is_newer(candidate: int, reference: int) -> bool:
    """Frame ``candidate`` is newer than ``reference`` (allowing for restarts, see REORDER_WINDOW)."""
    return candidate > reference or reference - candidate > REORDER_WINDOW


class NewestFrame:
    """The newest frame waiting for the caller, with what the caller missed in the frames superseded before it."""

    def __init__(self) -> None:
        self.pending: tuple[FrameOfData, float] | None = None
        """The newest frame not yet delivered, and when it was received."""
        self._last_delivered: int | None = None
        self._skipped_untracked: dict[int, list[float]] = {}
        """Body id -> [start, end, longest] of its runs of untracked poses in the frames skipped since the last
        delivery (superseded before the caller read them): the open run's first and last server time (start NaN
        when none is open) and the longest closed one. Empty while the caller keeps up, so the normal path pays
        nothing."""
        self._skipped = 0
        self._previous: FrameOfData | None = None
        """The frame delivered last."""

    def offer(self, data: FrameOfData, receive_time_s: float) -> bool:
        """Keep ``data`` if it is the newest frame; True when a frame was superseded (the one waiting, or ``data``
        itself: a duplicate or reordered frame older than what the caller already has)."""
        pending = self.pending
        if pending is not None:
            if is_newer(data.frame_number, pending[0].frame_number):
                self._skip(pending[0])
                self.pending = (data, receive_time_s)
            return True
        if self._last_delivered is not None and not is_newer(data.frame_number, self._last_delivered):
            return True
        self.pending = (data, receive_time_s)
        return False

    def take(self, names: Mapping[int, str]) -> tuple[FrameOfData, float, Mapping[str, float]]:
        """The waiting frame, when it was received, and its ``unseen_untracked_s`` (bodies named by ``names``)."""
        pending = self.pending
        if pending is None:
            raise RuntimeError("no pending frame to deliver")
        data, received = pending
        self.pending = None
        self._last_delivered = data.frame_number
        return data, received, self._unseen(data, names)

    def _skip(self, data: FrameOfData) -> None:
        """Note the untracked bodies of a frame the caller will never get (superseded by a newer one)."""
        self._skipped += 1
        t, runs = data.timestamp, self._skipped_untracked
        for rb in data.rigid_bodies:
            run = runs.get(rb.id)
            if rb.params & 0x01:
                if run is not None and run[0] == run[0]:  # an open run ends (NaN != NaN: none open)
                    run[2] = max(run[2], run[1] - run[0])
                    run[0] = math.nan
            elif run is None:
                runs[rb.id] = [t, t, 0.0]
            else:
                if run[0] != run[0]:
                    run[0] = t
                run[1] = t

    def _unseen(self, data: FrameOfData, names: Mapping[int, str]) -> Mapping[str, float]:
        """`MocapFrame.unseen_untracked_s` of the frame about to be delivered: the bodies' untracked runs in the
        frames skipped since the last delivery, each plus one frame interval (it was tracked a frame before and a
        frame after), of bodies tracked in the previous delivered frame and in this one (so the caller saw neither
        end), at least ``_UNSEEN_S`` long."""
        previous, self._previous = self._previous, data
        skipped, self._skipped = self._skipped, 0
        runs = self._skipped_untracked
        if not runs:
            return NO_UNSEEN
        self._skipped_untracked = {}
        if previous is None:
            return NO_UNSEEN
        interval = (data.timestamp - previous.timestamp) / (skipped + 1)
        before = {rb.id for rb in previous.rigid_bodies if rb.params & 0x01}
        now = {rb.id for rb in data.rigid_bodies if rb.params & 0x01}
        unseen = {}
        for i, (start, end, longest) in runs.items():
            gap = max(longest, end - start if start == start else 0.0) + interval
            if gap >= _UNSEEN_S and i in before and i in now:
                unseen[names.get(i, str(i))] = gap
        return unseen or NO_UNSEEN


def rigid_body_poses(
    data: FrameOfData, names: Mapping[int, str], y_up: bool
) -> tuple[dict[str, RigidBodyPose], bool, int]:
    """The frame's bodies in the Z-up world frame, by name (``str(id)`` for an id ``names`` lacks); whether one
    lacked a name; how many were untracked. Y-up: positions (x, y, z) become (x, -z, y) and quaternion vectors
    (qx, qy, qz) become (qx, -qz, qy), qw unchanged."""
    bodies: dict[str, RigidBodyPose] = {}
    unknown = False
    dropouts = 0
    for rb in data.rigid_bodies:
        name = names.get(rb.id)
        if name is None:
            name = str(rb.id)
            unknown = True
        if y_up:
            position = (rb.x, -rb.z, rb.y)
            quaternion = (rb.qx, -rb.qz, rb.qy, rb.qw)
        else:
            position = (rb.x, rb.y, rb.z)
            quaternion = (rb.qx, rb.qy, rb.qz, rb.qw)
        valid = bool(rb.params & 0x01)
        dropouts += not valid
        bodies[name] = RigidBodyPose(name, rb.id, position, quaternion, valid, rb.error)
    return bodies, unknown, dropouts


def camera_latency_s(data: FrameOfData, frequency: float | None) -> float | None:
    """Seconds from the cameras' mid-exposure to Motive's receipt of their data (None when the server's clock
    frequency or the camera timestamps are unknown)."""
    if frequency and data.camera_mid_exposure and data.camera_data_received >= data.camera_mid_exposure:
        return (data.camera_data_received - data.camera_mid_exposure) / frequency
    return None
