"""`Outbox`: the order and the coalescing rules of a drone's queued commands, on its real sender thread."""

from __future__ import annotations

import threading
from collections.abc import Callable

from rpf_fly.radio.outbox import Outbox


class Radio:
    """What the outbox's thread sent, in order; ``hold`` blocks the thread inside its current send (a dying link)."""

    def __init__(self) -> None:
        self.sent: list[str] = []
        self.hold = threading.Event()
        self.hold.set()
        self.inside = threading.Event()

    def run(self, action: Callable[[], None]) -> None:
        self.inside.set()
        self.hold.wait(5.0)
        action()

    def packet(self, label: str) -> Callable[[], None]:
        return lambda: self.sent.append(label)


def blocked_outbox() -> tuple[Outbox, Radio]:
    """An outbox whose thread is stuck in the send of ``first`` until ``radio.hold`` is set."""
    radio = Radio()
    radio.hold.clear()
    box = Outbox("cf1", radio.run)
    box.command(radio.packet("first"), ends_stream=False)
    assert radio.inside.wait(2.0)
    return box, radio


def test_setpoints_are_latest_wins_and_commands_keep_their_order() -> None:
    box, radio = blocked_outbox()
    for i in range(5):
        assert box.setpoint(radio.packet(f"sp{i}"))
    box.command(radio.packet("arm"), ends_stream=False)  # arming does not end the stream: the setpoint stays
    box.extpos(radio.packet("ext0"))
    box.extpos(radio.packet("ext1"))
    radio.hold.set()
    assert box.wait_idle(2.0)
    assert radio.sent == ["first", "arm", "sp4", "ext1"]
    assert box.setpoints_replaced == 4


def test_a_landing_drops_the_setpoint_queued_before_it_and_keeps_the_one_after() -> None:
    box, radio = blocked_outbox()
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


def test_clear_drops_everything_pending_and_close_flushes_then_refuses() -> None:
    box, radio = blocked_outbox()
    box.command(radio.packet("go-to"), ends_stream=True)
    box.setpoint(radio.packet("sp"))
    box.clear()
    box.command(radio.packet("disarm"), ends_stream=False)
    radio.hold.set()
    assert box.close(flush_s=2.0)
    assert radio.sent == ["first", "disarm"]  # the disarm queued before close went out
    assert not box.command(radio.packet("late"), ends_stream=False) and not box.setpoint(radio.packet("late"))
    assert not box._thread.is_alive()


def test_close_gives_up_on_a_stuck_send_after_its_flush_time() -> None:
    box, radio = blocked_outbox()
    box.command(radio.packet("land"), ends_stream=True)
    assert not box.close(flush_s=0.2)
    radio.hold.set()
    box._thread.join(2.0)
    assert radio.sent == ["first"]  # what was still waiting at close was dropped


def test_a_raising_send_does_not_end_the_thread() -> None:
    sent: list[str] = []

    def fail() -> None:
        raise RuntimeError("link")

    box = Outbox("cf2", lambda action: action())
    box.command(fail, ends_stream=False)
    box.command(lambda: sent.append("next"), ends_stream=False)
    assert box.wait_idle(2.0)
    assert sent == ["next"]
    box.close(0.5)
