"""`Outbox` and `SenderPool`: the order and the coalescing rules of a drone's queued commands, and the pool's
threads (one for the whole swarm normally, another taking over when one is stuck in a dying link), on real
threads."""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable
from functools import partial

from rpf_fly.radio import outbox
from rpf_fly.radio.cflib_connect import link_room
from rpf_fly.radio.outbox import STUCK_S, Outbox, SenderPool


class Radio:
    """What the pool sent, in order, and from which thread; ``hold`` blocks a send of a drone named in ``stuck``
    (a dying link) until it is set."""

    def __init__(self, stuck: tuple[str, ...] = ()) -> None:
        self.sent: list[str] = []
        self.threads: dict[str, set[int]] = {}
        self.stuck = stuck
        self.hold = threading.Event()
        self.inside = threading.Event()

    def runner(self, name: str) -> Callable[[Callable[[], None]], None]:
        def run(action: Callable[[], None]) -> None:
            self.threads.setdefault(name, set()).add(threading.get_ident())
            if name in self.stuck:
                self.inside.set()
                self.hold.wait(5.0)
            action()

        return run

    def packet(self, label: str) -> Callable[[], None]:
        return lambda: self.sent.append(label)


def blocked_outbox() -> tuple[Outbox, Radio, SenderPool]:
    """An outbox whose send is stuck in ``first`` until ``radio.hold`` is set."""
    radio = Radio(stuck=("cf1",))
    pool = SenderPool()
    box = pool.outbox("cf1", radio.runner("cf1"))
    box.command(radio.packet("first"), ends_stream=False)
    assert radio.inside.wait(2.0)
    return box, radio, pool


def test_setpoints_are_latest_wins_and_commands_keep_their_order() -> None:
    box, radio, pool = blocked_outbox()
    for i in range(5):
        assert box.setpoint(radio.packet(f"sp{i}"))
    box.command(radio.packet("arm"), ends_stream=False)  # arming does not end the stream: the setpoint stays
    box.extpos(radio.packet("ext0"))
    box.extpos(radio.packet("ext1"))
    radio.hold.set()
    assert box.wait_idle(2.0)
    assert radio.sent == ["first", "arm", "sp4", "ext1"]
    assert box.setpoints_replaced == 4
    pool.close()


def test_a_setpoint_waiting_behind_a_stuck_send_says_how_long_since_the_first_it_replaced() -> None:
    """`Outbox.setpoint_waiting_s`: from the first setpoint queued while none waited, through the newer ones that
    replaced it, until one is sent (the radio lag check lands a drone left without setpoints so long)."""
    box, radio, pool = blocked_outbox()
    assert box.setpoint_waiting_s() == 0.0
    box.setpoint(radio.packet("sp0"))
    time.sleep(0.2)
    box.setpoint(radio.packet("sp1"))  # replaces it: the same wait goes on
    assert 0.2 <= box.setpoint_waiting_s() < 2.0
    radio.hold.set()
    assert box.wait_idle(2.0)
    assert radio.sent == ["first", "sp1"] and box.setpoint_waiting_s() == 0.0
    pool.close()


def test_a_landing_drops_the_setpoint_queued_before_it_and_keeps_the_one_after() -> None:
    box, radio, pool = blocked_outbox()
    box.setpoint(radio.packet("before"))
    box.command(radio.packet("land"), ends_stream=True)
    radio.hold.set()
    assert box.wait_idle(2.0)
    assert radio.sent == ["first", "land"]  # nothing queued before the land reaches the drone after it

    radio.hold.clear()
    radio.inside.clear()
    box.command(radio.packet("take-off"), ends_stream=True)
    assert radio.inside.wait(2.0)
    box.setpoint(radio.packet("after"))
    box.command(radio.packet("hand-over"), ends_stream=True)
    box.setpoint(radio.packet("after the hand-over"))
    radio.hold.set()
    assert box.wait_idle(2.0)
    assert radio.sent == ["first", "land", "take-off", "hand-over", "after the hand-over"]
    pool.close()


