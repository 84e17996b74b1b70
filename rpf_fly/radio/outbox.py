"""Each drone's outgoing commands, and the threads that send them, so that a dying link stalls only its own drone.

Why: cflib's send blocks its caller while the link's driver holds a full queue (cflib's ``RadioDriver``:
``out_queue.put(pk, True, 2)``, then "Could not send packet to copter"). A link that dies in flight blocks every
send to it for about 0.4-0.6 s (the radio's unacknowledged retries, until cflib declares the link lost), up to 2 s.
When the flight loop sent every drone's setpoints itself, that one send held back the whole swarm's stream: the
fault campaign saw the flight watchdog (0.35 s at 10 Hz) land eight drones because one link dropped. Here each
drone's commands wait in its own :class:`Outbox`, and the threads of a :class:`SenderPool` hand them to cflib; the
caller (the flight loop, the watchdog) only queues and never waits for a radio.

What an outbox keeps, and in which order (the rules that make a queued stream safe):

- high-level commands (arm, take-off, go-to, hand-over, land, stop) are kept in the order they were queued and never
  dropped;
- a position setpoint is latest-wins: a newer one replaces one not yet sent (a setpoint planned from an older frame
  is worth nothing once a newer one exists);
- a command that ends the stream (every high-level command but arming) drops a setpoint still waiting, so a setpoint
  queued before a landing can never reach the drone after it; a setpoint queued after the command goes after it;
- extpos / extpose is latest-wins in a slot of its own (a stale mocap position only misleads the estimator), and one
  that comes with its pose's receipt time and has waited longer than :data:`EXTPOS_MAX_WAIT_S` in the ground station
  by the time a sender takes it is dropped, not sent (counted, and said in a warning);
- a keep-alive (the supervisor's emergency-stop watchdog, fed every 0.2 s) has a slot of its own too, and one
  queued while the previous is still waiting is skipped, not stacked: behind a stuck link at most one waits, so
  the link never sends a late burst of them (the firmware needs one a second, not their number);
- each turn of a drone sends its keep-alive first (it changes nothing but the drone's watchdog, so it may overtake
  anything, and a burst of commands never delays it), then its oldest command, then its setpoint, then its extpos,
  one action a turn: a command is never overtaken by anything queued after it. A drone's actions never go out from
  two threads at once.

Room first: cflib's radio link holds one packet at a time between the sender and its driver thread
(``RadioDriver.out_queue``, a ``Queue(1)``), which takes the next one only after its transaction and its
``rate_limit`` sleep. A sender that picked a drone's action and then blocked in cflib's ``put`` would hand over
what was newest when it picked, and a newer setpoint or mocap position queued meanwhile would wait a whole turn of
the link more. So an outbox whose link can say so (``room``) is served only once its link has room: the pool waits
for that (up to `ROOM_WAIT_S`, then it sends anyway and blocks as before), and then takes the drone's action,
the newest of each kind, and checks the extpos's age at that moment.

How the pool sends: one thread at a time does the work in the normal case, taking the drones in the order their
work arrived, one action each turn; so a tick's ten setpoints cost one thread wake-up, not ten. A thread whose send
has lasted longer than :data:`STUCK_S` is taken as stuck in a dying link (it keeps that drone, whose further
commands wait, newest setpoint only), and another thread takes over the other drones: at once when work is queued
or waited for then, and otherwise when the pool's watcher thread looks again, :data:`STUCK_S` after a send began
with other drones' work waiting behind it (the watchdog's landings must not wait for a dying link while the loop
that would queue more is stalled). A new thread is started only when no idle one is left, so there are never more
senders than drones slow at once plus one.

`Outbox.clear` drops everything pending and, for an emergency stop (which the backend sends at once from threads
of its own, not through the pool), refuses anything after it; `Outbox.close` lets what is pending go out (a disarm
queued after touchdown must reach the drone) for at most its ``flush_s``; `SenderPool.close` ends the threads.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from functools import partial

logger = logging.getLogger(__name__)

Action = Callable[[], None]
"""One radio command, ready to send."""

STUCK_S = 0.005
"""A send lasting longer than this is taken as blocked in its link (a healthy cflib send takes tens of
microseconds, a wait for the driver's one-packet queue on a busy dongle a few milliseconds, Python's thread switch
interval is 5 ms; a full driver queue on a dying link blocks for the radio's retries, 0.1-2 s): another thread
takes over the other drones. Taking a slow-but-healthy send for a stuck one costs only a thread wake-up."""


ROOM_WAIT_S = 0.5
"""How long a sender waits for a drone's link to take a packet before it takes the drone's action anyway and waits
inside cflib's send (a dying link's queue stays full until cflib declares it lost, 0.4-2 s: its commands then wait
there, as without the wait for room)."""

EXTPOS_MAX_WAIT_S = 0.05
"""How long a mocap pose may wait in the ground station, from its receipt to its hand-over to cflib, and still go to
the drone's estimator. Why: the firmware's estimator takes each extpos as the drone's position now, so a pose that
waited is a pull back along the drone's path by speed x wait: a ground station whose loop or sender threads were
held back (a loaded host, a long garbage collection) fed poses 0.1-0.28 s old to drones flying 0.6 m/s, their
estimates fell 0.13-0.25 m behind their true positions, and the on-board-estimate check cut two drones' motors
(docs/radio.md, "Extpos that waited"). Dropped instead, the estimator dead-reckons on its IMU until the next fresh
pose (a frame every 10 ms at 100 Hz), which costs millimetres. 50 ms is 2.5 cm at 0.5 m/s and five mocap frames at
100 Hz: more than a healthy loop's p99 from receipt to hand-over (a few milliseconds)."""
EXTPOS_STALE_WARN_EVERY_S = 1.0
"""A drone's dropped stale extpos are said in one warning at most this often (the count goes in each)."""


