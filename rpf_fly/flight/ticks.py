"""When the flight loop plans: planning ticks locked to the mocap frames, at the mission rate.

A setpoint is only as fresh as the pose it was planned on. Ticks on a free-running clock plan on a frame that
arrived up to one period earlier (a uniform 0-10 ms of extra age at 100 Hz, and a latency figure that only sees
the ticks where a frame happened to arrive late). So a tick fires on a frame, the moment it arrives:

- tick ``k`` has a nominal time ``due`` and owns the window ``[due - dt/2, due + dt/2)``; the windows tile the time
  line, one per period, so the loop plans at the mission rate whatever the mocap rate (120 Hz mocap and 100 Hz
  planning: each window holds one or two frames);
- the tick fires on the first frame received inside its window, or at the window's end without a frame (mocap late,
  lost, or slower than the planning rate), so setpoints keep streaming when mocap stops;
- after a tick on a frame the window's phase moves a tenth of the way towards that frame's arrival (a first-order
  phase lock): the windows centre on the frames, so arrival jitter near a window's edge does not make ticks
  alternate between frames and deadlines. The phase is an offset from a grid that advances exactly one period per
  tick and is clamped to half a period either way, so the lock never changes the rate (the first frame of a window
  is biased early when mocap runs faster; an unclamped lock would follow that bias and tick faster). A mocap clock
  drifting against ours by more than half a period over one flight (50 ppm drift needs 100 s at 100 Hz) loses the
  centring, not the ticks;
- a tick more than a period late is an overrun and the grid restarts from it.

Pure: times are passed in (seconds on any monotonic clock), nothing here sleeps or reads a clock.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class TickSchedule:
    """The planning-tick schedule of one flight (see the module docstring). ``grid_s``: the current tick's
    nominal time before the phase lock; ``phase_s``: the lock's offset, within half a period."""

    period_s: float
    grid_s: float
    phase_lock_gain: float = 0.1
    phase_s: float = 0.0
    overruns: int = 0
    frameless: int = 0

    @property
    def due_s(self) -> float:
        """The current tick's nominal time: the centre of its window."""
        return self.grid_s + self.phase_s

    @property
    def window_end_s(self) -> float:
        """The latest time the current tick may fire: wait for mocap until then."""
        return self.due_s + 0.5 * self.period_s

    def is_due(self, now_s: float, have_frame: bool) -> bool:
        """Whether the current tick fires now: a frame inside its window, or the window is over."""
        return now_s >= self.window_end_s or (have_frame and now_s >= self.due_s - 0.5 * self.period_s)

    def fired(self, now_s: float, on_frame: bool) -> None:
        """The current tick fired at ``now_s`` (on a frame or not): schedule the next one."""
        half = 0.5 * self.period_s
        if on_frame:
            phase = self.phase_s + self.phase_lock_gain * (now_s - self.due_s)
            self.phase_s = min(half, max(-half, phase))
        else:
            self.frameless += 1
        self.grid_s += self.period_s
        if now_s - self.due_s > self.period_s:
            self.overruns += 1
            self.grid_s, self.phase_s = now_s + self.period_s, 0.0