def test_clear_drops_everything_pending_and_close_flushes_then_refuses() -> None:
    box, radio, pool = blocked_outbox()
    box.command(radio.packet("go-to"), ends_stream=True)
    box.setpoint(radio.packet("sp"))
    box.clear()
    box.command(radio.packet("disarm"), ends_stream=False)
    radio.hold.set()
    assert box.close(flush_s=2.0)
    assert radio.sent == ["first", "disarm"]  # the disarm queued before close went out
    assert not box.command(radio.packet("late"), ends_stream=False) and not box.setpoint(radio.packet("late"))
    pool.close()
    assert not any(t.is_alive() for t in pool._threads)


def test_close_gives_up_on_a_stuck_send_after_its_flush_time() -> None:
    box, radio, pool = blocked_outbox()
    box.command(radio.packet("land"), ends_stream=True)
    assert not box.close(flush_s=0.2)
    radio.hold.set()
    pool.close(join_s=2.0)
    assert radio.sent == ["first"]  # what was still waiting at close was dropped


def test_a_raising_send_does_not_end_the_thread() -> None:
    sent: list[str] = []

    def fail() -> None:
        raise RuntimeError("link")

    pool = SenderPool()
    box = pool.outbox("cf2", lambda action: action())
    box.command(fail, ends_stream=False)
    box.command(lambda: sent.append("next"), ends_stream=False)
    assert box.wait_idle(2.0)
    assert sent == ["next"]
    pool.close()


def test_one_thread_sends_a_whole_swarm_in_turn() -> None:
    radio = Radio()
    pool = SenderPool()
    boxes = [pool.outbox(f"cf{i}", radio.runner(f"cf{i}")) for i in range(10)]
    for tick in range(20):
        for i, box in enumerate(boxes):
            box.setpoint(radio.packet(f"cf{i}/{tick}"))
        assert pool.wait_idle(boxes, 2.0)
    # one thread for the swarm (a second one only where the machine held a send past STUCK_S), not one a drone
    assert len(radio.sent) == 200 and pool.threads <= 2
    assert radio.sent[:10] == [f"cf{i}/0" for i in range(10)]  # in the order their work arrived
    pool.close()


def test_a_drone_stuck_in_its_send_keeps_one_thread_and_another_sends_the_others() -> None:
    radio = Radio(stuck=("cf1",))
    pool = SenderPool()
    stuck = pool.outbox("cf1", radio.runner("cf1"))
    others = [pool.outbox(f"cf{i}", radio.runner(f"cf{i}")) for i in (2, 3)]
    stuck.setpoint(radio.packet("cf1/0"))
    assert radio.inside.wait(2.0)
    time.sleep(2 * STUCK_S)
    for tick in range(5):
        stuck.setpoint(radio.packet(f"cf1/{tick + 1}"))  # waits, newest only
        for i, box in zip((2, 3), others):
            box.setpoint(radio.packet(f"cf{i}/{tick}"))
        assert pool.wait_idle(others, 1.0), radio.sent  # the others go out while cf1 is stuck
        assert not stuck.idle()
    assert [s for s in radio.sent if s.startswith("cf1")] == []  # cf1/0 is still inside its send
    assert 2 <= pool.threads <= 3 and not (radio.threads["cf2"] | radio.threads["cf3"]) & radio.threads["cf1"]
    radio.hold.set()
    assert stuck.wait_idle(2.0)
    assert [s for s in radio.sent if s.startswith("cf1")] == ["cf1/0", "cf1/5"]
    assert stuck.setpoints_replaced == 4
    pool.close()


