"""A thread that dies while a flight flies: one event line, its traceback in the text log
(rpf_fly/flight/thread_deaths.py)."""

from __future__ import annotations

import errno
import logging
import threading
import time

import pytest
import usb.core

from rpf_fly.flight.events import ERROR, EventBus
from rpf_fly.flight.thread_deaths import DONGLE_GONE, reported_thread_deaths


def die_in_thread(name: str, exc: BaseException) -> None:
    def run() -> None:
        raise exc

    thread = threading.Thread(target=run, name=name)
    thread.start()
    thread.join()


def test_a_dongle_pulled_out_under_cflibs_radio_thread_is_one_event_not_a_traceback(
    caplog: pytest.LogCaptureFixture, capsys: pytest.CaptureFixture[str]
) -> None:
    """cflib's ``Shared Radio`` thread ends on the ENODEV its next vendor request gets from an unplugged Crazyradio
    (what pyusb raises, and the emulated dongle too): the flight says so in one line, meaning included, and keeps
    the traceback for the text log."""
    events = EventBus(time.monotonic)
    before = threading.excepthook
    caplog.set_level(logging.INFO, logger="rpf_fly.flight")
    with reported_thread_deaths(events):
        gone = usb.core.USBError("No such device (it may have been disconnected)", errno=errno.ENODEV)
        die_in_thread("Shared Radio", gone)
        die_in_thread("rpf-cf1", ValueError("bad packet"))
    assert threading.excepthook is before
    first, second = events.of_kind("thread")
    assert first.level == ERROR and first.message.startswith("thread 'Shared Radio' ended: USBError: ")
    assert first.message.endswith(DONGLE_GONE)
    assert second.message == "thread 'rpf-cf1' ended: ValueError: bad packet"  # no meaning made up
    assert "Traceback" not in capsys.readouterr().err
    kept = [r for r in caplog.records if r.exc_info is not None]
    assert [r.exc_info[0] for r in kept if r.exc_info] == [usb.core.USBError, ValueError]


def test_outside_a_flight_the_hook_before_speaks_again(monkeypatch: pytest.MonkeyPatch) -> None:
    """The process's hook is the flight's only while it flies: the one before gets every death after it."""
    seen: list[str] = []
    monkeypatch.setattr(threading, "excepthook", lambda args: seen.append(str(args.exc_value)))
    events = EventBus(time.monotonic)
    with reported_thread_deaths(events):
        die_in_thread("during", RuntimeError("ours"))
    die_in_thread("after", RuntimeError("not ours"))
    assert seen == ["not ours"] and [e.message for e in events.of_kind("thread")] == [
        "thread 'during' ended: RuntimeError: ours"
    ]