class SenderPool:
    """The threads that send every outbox's actions (module docstring). One lock guards the pool and its outboxes."""

    def __init__(self, name: str = "rpf-send") -> None:
        self.name = name
        self._lock = threading.Lock()
        self._work = threading.Condition(self._lock)
        """Idle threads wait here for a token."""
        self._done = threading.Condition(self._lock)
        """Notified when a send leaves the line empty: `wait_idle` waits here."""
        self._ready: deque[Outbox] = deque()
        self._working = 0
        """Threads awake and looking for work (not inside a send)."""
        self._sending: dict[int, float] = {}
        """Threads inside a send, by thread number: since when (`time.monotonic()`)."""
        self._idle = 0
        self._tokens = 0
        """Wake-ups handed to idle threads and not yet taken."""
        self._threads: list[threading.Thread] = []
        self._closed = False
        self._recheck = threading.Condition(self._lock)
        self._recheck_at: float | None = None
        self._watcher: threading.Thread | None = None

    def outbox(self, name: str, run: Callable[[Action], None], room: Callable[[float], bool] | None = None) -> Outbox:
        """A new drone's outbox; ``run(action)`` sends one of its actions on a pool thread (what it raises is logged
        and the pool goes on); ``room(timeout_s)``, if given, waits until the drone's link can take a packet
        without blocking (True) or the timeout passed (False): the action is taken then (module docstring, "Room
        first")."""
        return Outbox(self, name, run, room)

    @property
    def threads(self) -> int:
        """Threads started so far (one in normal flight; one more per drone stuck in a dying link)."""
        return len(self._threads)

    # ------------------------------------------------------------------------------------------ with the lock held

    def _schedule(self, box: Outbox) -> None:
        """``box`` has work: put it in line unless it is in line already or one of its sends is under way."""
        if not box._queued and not box._busy and box._pending():
            box._queued = True
            self._ready.append(box)
        self._wake()

    def _wake(self) -> None:
        """Make sure a thread that is not stuck will take the work in line: an idle one, or a new one."""
        if not self._ready or self._closed:
            return
        now = time.monotonic()
        if self._working + self._tokens > 0:
            return
        unstuck = [since for since in self._sending.values() if now - since <= STUCK_S]
        if unstuck:  # a sender will take it if its send returns: look again once it would count as stuck
            self._arm(min(unstuck))
            return
        if self._idle > self._tokens:
            self._tokens += 1
            self._work.notify()
            return
        thread = threading.Thread(target=self._loop, name=f"{self.name}-{len(self._threads) + 1}", daemon=True)
        self._working += 1
        try:
            thread.start()
        except RuntimeError:  # "can't start new thread": the next queue or wait tries again
            self._working -= 1
            logger.exception("sender pool %s: no thread could be started", self.name)
            return
        self._threads.append(thread)

    # ------------------------------------------------------------------------------------------ the threads

    def _loop(self) -> None:
        me = threading.get_ident()
        with self._lock:
            while True:
                if not self._ready:
                    self._working -= 1
                    if self._closed:
                        return
                    self._idle += 1
                    while not self._tokens and not self._closed:
                        self._work.wait()
                    self._idle -= 1
                    if self._tokens:
                        self._tokens -= 1
                    self._working += 1
                    continue
                box = self._ready.popleft()
                box._queued = False
                if box._room is not None:
                    self._wait_for_room(me, box)
                action = box._take()
                if action is None:  # a stale extpos dropped: nothing of this drone's went out
                    if not self._ready:
                        self._done.notify_all()
                    continue
                self._outside_lock(me, box, partial(box._run, action), "sending a command failed")
                if box._pending():
                    box._queued = True
                    self._ready.append(box)  # behind the drones already waiting: one action a turn
                if not self._ready:  # the burst is out: wake the waiters once, not after every drone's send
                    self._done.notify_all()

    def _wait_for_room(self, me: int, box: Outbox) -> None:
        """Lock held on entry and exit: wait until ``box``'s link can take a packet, so that the action taken next
        is the newest (a link that cannot say is sent to as without the wait)."""
        room = box._room
        assert room is not None
        self._outside_lock(me, box, partial(room, ROOM_WAIT_S), "waiting for room in its link failed")

    def _outside_lock(self, me: int, box: Outbox, call: Callable[[], object], failed: str) -> None:
        """Lock held on entry and exit: ``call()`` with the lock released, counted as a send (``box`` not scheduled
        again meanwhile; the drones in line behind are taken over if it blocks); what it raises is logged with
        ``failed`` (a pool thread never dies: the next commands must still go out)."""
        box._busy = True
        self._working -= 1
        self._sending[me] = time.monotonic()
        if self._ready:
            self._arm(self._sending[me])
        self._lock.release()
        try:
            call()
        except BaseException:
            logger.exception("drone %s: %s", box.name, failed)
        finally:
            self._lock.acquire()
        del self._sending[me]
        self._working += 1
        box._busy = False

    def _arm(self, since: float) -> None:
        """Look at the line again when a send begun at ``since`` would count as stuck."""
        at = since + STUCK_S + 1e-4
        if self._recheck_at is None or at < self._recheck_at:
            self._recheck_at = at
            if self._watcher is None:
                self._watcher = threading.Thread(target=self._watch, name=f"{self.name}-watch", daemon=True)
                self._watcher.start()
            self._recheck.notify()

    def _watch(self) -> None:
        with self._lock:
            while not self._closed:
                if self._recheck_at is None:
                    self._recheck.wait()
                elif (delay := self._recheck_at - time.monotonic()) > 0:
                    self._recheck.wait(delay)
                else:
                    self._recheck_at = None
                    self._wake()

    # ------------------------------------------------------------------------------------------ waiting, closing

    def wait_idle(self, boxes: Iterable[Outbox], timeout_s: float) -> bool:
        """Wait until every one of ``boxes`` has sent (or dropped) what was queued so far; False on timeout, and then
        another thread takes over from one stuck in a send."""
        boxes = list(boxes)
        with self._lock:
            done = self._done.wait_for(lambda: all(b._idle() for b in boxes), timeout_s)
            if not done:
                self._wake()
            return done

    def close(self, join_s: float = 1.0) -> None:
        """End the threads (those stuck in a send end when it returns)."""
        with self._lock:
            self._closed = True
            self._work.notify_all()
            self._recheck.notify_all()
        deadline = time.monotonic() + join_s
        for thread in list(self._threads):
            thread.join(max(deadline - time.monotonic(), 0.0))


