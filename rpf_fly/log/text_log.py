"""Where the libraries' log records go while a flight's processes run: a text file, and the console only on request.

cflib logs through :mod:`logging` (a traceback at ``error`` for every link it cannot open, warnings for link
errors); with no handler configured Python prints every warning and error on stderr, between the lines the
command means the user to read. :func:`route_logging` sends every record from INFO up (cflib's and rpf_fly's) to
a text file instead, and to stderr as well with ``--verbose``. Here, beside the flight log, rather than in the CLI:
``fly`` and ``check`` route through the application layer, and the distributed flight's own processes (the logger,
the mocap relay: rpf_fly/runtime/) route their records the same way without importing a command.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

FORMAT = "%(asctime)s %(levelname)s %(threadName)s %(name)s: %(message)s"


class LogRouting:
    """The handlers :func:`route_logging` installed on the root logger; :meth:`close` removes them."""

    def __init__(self, path: Path | None, handlers: list[logging.Handler], previous_level: int):
        self.path = path
        self._handlers = handlers
        self._previous_level = previous_level
        self._counter = _Counter()
        root = logging.getLogger()
        root.addHandler(self._counter)
        self._handlers.append(self._counter)

    @property
    def warnings(self) -> int:
        """Records at WARNING or above seen since the routing started."""
        return self._counter.count

    def close(self) -> None:
        root = logging.getLogger()
        for handler in self._handlers:
            root.removeHandler(handler)
            handler.close()
        root.setLevel(self._previous_level)

    def __enter__(self) -> LogRouting:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class _Counter(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.count = 0

    def emit(self, record: logging.LogRecord) -> None:
        self.count += 1


def text_log_path(log_path: Path) -> Path:
    """The libraries' log records of a flight: beside its MCAP log, ``.log`` for ``.mcap``."""
    return log_path.with_suffix(".log") if log_path.suffix != ".log" else log_path.with_name(log_path.name + ".txt")


def route_logging(path: Path | None, verbose: bool = False) -> LogRouting:
    """Send log records (INFO and up) to ``path`` (a text file, overwritten) and, with ``verbose``, to stderr;
    nothing reaches the console otherwise. A file that cannot be opened is skipped (the records are dropped)."""
    root = logging.getLogger()
    previous = root.level
    handlers: list[logging.Handler] = []
    written: Path | None = None
    if path is not None:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            handler: logging.Handler = logging.FileHandler(path, mode="w", encoding="utf-8", delay=False)
            written = path
        except OSError:
            handler = logging.NullHandler()
        handler.setFormatter(logging.Formatter(FORMAT))
        handlers.append(handler)
    if verbose:
        console = logging.StreamHandler(sys.stderr)
        console.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
        handlers.append(console)
    if not handlers:
        handlers.append(logging.NullHandler())  # a handler on the root: Python's last resort stays silent
    for handler in handlers:
        handler.setLevel(logging.INFO)
        root.addHandler(handler)
    root.setLevel(logging.INFO)
    return LogRouting(written, handlers, previous)