def test_work_queued_behind_a_send_that_then_blocks_is_taken_over_without_another_call() -> None:
    """The watchdog's landings while the loop is stalled: cf1's land goes first and its send blocks (a dying link);
    cf2's land, queued a moment later, must not wait for it although nobody queues or waits any more (the pool's
    watcher looks again once cf1's send counts as stuck)."""
    radio = Radio(stuck=("cf1",))
    pool = SenderPool()
    stuck, other = pool.outbox("cf1", radio.runner("cf1")), pool.outbox("cf2", radio.runner("cf2"))
    t0 = time.monotonic()
    sent_at: dict[str, float] = {}
    stuck.command(lambda: sent_at.setdefault("cf1", time.monotonic() - t0), ends_stream=True)
    other.command(lambda: sent_at.setdefault("cf2", time.monotonic() - t0), ends_stream=True)
    deadline = time.monotonic() + 1.0
    while "cf2" not in sent_at and time.monotonic() < deadline:
        time.sleep(0.005)
    assert "cf2" in sent_at and sent_at["cf2"] < 0.2, sent_at  # STUCK_S after cf1's send began, not after it
    assert "cf1" not in sent_at
    radio.hold.set()
    assert stuck.wait_idle(2.0)
    pool.close()


def test_a_cleared_and_refusing_outbox_takes_nothing_more() -> None:
    box, radio, pool = blocked_outbox()
    box.setpoint(radio.packet("sp"))
    box.clear(refuse=True)  # an emergency stop
    assert not box.setpoint(radio.packet("late")) and not box.command(radio.packet("land"), ends_stream=True)
    radio.hold.set()
    assert box.wait_idle(2.0)
    assert radio.sent == ["first"]
    pool.close()


def test_keep_alives_never_stack_behind_a_stuck_link_and_go_out_first() -> None:
    """A keep-alive queued while the previous one still waits is skipped: behind a stuck send at most one waits, so
    the link sends no late burst when it comes back; it goes out before the commands queued ahead of it (it changes
    nothing but the drone's watchdog)."""
    box, radio, pool = blocked_outbox()
    box.command(radio.packet("land"), ends_stream=True)
    assert box.keepalive(radio.packet("alive0"))
    for i in range(1, 5):  # a second of keep-alives at 0.2 s while the link is stuck
        assert not box.keepalive(radio.packet(f"alive{i}"))
    assert box.keepalives_skipped == 4
    radio.hold.set()
    assert box.wait_idle(2.0)
    assert radio.sent == ["first", "alive0", "land"]
    assert box.keepalive(radio.packet("alive5")) and box.wait_idle(2.0)  # sent: the slot is free again
    assert radio.sent[-1] == "alive5"
    pool.close()


def test_keep_alives_are_dropped_by_clear_and_refused_once_closed() -> None:
    box, radio, pool = blocked_outbox()
    assert box.keepalive(radio.packet("alive0"))
    box.clear(refuse=True)  # an emergency stop: nothing may follow it
    assert not box.keepalive(radio.packet("alive1"))
    radio.hold.set()
    assert box.wait_idle(2.0)
    assert radio.sent == ["first"]
    other = pool.outbox("cf2", radio.runner("cf2"))
    assert other.close(flush_s=1.0) and not other.keepalive(radio.packet("alive2"))
    pool.close()


def test_an_extpos_whose_pose_waited_too_long_is_dropped_and_counted_not_sent(caplog) -> None:
    """A pose that waited longer than `EXTPOS_MAX_WAIT_S` in the ground station (here behind a stuck send) would
    pull the estimator back along the drone's path: it is dropped when a sender takes it, counted and said once; a
    fresh one and one without a receipt time go out."""
    from rpf_fly.radio.outbox import EXTPOS_MAX_WAIT_S

    box, radio, pool = blocked_outbox()
    box.extpos(radio.packet("old"), received_s=time.monotonic())
    time.sleep(EXTPOS_MAX_WAIT_S + 0.02)  # it waits behind the stuck send past the bound
    radio.hold.set()
    assert box.wait_idle(2.0)
    assert radio.sent == ["first"] and box.extpos_stale == 1
    assert box.extpos_taken_s is None  # nothing fed the drone's estimator (the estimate check reads this)
    assert "waited" in caplog.text and "not sent to its estimator" in caplog.text
    before = time.monotonic()
    box.extpos(radio.packet("fresh"), received_s=time.monotonic())
    assert box.wait_idle(2.0)
    assert box.extpos_taken_s is not None and before <= box.extpos_taken_s <= time.monotonic()
    box.extpos(radio.packet("unstamped"))  # no receipt time: sent whatever its age
    assert box.wait_idle(2.0)
    assert radio.sent == ["first", "fresh", "unstamped"] and box.extpos_stale == 1
    pool.close()


