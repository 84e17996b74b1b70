"""What ``rpf-fly fly`` prints last on stdout: each drone's outcome only where no final table showed it on the same
screen, then the summary line and the log."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest

import rpf_fly.cli.output
from rpf_fly.cli.fly_cmd import _summary
from rpf_fly.flight.phases import FlightOutcome

REPORT = SimpleNamespace(
    outcomes={f"cf{i}": FlightOutcome.REACHED for i in range(1, 41)} | {"cf41": FlightOutcome.LANDED_EARLY},
    reasons={"cf41": "low battery"},
    error=None,
    stats=SimpleNamespace(summary=lambda: {"ticks": 93, "overruns": 0, "latency_p50_s": 0.003, "latency_p99_s": 0.03}),
)


def printed(capsys, monkeypatch, final_table: bool, terminals: tuple[bool, bool]) -> list[str]:  # type: ignore[no-untyped-def]
    def console(stderr: bool = False, **kwargs):  # type: ignore[no-untyped-def]
        return SimpleNamespace(is_terminal=terminals[1 if stderr else 0])

    monkeypatch.setattr(rpf_fly.cli.output, "console", console)
    _summary(REPORT, Path("flights/f.mcap"), final_table=final_table)
    return capsys.readouterr().out.splitlines()


SUMMARY = [
    "ticks 93, overruns 0, mocap-to-setpoint latency p50 3.00 ms p99 30.00 ms",
    "log: flights/f.mcap  (rpf-fly review flights/f.mcap)",
]


def test_after_the_final_table_on_a_terminal_only_the_summary_line(capsys, monkeypatch):
    assert printed(capsys, monkeypatch, True, (True, True)) == SUMMARY


@pytest.mark.parametrize(
    "final_table, terminals",
    [
        (False, (True, True)),  # --no-console
        (True, (False, True)),  # stdout piped: a script reads it
        (True, (True, False)),
    ],
)  # the table went to a file
def test_without_a_final_table_on_the_screen_every_drone_has_its_line(capsys, monkeypatch, final_table, terminals):
    lines = printed(capsys, monkeypatch, final_table, terminals)
    assert len(lines) == 41 + 2 and lines[0] == "cf1: reached" and lines[40] == "cf41: landed_early (low battery)"
    assert lines[41:] == SUMMARY


def test_the_event_lines_are_spelt_alike_with_and_without_the_status_console(capsys):
    """``[phase] swarm: flying``: the status console (a single process's default), ``--no-console`` and a distributed
    flight's coordinator (tests/cli/test_fly_console.py) print an event's kind in brackets alike."""
    from rpf_fly.cli.flight_console import FlightConsole
    from rpf_fly.cli.fly_cmd import _print_event
    from rpf_fly.flight.events import FlightEvent

    events = [
        FlightEvent(1.0, 2, "phase", "swarm: flying"),
        FlightEvent(2.0, 3, "pose_late", "no pose for 100 ms", "cf2"),
    ]
    console = FlightConsole("m")
    for event in events:
        console.event(event)
    with_console = capsys.readouterr().err.splitlines()
    for event in events:
        _print_event(event)
    assert (
        with_console
        == capsys.readouterr().err.splitlines()
        == ["[phase] swarm: flying", "[pose_late] cf2: no pose for 100 ms"]
    )
