"""What the flight knows of each drone's pose: the newest valid mocap pose, its age, and a velocity estimate.

The planner needs neighbours' velocities (a hovering neighbour is an obstacle for the robust preset); mocap gives
positions only, so velocity is a low-pass filtered finite difference of valid samples. Invalid or missing bodies
keep their last pose but age; the supervisor decides what a stale pose means.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Optional

from rpf_fly.mocap.frame import MocapFrame


@dataclass
class TrackedPose:
    """Newest valid pose of one drone: position (x, y, z) metres, quaternion (qx, qy, qz, qw), planar velocity
    (complex, m/s), ``stamp_s`` (monotonic receive time of that sample), ``frame_number``, and whether the newest
    frame tracked it (``valid``)."""

    position: tuple[float, float, float]
    quaternion: tuple[float, float, float, float]
    velocity: complex
    stamp_s: float
    frame_number: int
    valid: bool = True

    @property
    def xy(self) -> complex:
        return complex(self.position[0], self.position[1])


class PoseTracker:
    """Folds mocap frames into per-drone poses. ``bodies`` maps drone name -> rigid body name."""

    def __init__(self, bodies: Mapping[str, str], velocity_tau_s: float = 0.1):
        self.bodies = dict(bodies)
        self.velocity_tau_s = velocity_tau_s
        self.poses: dict[str, TrackedPose] = {}
        self.last_frame_s: Optional[float] = None

    def update(self, frame: MocapFrame) -> None:
        """Take the frame's poses of our drones (Z-up world frame)."""
        self.last_frame_s = frame.receive_time_s
        for name, body_name in self.bodies.items():
            body = frame.bodies.get(body_name)
            previous = self.poses.get(name)
            if body is None or not body.valid:
                if previous is not None:
                    previous.valid = False
                continue
            velocity = 0j
            if previous is not None:
                dt = frame.receive_time_s - previous.stamp_s
                if dt > 1e-4:
                    raw = (complex(body.position[0], body.position[1]) - previous.xy) / dt
                    blend = min(dt / self.velocity_tau_s, 1.0) if previous.valid else 1.0
                    velocity = previous.velocity + blend * (raw - previous.velocity)
                else:
                    velocity = previous.velocity
            self.poses[name] = TrackedPose(
                tuple(body.position), tuple(body.quaternion), velocity, frame.receive_time_s, frame.frame_number
            )

    def get(self, name: str) -> Optional[TrackedPose]:
        return self.poses.get(name)

    def age(self, name: str, now_s: float) -> float:
        """Seconds since the drone's newest valid pose (infinite if it never had one)."""
        pose = self.poses.get(name)
        return float("inf") if pose is None else now_s - pose.stamp_s
