"""GcPacer: while active, the automatic collector is off, what lived at the start is frozen, and collect_if_due
reclaims cyclic garbage on CPython's own schedule; stop() gives everything back as it was."""

from __future__ import annotations

import gc
import weakref

import pytest

from rpf_fly.flight.gc_pacing import GcPacer


class Node:
    def __init__(self) -> None:
        self.other: object = None


def cycle() -> weakref.ref:
    a, b = Node(), Node()
    a.other, b.other = b, a
    return weakref.ref(a)


@pytest.fixture(autouse=True)
def restore_gc():  # type: ignore[no-untyped-def]
    enabled, threshold = gc.isenabled(), gc.get_threshold()
    yield
    gc.unfreeze()
    gc.set_threshold(*threshold)
    gc.enable() if enabled else gc.disable()


def test_start_freezes_and_disables_stop_restores():
    gc.enable()
    pacer = GcPacer()
    with pacer:
        assert pacer.active and not gc.isenabled() and gc.get_freeze_count() > 0
        pacer.start()  # idempotent
        assert pacer.active
    assert not pacer.active and gc.isenabled() and gc.get_freeze_count() == 0
    pacer.stop()  # idempotent
    assert gc.isenabled()


def test_a_collector_disabled_before_stays_disabled():
    gc.disable()
    with GcPacer():
        pass
    assert not gc.isenabled()


def test_cyclic_garbage_waits_for_the_pacer_and_is_collected_when_due():
    gc.set_threshold(50, 10, 10)
    with GcPacer() as pacer:
        assert pacer.collect_if_due() == -1  # just collected and frozen: nothing due
        ref = cycle()
        assert ref() is not None  # unreachable, but only a collection frees a cycle, and none runs by itself
        keep = [Node() for _ in range(100)]  # 100 tracked allocations: past the young threshold
        assert gc.get_count()[0] > 50
        assert ref() is not None
        assert pacer.collect_if_due() == 0
        assert ref() is None
        assert pacer.stats.collections == [1, 0, 0] and pacer.stats.seconds[0] > 0
        del keep


def test_older_generations_come_due_on_cpythons_schedule():
    gc.set_threshold(10, 2, 2)
    generations = []
    keep = []
    with GcPacer() as pacer:
        for _ in range(40):
            keep.append([Node() for _ in range(20)])  # live allocations push the young count past 10
            generation = pacer.collect_if_due()
            if generation >= 0:
                generations.append(generation)
    # a generation is collected when its count exceeds its threshold: after three young collections a middle
    # one, after three middle ones a full one
    assert generations[:16] == [0, 0, 0, 1] * 3 + [0, 0, 0, 2]
    assert pacer.stats.collections[2] >= 1


def test_inactive_pacer_never_collects():
    assert GcPacer().collect_if_due() == -1
