"""Python's cyclic garbage collector paced by the flight loop, so its pauses never fall between a mocap frame and
its setpoints.

Left alone, the collector runs whenever any thread of the process (the loop, cflib's link threads, the log writer)
has allocated 700 more container objects than it freed, wherever that thread happens to be. In a 10-drone, 100 Hz
dry run that is a young-generation pass every ~0.3 s costing 0.2-2 ms, a middle-generation pass every few seconds
costing ~1 ms, and a full pass over every object of the process (numpy, onnxruntime, cflib, the mission) costing
~30 ms: each lands on whatever it interrupts, a planning tick included (docs/flight.md, "Garbage collection").

While flying, :class:`GcPacer` instead:

- *freezes* every object that lives at take-off (``gc.freeze``: the modules, the mission, the connected links;
  they are never scanned again during the flight), without collecting first: a collection over every object of the
  process takes 25-45 ms on an idle 2-core host and took 1.2 s on a loaded one, a second without extpos before
  take-off in which the drones' estimates drifted 0.2 m and one stayed on the floor; the little garbage frozen with
  the rest is freed when the flight gives the collector back;
- disables the automatic collector and runs the same generational schedule itself (:meth:`GcPacer.collect_if_due`,
  from the loop right after its work for a frame, in the gap before the next one): a generation is collected when
  CPython's own thresholds say it is due, so garbage is reclaimed as often as before, only at a chosen moment;
- restores the collector as it found it on exit, whatever ends the flight.
"""

from __future__ import annotations

import gc
import time
from dataclasses import dataclass, field


@dataclass
class GcStats:
    """Collections the pacer ran per generation and their total wall time (seconds)."""

    collections: list[int] = field(default_factory=lambda: [0, 0, 0])
    seconds: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    freeze_s: float = 0.0


class GcPacer:
    """Context manager: inside it the loop decides when the garbage collector runs (see the module docstring)."""

    def __init__(self) -> None:
        self.stats = GcStats()
        self._was_enabled = False
        self._active = False

    @property
    def active(self) -> bool:
        return self._active

    def start(self) -> None:
        """Freeze what lives now (no collection: module doc), then take over the schedule (idempotent)."""
        if self._active:
            return
        self._was_enabled = gc.isenabled()
        t0 = time.perf_counter()
        gc.freeze()
        self.stats.freeze_s = time.perf_counter() - t0
        gc.disable()
        self._active = True

    def stop(self) -> None:
        """Give the schedule back: unfreeze, and re-enable the collector if it was enabled (idempotent)."""
        if not self._active:
            return
        self._active = False
        gc.unfreeze()
        if self._was_enabled:
            gc.enable()

    def __enter__(self) -> GcPacer:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def collect_if_due(self) -> int:
        """Collect the oldest generation whose count exceeds its threshold, as CPython's automatic collector does
        (a full collection skips CPython's extra "enough long-lived objects" condition: with the start's objects
        frozen it only scans what the flight created); -1 if none is due. Cheap when nothing is due."""
        if not self._active:
            return -1
        count0, count1, count2 = gc.get_count()
        threshold0, threshold1, threshold2 = gc.get_threshold()
        if threshold0 <= 0 or count0 <= threshold0:
            return -1
        generation = 0
        if count1 > threshold1:
            generation = 2 if count2 > threshold2 else 1
        t0 = time.perf_counter()
        gc.collect(generation)
        self.stats.collections[generation] += 1
        self.stats.seconds[generation] += time.perf_counter() - t0
        return generation