class Outbox:
    """One drone's pending commands (module docstring); made by :meth:`SenderPool.outbox`."""

    def __init__(
        self, pool: SenderPool, name: str, run: Callable[[Action], None], room: Callable[[float], bool] | None = None
    ):
        self.name = name
        self._pool = pool
        self._run = run
        self._room = room
        self._commands: deque[Action] = deque()
        self._setpoint: Action | None = None
        self._extpos: Action | None = None
        self._extpos_stamp_s: float | None = None
        self._keepalive: Action | None = None
        self._busy = False
        """One of its actions is being sent."""
        self._queued = False
        """It is in the pool's line."""
        self._closed = False
        self.setpoints_replaced = 0
        """Setpoints replaced by a newer one or dropped by a command before they were sent."""
        self.keepalives_skipped = 0
        """Keep-alives not queued because the previous one was still waiting (a slow or stuck link)."""
        self.extpos_stale = 0
        """Extpos dropped because their pose waited longer than `EXTPOS_MAX_WAIT_S` before a sender took it."""
        self.extpos_taken_s: float | None = None
        self._setpoint_since = 0.0
        """When the setpoint now waiting (or the first of those it replaced) was queued."""
        """`time.monotonic()` when a sender last took this drone's extpos to hand it to its link (None: never)."""
        self._stale_warned_at: float | None = None

    # ------------------------------------------------------------------------------------------ queueing

    def command(self, action: Action, ends_stream: bool) -> bool:
        """Queue a high-level command (kept in order); one that ``ends_stream`` drops a waiting setpoint. False
        once the outbox is closed."""
        with self._pool._lock:
            if self._closed:
                return False
            if ends_stream and self._setpoint is not None:
                self._setpoint = None
                self.setpoints_replaced += 1
            self._commands.append(action)
            self._pool._schedule(self)
            return True

    def setpoint(self, action: Action) -> bool:
        """Queue a streamed setpoint, replacing one not yet sent. False once the outbox is closed."""
        with self._pool._lock:
            if self._closed:
                return False
            if self._setpoint is not None:
                self.setpoints_replaced += 1
            else:
                self._setpoint_since = time.monotonic()
            self._setpoint = action
            self._pool._schedule(self)
            return True

    def setpoint_waiting_s(self) -> float:
        """How long a setpoint of this drone has been waiting unsent (replaced by newer ones meanwhile: the same
        wait), 0 when none waits: a link that takes none leaves the drone without setpoints that long and more."""
        with self._pool._lock:
            return time.monotonic() - self._setpoint_since if self._setpoint is not None else 0.0

    def extpos(self, action: Action, received_s: float | None = None) -> bool:
        """Queue a mocap position for the estimator, replacing one not yet sent; ``received_s``: when its pose was
        received (`time.monotonic()`): it is dropped if it waited longer than `EXTPOS_MAX_WAIT_S` by the time a
        sender takes it. False once closed."""
        with self._pool._lock:
            if self._closed:
                return False
            self._extpos, self._extpos_stamp_s = action, received_s
            self._pool._schedule(self)
            return True

    def keepalive(self, action: Action) -> bool:
        """Queue a keep-alive, unless the previous one is still waiting: then this one is skipped (counted in
        `keepalives_skipped`). True when queued; False when skipped or once the outbox is closed."""
        with self._pool._lock:
            if self._closed:
                return False
            if self._keepalive is not None:
                self.keepalives_skipped += 1
                return False
            self._keepalive = action
            self._pool._schedule(self)
            return True

    def clear(self, refuse: bool = False) -> None:
        """Drop everything not yet sent (what is being sent now still goes out); ``refuse``: and accept nothing
        more (an emergency stop: nothing may follow it)."""
        with self._pool._lock:
            self._closed = self._closed or refuse
            if self._setpoint is not None:
                self.setpoints_replaced += 1
            self._commands.clear()
            self._setpoint = self._extpos = self._keepalive = None

    # ------------------------------------------------------------------------------------------ state (lock held)

    def _pending(self) -> bool:
        return (
            bool(self._commands)
            or self._setpoint is not None
            or self._extpos is not None
            or self._keepalive is not None
        )

    def _idle(self) -> bool:
        return not self._busy and not self._pending()

    def _take(self) -> Action | None:
        """The next action to send (the keep-alive, the oldest command, then the setpoint, then the extpos), marking
        it under way."""
        if self._keepalive is not None:
            action: Action | None = self._keepalive
            self._keepalive = None
        elif self._commands:
            action = self._commands.popleft()
        elif self._setpoint is not None:
            action, self._setpoint = self._setpoint, None
        else:
            action, self._extpos = self._extpos, None
            if action is not None and self._extpos_stamp_s is not None:
                waited = time.monotonic() - self._extpos_stamp_s
                if waited > EXTPOS_MAX_WAIT_S:
                    self._stale(waited)
                    action = None
            if action is not None:
                self.extpos_taken_s = time.monotonic()
        self._busy = action is not None
        return action

    def _stale(self, waited_s: float) -> None:
        """Count a dropped stale extpos; warn at the first and then at most every `EXTPOS_STALE_WARN_EVERY_S`."""
        self.extpos_stale += 1
        now = time.monotonic()
        if self._stale_warned_at is None or now - self._stale_warned_at >= EXTPOS_STALE_WARN_EVERY_S:
            self._stale_warned_at = now
            logger.warning(
                "drone %s: a mocap pose waited %.0f ms in the ground station (over %.0f ms): not sent to its "
                "estimator (%d so far; the host held the flight back)",
                self.name,
                waited_s * 1000.0,
                EXTPOS_MAX_WAIT_S * 1000.0,
                self.extpos_stale,
            )

    # ------------------------------------------------------------------------------------------ waiting, closing

    def idle(self) -> bool:
        """Nothing waiting and nothing being sent."""
        with self._pool._lock:
            return self._idle()

    def wait_idle(self, timeout_s: float) -> bool:
        """Wait until everything queued so far has been handed to cflib (or dropped); False on timeout."""
        return self._pool.wait_idle((self,), timeout_s)

    def close(self, flush_s: float) -> bool:
        """Refuse new commands, let the pending ones go out for at most ``flush_s``, then drop what is left. True
        when everything pending went out."""
        with self._pool._lock:
            self._closed = True
        flushed = self.wait_idle(flush_s)
        with self._pool._lock:
            self._commands.clear()
            self._setpoint = self._extpos = self._keepalive = None
        return flushed
