"""The flight's status console, shared by ``rpf-fly fly`` (one process: rows from ``FlightLoop.snapshot``) and
``rpf-fly fly --distributed`` (rows from ``Coordinator.snapshot``, built from the drones' status and tf messages).

On a terminal a live table (rich), redrawn at most four times a second; at the end the final table: every drone's
final state and outcome. Not a terminal: the lines as plain lines and the final table once, wide, with its newline
(cli/output.py). One table builder for both paths: a row is ``{name, phase, position, goal_distance, battery_v,
link_pct}``; a distributed flight's rows add ``worker`` (and ``lost``: that worker is gone), which adds a worker
column; the final rows add ``outcome`` and ``reason``.
"""

from __future__ import annotations

import time
from types import TracebackType
from typing import Any

import typer

REFRESH_S = 0.25
"""The live table is redrawn at most this often (4 Hz): more is unreadable and costs the flight's thread."""

FINAL_STATES = {
    "landed": "landed",
    "emergency": "stopped",
    "link_lost": "link lost",
    "failed": "grounded",
    "grounded": "on the floor (did not lift off)",
    "landing": "landing, touchdown not confirmed",
}
"""What the final table says of a drone's last phase (flight/phases.py): ``stopped`` is motors cut by an
emergency stop; a drone still ``landing`` at the end never had its touchdown confirmed (docs/flight.md)."""


def final_state(phase: str) -> str:
    return FINAL_STATES.get(phase, phase)


def worker_cell(row: dict[str, Any]) -> str:
    """A distributed flight's worker column: the worker's name, ``(lost)`` once its liveliness token vanished."""
    return f"{row['worker']}{' (lost)' if row.get('lost') else ''}"


class FlightConsole:
    """The status table of one flight on stderr: :meth:`show` redraws it live (a terminal only), :meth:`line` and
    :meth:`event` print above it, :meth:`final` prints how the flight ended."""

    def __init__(self, name: str):
        from rich.live import Live

        from rpf_fly.cli.output import console

        self.name = name
        self.console = console(stderr=True)
        self.live = (
            Live(console=self.console, refresh_per_second=4, transient=False) if self.console.is_terminal else None
        )
        self._last = 0.0

    def __enter__(self) -> FlightConsole:
        if self.live is not None:
            self.live.__enter__()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if self.live is not None:
            self.live.__exit__(exc_type, exc, tb)

    def line(self, text: str) -> None:
        """One line as it is (no markup): above the live table on a terminal, a plain line otherwise."""
        if self.live is None:
            typer.echo(text, err=True)
        else:
            from rich.text import Text

            self.console.print(Text(text), soft_wrap=True)

    def event(self, event) -> None:
        from rich.markup import escape

        if event.level >= 3 or (event.drone is None and event.kind == "phase"):
            who = f"{event.drone}: " if event.drone else ""
            style = {3: "yellow", 4: "red", 5: "bold red"}.get(event.level, "")
            kind, text = escape(f"[{event.kind}]"), escape(f"{who}{event.message}")  # as every flight's lines spell it
            self.console.print(f"[{style}]{kind}[/{style}] {text}" if style else f"{kind} {text}")

    def show(self, phase: str, rows_of: Any) -> None:
        """Redraw the live table (a terminal only, at most every :data:`REFRESH_S`); ``rows_of()`` gives the rows,
        called only when the table is redrawn."""
        if self.live is None:
            return
        now = time.monotonic()
        if now - self._last < REFRESH_S:
            return
        self._last = now
        self.live.update(table(f"{self.name}: {phase}", rows_of()))

    def final(self, phase: str, rows: list[dict[str, Any]]) -> None:
        """The table of how the flight ended: each drone's final state, its outcome (``-``: none known) and, for a
        drone that did not reach its goal, why."""
        for row in rows:
            row["phase"] = final_state(str(row["phase"]))
            row["outcome"] = row.get("outcome") or "-"
            row["why"] = (row.get("reason") or "") if row["outcome"] != "reached" else ""
        made = table(f"{self.name}: {phase}", rows, final=True)
        if self.live is not None:
            self.live.update(made, refresh=True)
        else:
            self.console.print(made)


def table(title: str, rows: list[dict[str, Any]], final: bool = False):
    """The status table (rich): drone, [worker,] state, [outcome,] position, distance to goal, battery, link[, why]."""
    from rich.markup import escape
    from rich.table import Table

    made = Table(title=escape(title))
    workers = any("worker" in row for row in rows)
    columns = (
        ["drone"]
        + (["worker"] if workers else [])
        + ["state"]
        + (["outcome"] if final else [])
        + ["x", "y", "z", "to goal [m]", "battery [V]", "link [%]"]
    )
    why = final and any(row.get("why") for row in rows)
    if why:
        columns.append("why")
    for column in columns:
        left = column in ("drone", "worker", "state", "outcome", "why")
        made.add_column(escape(column), justify="left" if left else "right")
    for row in rows:
        pos: Any | None = row["position"]
        cells = [escape(str(row["name"]))] + ([escape(worker_cell(row))] if workers else [])
        cells += [escape(str(row["phase"]))] + ([escape(str(row["outcome"]))] if final else [])
        cells += [*(f"{v:.2f}" for v in pos)] if pos else ["-", "-", "-"]
        cells += [
            "-" if row["goal_distance"] is None else f"{row['goal_distance']:.2f}",
            "-" if row["battery_v"] is None else f"{row['battery_v']:.2f}",
            "-" if row["link_pct"] is None else f"{row['link_pct']:.0f}",
        ]
        if why:
            cells.append(escape(str(row.get("why") or "")))
        made.add_row(*cells)
    return made
