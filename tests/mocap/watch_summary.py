"""``mocap watch``'s summary read back, and a stream that stops while the watch goes on."""

from __future__ import annotations

import re
import threading

from rpf_fly.emulator.natnet_server import NatNetServer

SUMMARY = re.compile(r"summary: (\d+) frames over ([\d.]+) s, ([\d.]+) Hz \(first to last\); watched ([\d.]+) s; ")


def summary_numbers(head: str) -> tuple[int, float, float, float]:
    """The summary's frames, their span [s] and rate [Hz], and the watch's duration [s]."""
    found = SUMMARY.match(head)
    assert found, head
    return int(found[1]), float(found[2]), float(found[3]), float(found[4])


def stop_after(server: NatNetServer, seconds: float) -> threading.Timer:
    """Close ``server`` (its stream stops) ``seconds`` from now, while a watch goes on."""
    timer = threading.Timer(seconds, server.close)
    timer.start()
    return timer
