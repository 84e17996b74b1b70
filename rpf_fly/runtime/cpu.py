"""CPU time of the threads Python does not run: Zenoh's runtime (its I/O and timer threads), for a worker's honest
logging figure (docs/performance.md).

A worker's log messages cost CPU in three places: the flight loop that hands them over, the log writer thread that
encodes and publishes them, and Zenoh's own threads that batch and send them (Rust, named ``tx-0``, ``rx-0``,
``net-0``, ``app-0``, ``acc-0``: invisible to ``time.thread_time`` of any Python thread). The first two are measured
with ``time.thread_time``; this module reads the third from ``/proc/self/task`` (Linux; None elsewhere).
"""

from __future__ import annotations

import os
import re

ZENOH_THREAD = re.compile(r"^(tx|rx|net|app|acc)-\d+$")
"""The names Zenoh's runtime gives its threads (zenoh 1.x)."""
ZENOH_SENDING = re.compile(r"^(tx|net|app)-\d+$")
"""Those that send what this process publishes (``rx-*`` receive, and run the subscribers' callbacks: a worker's
relayed mocap frames are its input, not its logging)."""


def zenoh_threads_cpu_s(names: re.Pattern = ZENOH_THREAD) -> float | None:
    """CPU seconds (user + system) of this process's Zenoh runtime threads so far (those whose name ``names``
    matches); None where /proc has no tasks."""
    tasks = "/proc/self/task"
    if not os.path.isdir(tasks):
        return None
    tick = os.sysconf("SC_CLK_TCK")
    total = 0
    for tid in os.listdir(tasks):
        try:
            with open(f"{tasks}/{tid}/comm") as f:
                if not names.match(f.read().strip()):
                    continue
            with open(f"{tasks}/{tid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:  # the thread ended meanwhile
            continue
        total += int(fields[11]) + int(fields[12])  # utime, stime (fields 14 and 15 of stat)
    return total / tick
