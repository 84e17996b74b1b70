"""Waiting in tests for something another thread or process does: poll a condition until it holds or time is up."""

from __future__ import annotations

import time
from collections.abc import Callable


def wait_for(predicate: Callable[[], object], timeout_s: float, poll_s: float = 0.01) -> bool:
    """Poll ``predicate`` every ``poll_s`` until it is true (True) or ``timeout_s`` has passed (its last answer)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(poll_s)
    return bool(predicate())
