"""What the commands print, on a terminal and piped.

On a terminal rich draws as usual (colours, a live table, a progress bar, the terminal's width). Piped or redirected
(a log file, ``| tee``, CI) rich would cut tables to 80 columns (``landed_ea…``), end a live display without its
newline and draw a progress bar nobody sees move. So a console that is not a terminal is a plain, wide one (no
colours, no cursor control, :data:`PIPE_WIDTH` columns, every line ending in a newline), and progress is one plain
line every :data:`PIPE_PROGRESS_S` seconds (:class:`ProgressLines`).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import Any

PIPE_WIDTH = 240
"""Columns of a console that is not a terminal: wide enough that no table of the commands is cut."""

PIPE_PROGRESS_S = 10.0
"""Seconds between two progress lines when the output is not a terminal."""


def console(stderr: bool = False, pipe_width: int = PIPE_WIDTH, **kwargs: Any):
    """A rich Console on stdout (or stderr): the terminal's own, or a plain one ``pipe_width`` columns wide when not
    a terminal."""
    from rich.console import Console

    made = Console(stderr=stderr, **kwargs)
    if made.is_terminal:
        return made
    return Console(
        stderr=stderr,
        width=pipe_width,
        force_terminal=False,
        no_color=True,
        highlight=False,
        soft_wrap=False,
        **{k: v for k, v in kwargs.items() if k not in ("width", "highlight")},
    )


class ProgressLines:
    """Progress for a console that is not a terminal: ``update`` prints one line at most every ``period_s`` seconds
    (and always for the first and the last step), each ending in a newline."""

    def __init__(
        self,
        label: str,
        total: int,
        unit: str,
        stream: Any = None,
        period_s: float = PIPE_PROGRESS_S,
        clock: Callable[[], float] = time.monotonic,
    ):
        self.label, self.total, self.unit = label, total, unit
        self.stream = stream
        self.period_s = period_s
        self.clock = clock
        self.started = clock()
        self._last: float | None = None
        self._done = False
        self.lines = 0

    def update(self, completed: int, text: str = "", final: bool = False) -> None:
        now = self.clock()
        done = final or completed >= self.total
        if self._done or (not done and self._last is not None and now - self._last < self.period_s):
            return
        self._done = done
        self._last = now
        elapsed = int(now - self.started)
        stream = self.stream or sys.stdout
        tail = f"  {text}" if text else ""
        stream.write(
            f"{self.label}: {completed}/{self.total} {self.unit}  {elapsed // 60:d}:{elapsed % 60:02d}{tail}\n"
        )
        stream.flush()
        self.lines += 1
