"""``rpf-fly fly``'s console, piped (not a terminal) as CI and ``| tee`` see it: the final table holds every drone's
final state, is not cut, and ends with its newline."""

from __future__ import annotations

import re

import pytest

# Its module and session fixtures fly once: the tests sharing them run on one xdist worker (pyproject: --dist
# loadgroup).
pytestmark = pytest.mark.xdist_group("cli_flights")


def final_table(stderr: str) -> list[str]:
    """The lines of the last table on stderr (from its title to its bottom border)."""
    lines = stderr.splitlines()
    bottom = max(i for i, line in enumerate(lines) if line.startswith("└"))
    top = max(i for i, line in enumerate(lines[:bottom]) if line.startswith("┏"))
    return lines[top - 1 : bottom + 1]


def rows(table: list[str]) -> dict[str, list[str]]:
    return {
        cells[0]: cells
        for cells in ([c.strip() for c in line.strip("│").split("│")] for line in table if line.startswith("│"))
    }


def test_a_clean_flight_ends_with_every_drone_landed(clean_cli_flight):
    flight = clean_cli_flight
    assert flight.returncode == 0, flight.stderr
    table = final_table(flight.stderr)
    assert table[0].strip() == "short-3: done"
    header = " ".join(table[2].split())
    assert "state" in header and "outcome" in header and "to goal [m]" in header and "battery [V]" in header
    found = rows(table)
    assert set(found) == {"cf1", "cf2", "cf3"}
    for cells in found.values():
        assert cells[1:3] == ["landed", "reached"], cells
        assert float(cells[5]) < 0.1  # z: on the floor
    assert "…" not in flight.stderr
    # the last border has its newline: nothing is glued to it (a line counting the text log's warnings may follow:
    # a host that held the flight back has its stale extpos dropped, each drop a warning)
    end = flight.stderr.rpartition("┘")[2]
    assert end == "\n" or re.fullmatch(r"\n\(\d+ warning\(s\) from cflib and rpf_fly: \S+\)\n", end), repr(end)
    assert all(line.endswith("┃") or line.endswith("│") or not line.startswith(("┃", "│")) for line in table)


def test_a_ctrl_c_is_said_once_plainly(landed_cli_flight):
    """The first Ctrl-C: one line says what happens and what a second one does, the landing phase follows without
    repeating it, and the end (table, summary) says why each drone landed without the now stale hint."""
    flight = landed_cli_flight
    assert flight.returncode == 130, flight.stderr
    lines = flight.stderr.splitlines()
    events = [
        line
        for line in lines[lines.index("[phase] swarm: flying") + 1 : lines.index("[phase] swarm: done")]
        if line.startswith(("[interrupt]", "[phase]"))
    ]
    assert events == ["[interrupt] Ctrl-C: all drones land (Ctrl-C again: emergency stop)", "[phase] swarm: landing"]
    for cells in rows(final_table(flight.stderr)).values():
        assert cells[1:3] == ["landed", "landed_early"] and cells[-1] == "interrupted by Ctrl-C", cells
    assert "cf1: landed_early (interrupted by Ctrl-C)" in flight.stdout.splitlines()
    assert "Ctrl-C again" not in flight.stdout


def test_an_emergency_stop_ends_with_every_drone_stopped(stopped_cli_flight):
    flight = stopped_cli_flight
    assert flight.returncode == 130, flight.stderr
    table = final_table(flight.stderr)
    found = rows(table)
    assert set(found) == {"cf1", "cf2", "cf3"}
    for cells in found.values():
        assert cells[1:3] == ["stopped", "emergency"], cells
    assert "landing" not in "\n".join(table)
    assert "second Ctrl-C" in flight.stderr


def test_a_distributed_flight_ends_with_the_same_table_naming_each_drones_worker(tmp_path):
    """``--distributed``, piped: the coordinator's lines as plain lines, then the single process's final table
    (same title, states and outcomes) with a worker column, once, wide, ending in its newline; the outcomes on
    stdout as before."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    mission = Path(__file__).resolve().parents[1] / "runtime" / "two-dongles.yaml"
    flight = subprocess.run(
        [
            sys.executable,
            "-m",
            "rpf_fly",
            "fly",
            str(mission),
            "--dry-run",
            "--distributed",
            "--log",
            str(tmp_path / "flight.mcap"),
        ],
        capture_output=True,
        text=True,
        timeout=180,
        cwd=tmp_path,
        env=dict(os.environ, PYTHONUNBUFFERED="1"),
    )
    assert flight.returncode == 0, flight.stderr
    table = final_table(flight.stderr)
    assert table[0].strip() == "two-dongles: done"
    assert table[2].split() == [
        "┃",
        "drone",
        "┃",
        "worker",
        "┃",
        "state",
        "┃",
        "outcome",
        "┃",
        "x",
        "┃",
        "y",
        "┃",
        "z",
        "┃",
        "to",
        "goal",
        "[m]",
        "┃",
        "battery",
        "[V]",
        "┃",
        "link",
        "[%]",
        "┃",
    ]
    found = rows(table)
    assert {name: cells[1:4] for name, cells in found.items()} == {
        "cf1": ["dongle-0", "landed", "reached"],
        "cf2": ["dongle-0", "landed", "reached"],
        "cf3": ["dongle-1", "landed", "reached"],
        "cf4": ["dongle-1", "landed", "reached"],
    }
    for cells in found.values():
        assert float(cells[6]) < 0.1 and float(cells[7]) <= 0.1 and 3.0 < float(cells[8]) < 4.3, cells  # z, goal
    assert flight.stderr.count("two-dongles: done") == 1  # the table once
    assert "[phase] swarm: flying" in flight.stderr.splitlines()
    assert "…" not in flight.stderr and flight.stderr.endswith("┘\n")
    assert flight.stdout.splitlines()[:4] == ["cf1: reached", "cf2: reached", "cf3: reached", "cf4: reached"]