class Link:
    """cflib's radio link as the sender sees it: ``link.out_queue``, the driver's ``Queue(1)``."""

    def __init__(self) -> None:
        self.out_queue: queue.Queue[str] = queue.Queue(1)


class Cf:
    def __init__(self) -> None:
        self.link = Link()


def test_a_sender_waits_for_room_in_cflibs_queue_and_then_sends_the_newest_setpoint(monkeypatch) -> None:
    """Room first: with the link's one-packet queue full, setpoints queued meanwhile replace each other in the
    outbox; when the driver takes the packet waiting there, the newest goes in, without blocking in ``put``."""
    monkeypatch.setattr(outbox, "ROOM_WAIT_S", 30.0)  # however slow the host, the wait outlasts the test's steps
    cf = Cf()
    cf.link.out_queue.put("older")  # the driver has not taken it yet
    pool = SenderPool("room")
    handed: list[tuple[str, bool]] = []

    def run(action: Callable[[], None]) -> None:
        action()

    def setpoint(label: str) -> Callable[[], None]:
        def send() -> None:
            room = not cf.link.out_queue.full()
            cf.link.out_queue.put(label, timeout=2.0)  # as cflib's RadioDriver.send_packet
            handed.append((label, room))

        return send

    box = pool.outbox("cf1", run, partial(link_room, cf))
    try:
        for k in range(5):
            box.setpoint(setpoint(f"sp{k}"))
            time.sleep(0.02)
        assert handed == []  # nothing taken while there is no room: the newest waits in the outbox
        assert cf.link.out_queue.get(timeout=1.0) == "older"  # the driver takes its next packet
        assert box.wait_idle(10.0)
        assert handed == [("sp4", True)] and box.setpoints_replaced == 4
        assert cf.link.out_queue.get(timeout=1.0) == "sp4"
    finally:
        pool.close()


def test_waiting_for_room_passes_the_wake_up_on_to_cflibs_own_blocked_sender() -> None:
    """The driver's take wakes one waiter. When that is the room wait and the sender then sends nothing (its extpos
    was stale), cflib's own sender blocked in ``put`` (a parameter, a log block, its ping) must still get the
    slot at once, not wait out its 2 s timeout on an empty queue."""
    cf = Cf()
    cf.link.out_queue.put("older")
    room_waiting = threading.Event()
    got: list[bool] = []

    def waiter() -> None:
        room_waiting.set()
        got.append(link_room(cf, 2.0))  # then takes nothing

    def cflib_sender(done: list[float]) -> None:
        began = time.monotonic()
        cf.link.out_queue.put("ping", timeout=2.0)
        done.append(time.monotonic() - began)

    def waiters(n: int) -> None:  # CPython's Condition keeps its waiters in order: wait for the n-th to queue
        deadline = time.monotonic() + 10.0
        while len(cf.link.out_queue.not_full._waiters) < n and time.monotonic() < deadline:  # type: ignore[attr-defined]
            time.sleep(0.005)

    threading.Thread(target=waiter, daemon=True).start()
    room_waiting.wait(1.0)
    waiters(1)  # the room wait first
    put_took: list[float] = []
    blocked = threading.Thread(target=cflib_sender, args=(put_took,), daemon=True)
    blocked.start()
    waiters(2)  # then cflib's put: two waiters for one slot
    assert cf.link.out_queue.get(timeout=1.0) == "older"  # the driver takes: one notification, to the first
    blocked.join(1.5)
    assert got == [True] and put_took and put_took[0] < 1.0, (got, put_took)
    assert cf.link.out_queue.get(timeout=1.0) == "ping"


def test_a_link_without_a_bounded_queue_has_room_at_once() -> None:
    class Fake:
        link = object()  # fake:// takes every packet at once

    began = time.monotonic()
    assert link_room(Fake(), 5.0) and time.monotonic() - began < 1.0
