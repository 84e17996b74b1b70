"""The dry run's truth feed: a thread of the flight's process that brings the simulated world's true states into the
flight log (``/truth/<drone>``, docs/log-format.md).

The simulated world samples every drone after each of its 10 ms steps, stamped with ``time.monotonic()`` of that
step (:meth:`rpf_fly.emulator.fake_world.FakeWorld.truth_samples`). This thread fetches what accumulated every
`FETCH_PERIOD_S` and hands each sample to the recorder, which turns the stamp into log time with its own offset
(the clock is shared by every process of one machine).

Why a poll of batches (docs/flight.md, "Dry run"): the flight's process pays for the truth with its GIL, and what
costs is each wake-up and each round trip, not the bytes. One fetch of 0.1 s of samples (10 per drone) is one round
trip over the world process's control connection (:meth:`rpf_fly.emulator.world_process.WorldProcess.call`, locked,
shared with the fault hooks) and one small unpickle; a poll at 50 Hz does five times the round trips for the same
samples, and a push of every sample over a socket wakes a receiving thread 100 times a second. The log gets every
sample all the same: latency to the file does not matter, the stamps are the world's.

A fetch that fails (the world process died, a test killed it) stops the feed with one warning; nothing reaches the
flight loop.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from rpf_fly.flight.periodic import PeriodicFeed

logger = logging.getLogger(__name__)

FETCH_PERIOD_S = 0.1
"""How often the feed fetches the samples that accumulated in the world (it keeps 5 s: `TRUTH_BUFFER_S`)."""

TruthBatch = list[tuple[float, dict[str, Any]]]
"""``[(monotonic_s, {drone: (position, yaw, motors, crashed, estimate)})]``, oldest first."""


class TruthFeed(PeriodicFeed):
    """Fetches truth samples with ``fetch()`` on a thread every ``period_s`` and calls ``sink(monotonic_s, states)``
    for each, oldest first. :meth:`stop` joins the thread and fetches one last time, so the log ends with the
    world's last state before the log closes. ``cpu_s``: the thread's CPU time (fetch, unpickle, hand-over)."""

    def __init__(
        self,
        fetch: Callable[[], TruthBatch],
        sink: Callable[[float, dict[str, Any]], None],
        period_s: float = FETCH_PERIOD_S,
    ) -> None:
        super().__init__("truth-feed", period_s)
        self._fetch = fetch
        self._sink = sink
        self.fetches = 0
        self.samples = 0
        self.error: BaseException | None = None

    def _once(self) -> bool:
        """One fetch and hand-over; False once fetching failed (the feed then stays silent)."""
        if self.error is not None:
            return False
        try:
            batch = self._fetch()
        except Exception as err:  # noqa: BLE001 - the world process is gone: no truth, the flight goes on
            self.error = err
            logger.warning("truth feed stopped: %s: %s", type(err).__name__, err)
            return False
        self.fetches += 1
        for stamp_s, states in batch:
            try:
                self._sink(stamp_s, states)
            except Exception:  # noqa: BLE001 - a bad sample loses itself, not the feed
                logger.exception("truth feed: recording a sample failed")
            self.samples += 1
        return True
