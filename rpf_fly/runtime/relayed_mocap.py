"""A worker's mocap when the flight has a relay: a :class:`~rpf_fly.mocap.frame.MocapSource` over the relay's
signed frames on Zenoh (rpf_fly/runtime/frames.py, docs/distributed.md "Mocap relay").

The Zenoh subscriber's thread verifies each message and keeps the newest frame; :meth:`RelayedMocap.receive` hands
it to the flight loop as any mocap source does. Anything that is not this flight's relay's (no signature, a wrong
one, another flight's, a replayed or older frame, garbage) is dropped and counted (``stats.dropped``; garbage also
``stats.malformed``) and reported as a warning: at once for the first, then at most every
:data:`WARN_INTERVAL_S` with the count since, never raised into Zenoh or the loop. A frame's ``receive_time_s`` is
this process's own ``time.monotonic()`` when the message arrived, so the loop's latency figure (frame to setpoint)
starts at the worker's receipt and leaves out the mocap-to-relay-to-worker path; that hop, from the relay's receipt
to the worker's (wall clocks: exact on one host, as good as their sync across hosts), is kept in
:attr:`RelayedMocap.transit`.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from types import TracebackType
from typing import Any

from rpf_fly.mocap.frame import MocapFrame, MocapStats
from rpf_fly.runtime.frames import FrameVerifier

logger = logging.getLogger(__name__)

WARN_INTERVAL_S = 5.0
"""At most one warning about refused frames this often (a flood of forged frames is one line every 5 s)."""
TRANSIT_KEPT = 200_000
"""The relay hops kept for the worker's report (100 Hz for half an hour)."""


class RelayedMocap:
    """The flight's relayed mocap frames, verified with its secret. ``warn(message)``: where refusals are reported
    (the worker sets it to its loop's events once the loop exists; Python's logging always gets them too)."""

    def __init__(self, session: Any, key: str, secret: str, flight: str, warn: Callable[[str], None] | None = None):
        self.key = key
        self.warn = warn
        self._verifier = FrameVerifier(secret, flight)
        self._stats = MocapStats()
        self._cond = threading.Condition()
        self._verify_lock = threading.Lock()
        self._pending: MocapFrame | None = None
        self._closed = False
        self._last_warning_s = -1e9
        self._unreported = 0
        self.transit: deque[tuple[float, float]] = deque(maxlen=TRANSIT_KEPT)
        """(this process's receipt, monotonic s; the relay's hop, s) of each frame taken; Zenoh's thread appends
        to it: read it through `transits`."""
        self._subscriber = session.declare_subscriber(key, self._received)

    def transits(self, since_s: float) -> list[float]:
        """The relay's hop (s) of each frame taken from ``since_s`` (monotonic) on: a copy made under the lock Zenoh's
        thread appends under (iterating `transit` while a frame arrives raises "deque mutated during iteration":
        a worker's last report died of it on a loaded host)."""
        with self._cond:
            return [t for at, t in self.transit if at >= since_s]

    # ------------------------------------------------------------------------------------------ Zenoh's thread

    def _received(self, sample: Any) -> None:
        received_s = time.monotonic()
        received_ns = time.time_ns()
        with self._verify_lock:  # the sequence check and the warnings' rate, one sample at a time
            self._verify(sample, received_s, received_ns)

    def _verify(self, sample: Any, received_s: float, received_ns: int) -> None:
        try:
            attachment = sample.attachment.to_bytes() if sample.attachment is not None else None
            checked = self._verifier.verify(sample.payload.to_bytes(), attachment, received_s)
        except Exception as err:  # noqa: BLE001 - whatever arrives, never into Zenoh's thread
            verdict = None
            why, malformed = f"malformed mocap frame ({err})", True
        else:
            verdict = checked
            why, malformed = checked.why, checked.malformed
        with self._cond:
            stats = self._stats
            stats.packets += 1
            if verdict is None or verdict.frame is None:
                stats.dropped += 1
                stats.malformed += malformed
            else:
                stats.frames += 1
                if self._pending is not None:
                    stats.superseded += 1
                self._pending = verdict.frame
                self.transit.append((received_s, (received_ns - verdict.relay_receive_ns) * 1e-9))
                self._cond.notify_all()
                return
        self._refused(why, received_s)

    def _refused(self, why: str, now_s: float) -> None:
        self._unreported += 1
        if now_s - self._last_warning_s < WARN_INTERVAL_S:
            return
        more = f" ({self._unreported - 1} more since the last warning)" if self._unreported > 1 else ""
        self._last_warning_s, self._unreported = now_s, 0
        message = f"ignored a mocap frame that is not this flight's relay's: {why}{more}"
        logger.warning("%s on %s", message, self.key)
        warn = self.warn
        if warn is not None:
            try:
                warn(message)
            except Exception:  # noqa: BLE001
                logger.exception("relayed mocap: reporting a refused frame failed")

    # ------------------------------------------------------------------------------------------ MocapSource

    def receive(self, timeout_s: float) -> MocapFrame | None:
        """The newest frame since the last call, waiting up to ``timeout_s`` seconds; None on timeout or closed."""
        with self._cond:
            if self._pending is None and not self._closed:
                self._cond.wait_for(lambda: self._pending is not None or self._closed, max(0.0, timeout_s))
            frame, self._pending = self._pending, None
            if frame is not None:
                self._stats.delivered += 1
                self._stats.body_dropouts += sum(not b.valid for b in frame.bodies.values())
            return frame

    def wait_first(self, timeout_s: float) -> bool:
        """Whether a frame arrived within ``timeout_s`` (kept for the next :meth:`receive`)."""
        with self._cond:
            return self._cond.wait_for(lambda: self._pending is not None or self._stats.frames > 0, timeout_s)

    @property
    def stats(self) -> MocapStats:
        with self._cond:
            return dataclasses.replace(self._stats)

    def close(self) -> None:
        with self._cond:
            if self._closed:
                return
            self._closed = True
            self._cond.notify_all()
        try:
            self._subscriber.undeclare()
        except Exception:  # noqa: BLE001 - a session closed first
            pass

    def __enter__(self) -> RelayedMocap:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
