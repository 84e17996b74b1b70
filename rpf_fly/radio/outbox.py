"""One drone's outgoing commands and the thread that sends them, so that a dying link stalls only its own drone.

Why: cflib's send blocks its caller while the link's driver holds a full queue (cflib's ``RadioDriver``:
``out_queue.put(pk, True, 2)``, then "Could not send packet to copter"). A link that dies in flight blocks every
send to it for about 0.4-0.6 s (the radio's unacknowledged retries, until cflib declares the link lost), up to 2 s.
When one thread sent every drone's setpoints, that one send held back the whole swarm's stream: the fault campaign
saw the flight watchdog (0.35 s at 10 Hz) land eight drones because one link dropped. Here each drone's commands
wait in its own outbox, and a thread per drone hands them to cflib; the caller (the flight loop, the watchdog) only
queues and never waits for a radio.

What is kept, and in which order (the rules that make a queued stream safe):

- high-level commands (arm, take-off, go-to, hand-over, land, stop) are kept in the order they were queued and never
  dropped;
- a position setpoint is latest-wins: a newer one replaces one not yet sent (a setpoint planned from an older frame
  is worth nothing once a newer one exists);
- a command that ends the stream (every high-level command but arming) drops a setpoint still waiting, so a setpoint
  queued before a landing can never reach the drone after it; a setpoint queued after the command goes after it;
- extpos / extpose is latest-wins in a slot of its own (a stale mocap position only misleads the estimator);
- each round sends the oldest command first, then the setpoint, then the extpos: a command is never overtaken by
  anything queued after it, and the setpoint is always newer than every command already sent.

`clear` drops everything pending (an emergency stop, which the backend sends from its caller's thread at once);
`close` lets what is pending go out (a disarm queued after touchdown must reach the drone) for at most its
``flush_s``, then ends the thread.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable

logger = logging.getLogger(__name__)

Action = Callable[[], None]
"""One radio command, ready to send (it raises on failure; the runner reports it)."""


class Outbox:
    """A drone's pending commands and the daemon thread that sends them (see the module docstring)."""

    def __init__(self, name: str, run: Callable[[Action], None]):
        """``run(action)`` sends one action on the outbox's thread (what it raises is logged, and the thread goes
        on with the next command)."""
        self.name = name
        self._run = run
        self._cond = threading.Condition()
        self._commands: deque[Action] = deque()
        self._setpoint: Action | None = None
        self._extpos: Action | None = None
        self._sending = False
        self._closed = False
        self.setpoints_replaced = 0
        """Setpoints replaced by a newer one or dropped by a command before they were sent."""
        self._thread = threading.Thread(target=self._loop, name=f"rpf-send-{name}", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------------------------------ queueing

    def command(self, action: Action, ends_stream: bool) -> bool:
        """Queue a high-level command (kept in order); one that ``ends_stream`` drops a waiting setpoint. False
        once the outbox is closed."""
        with self._cond:
            if self._closed:
                return False
            if ends_stream and self._setpoint is not None:
                self._setpoint = None
                self.setpoints_replaced += 1
            self._commands.append(action)
            self._cond.notify()
            return True

    def setpoint(self, action: Action) -> bool:
        """Queue a streamed setpoint, replacing one not yet sent. False once the outbox is closed."""
        with self._cond:
            if self._closed:
                return False
            if self._setpoint is not None:
                self.setpoints_replaced += 1
            self._setpoint = action
            self._cond.notify()
            return True

    def extpos(self, action: Action) -> bool:
        """Queue a mocap position for the estimator, replacing one not yet sent. False once closed."""
        with self._cond:
            if self._closed:
                return False
            self._extpos = action
            self._cond.notify()
            return True

    def clear(self) -> None:
        """Drop everything not yet sent (what is being sent now still goes out)."""
        with self._cond:
            if self._setpoint is not None:
                self.setpoints_replaced += 1
            self._commands.clear()
            self._setpoint = self._extpos = None

    # ------------------------------------------------------------------------------------------ state

    def _pending(self) -> bool:
        return bool(self._commands) or self._setpoint is not None or self._extpos is not None

    def idle(self) -> bool:
        """Nothing waiting and nothing being sent."""
        with self._cond:
            return not self._pending() and not self._sending

    def wait_idle(self, timeout_s: float) -> bool:
        """Wait until everything queued so far has been handed to cflib (or dropped); False on timeout."""
        with self._cond:
            return self._cond.wait_for(lambda: not self._pending() and not self._sending, timeout_s)

    def close(self, flush_s: float) -> bool:
        """Refuse new commands, let the pending ones go out for at most ``flush_s``, then end the thread (what is
        still pending then is dropped). True when everything pending went out."""
        with self._cond:
            self._closed = True
            flushed = self._cond.wait_for(lambda: not self._pending() and not self._sending, flush_s)
            self._commands.clear()
            self._setpoint = self._extpos = None
            self._cond.notify_all()
        self._thread.join(max(flush_s, 0.1))
        return flushed

    # ------------------------------------------------------------------------------------------ the thread

    def _next(self) -> Action | None:
        """The next action (oldest command, then the setpoint, then the extpos), or None when closed and empty."""
        with self._cond:
            self._sending = False
            self._cond.notify_all()  # wait_idle / close
            while not self._pending():
                if self._closed:
                    return None
                self._cond.wait()
            self._sending = True
            if self._commands:
                return self._commands.popleft()
            if self._setpoint is not None:
                action, self._setpoint = self._setpoint, None
                return action
            action, self._extpos = self._extpos, None
            return action

    def _loop(self) -> None:
        while (action := self._next()) is not None:
            try:
                self._run(action)
            except Exception:  # the drone's next commands must still go out
                logger.exception("drone %s: sending a command failed", self.name)
