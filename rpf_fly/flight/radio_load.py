"""The radio's measured load per dongle, into the flight log (``/radio/<dongle>``, docs/log-format.md).

A thread of the flight's process samples the backend's per-link counts (:meth:`CflibBackend.radio_counts`: cflib's
own link statistics, i.e. the acknowledgements the radio saw) every `PERIOD_S`, adds them up per dongle
(:func:`rpf_fly.radio.schedule.dongle_loads`) and hands each dongle's window to the recorder, with what the radio
budget planned for that dongle and what it carries. Nothing here touches the flight loop: one lock-guarded copy
of a few numbers a second from the backend, so its cost is nil beside the loop's.

The first sample is the baseline (a flight's recorder starts before the links connect: zeros); :meth:`stop` takes
one last sample, so the windows add up to every packet counted from the baseline to the end.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterable, Mapping

from rpf_fly.flight.periodic import PeriodicFeed
from rpf_fly.radio.schedule import LinkCount, MeasuredLoad, dongle_loads

logger = logging.getLogger(__name__)

PERIOD_S = 1.0
"""One window a second per dongle: `rpf-fly review` compares packets a second with the budget."""


class RadioLoadFeed(PeriodicFeed):
    """Calls ``sink(monotonic_s, [MeasuredLoad per dongle])`` every ``period_s`` with the traffic since the previous
    sample of ``fetch()`` (drone -> :class:`LinkCount`). ``dongles``: the mission's dongles, reported from the first
    window (zeros until their links connect)."""

    def __init__(
        self,
        fetch: Callable[[], Mapping[str, LinkCount]],
        sink: Callable[[float, list[MeasuredLoad]], None],
        dongles: Iterable[int] = (),
        period_s: float = PERIOD_S,
    ) -> None:
        super().__init__("radio-load", period_s)
        self._fetch = fetch
        self._sink = sink
        self._dongles = tuple(sorted(set(dongles)))
        self._lock = threading.Lock()
        self._last: Mapping[str, LinkCount] = {}
        self._last_s = time.monotonic()
        self.windows = 0
        self.error: BaseException | None = None

    def start(self) -> RadioLoadFeed:
        self._last, self._last_s = dict(self._fetch()), time.monotonic()
        super().start()
        return self

    def _once(self) -> bool:
        with self._lock:
            if self.error is not None:
                return False
            try:
                counts = dict(self._fetch())
                now = time.monotonic()
                loads = dongle_loads(self._last, counts, now - self._last_s, self._dongles)
                self._last, self._last_s = counts, now
                self._sink(now, loads)
                self.windows += 1
            except Exception as err:  # noqa: BLE001 - the flight goes on without its radio figures
                self.error = err
                logger.warning("radio load feed stopped: %s: %s", type(err).__name__, err)
                return False
        return True
