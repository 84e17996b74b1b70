"""A thread that dies while a flight flies is one event line, not a traceback in the middle of the console.

cflib carries a flight's radio on threads of its own (each link's driver thread, each dongle's ``Shared Radio``
thread, the latency ping). An exception it does not catch ends that thread, and Python prints the traceback to
stderr between the flight's lines, with nothing saying what it means for the drones. A Crazyradio pulled out of its
USB port is one: cflib 0.1.34's ``_SharedRadio.run`` gets ``USBError`` (errno 19, ENODEV) from its next vendor
request and its thread ends, so no link on that dongle carries anything again in this process (docs/radio.md, "A
dongle pulled out"; the flight's radio lag check lands what it can, the firmware's watchdog stops the rest).

While a flight flies (`reported_thread_deaths`, around the flight loop's run) such a death is one ERROR event of kind
``thread`` naming the thread and the exception, and its traceback goes to the flight's text log (``.log`` beside the
MCAP log) only. The hook is the process's (`threading.excepthook`); the one before is restored after.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import threading
from collections.abc import Iterator

from rpf_fly.flight.events import ERROR, EventBus

logger = logging.getLogger("rpf_fly.flight")

DONGLE_GONE = (
    ": the dongle is gone (unplugged?): nothing reaches the drones on it from this process any more (their "
    "firmware stops each by its watchdog; restart the program after plugging it back)"
)
"""What an ENODEV in a thread means here: a USB device (a Crazyradio) left while cflib used it."""


def death_message(thread_name: str, exc: BaseException) -> str:
    """The event's line for thread ``thread_name`` ended by ``exc``."""
    meaning = DONGLE_GONE if getattr(exc, "errno", None) == errno.ENODEV else ""
    return f"thread {thread_name!r} ended: {type(exc).__name__}: {exc}{meaning}"


@contextlib.contextmanager
def reported_thread_deaths(events: EventBus) -> Iterator[None]:
    """While the block runs, an uncaught exception in any thread is an ERROR ``thread`` event on ``events`` (and its
    traceback an INFO record of the text log), not Python's traceback on stderr."""
    previous = threading.excepthook

    def report(args: threading.ExceptHookArgs) -> None:
        if args.exc_value is None or issubclass(args.exc_type, SystemExit):
            previous(args)
            return
        name = args.thread.name if args.thread is not None else "unknown"
        try:
            events.emit(ERROR, "thread", death_message(name, args.exc_value))
            logger.info("thread %r ended by", name, exc_info=(args.exc_type, args.exc_value, args.exc_traceback))
        except Exception:  # noqa: BLE001 - a report that fails falls back to Python's own
            previous(args)

    threading.excepthook = report
    try:
        yield
    finally:
        if threading.excepthook is report:  # a hook set after ours (and not undone) stays
            threading.excepthook = previous
