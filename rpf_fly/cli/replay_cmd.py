"""``rpf-fly replay``: feed a flight log's poses back through the planners and say where the decisions differ.

With the flight's own planner and policy (the default, from the log's mission metadata) the replay gives the logged
directions and modes back; with ``--planner`` or ``--policy`` it shows what that planner would have decided on
the same poses, open loop. docs/replay.md; the work is :mod:`rpf_fly.flight.replay`.
"""

from __future__ import annotations

import json
from pathlib import Path

import typer

from rpf_fly.cli import app
from rpf_fly.cli.errors import fail, read_log_or_fail
from rpf_fly.mission.model import PLANNER_KINDS


@app.command()
def replay(
    log: Path = typer.Argument(..., help="Flight log (.mcap) written by `rpf-fly fly [--dry-run] --log`."),
    planner: str | None = typer.Option(
        None,
        "--planner",
        help=f"Replay with this planner kind: "
        f"{', '.join(PLANNER_KINDS)} (default: the one flown, from the log's "
        f"mission).",
    ),
    policy: Path | None = typer.Option(
        None,
        "--policy",
        help="ONNX policy for a learned planner (default: the mission's, checked against the flown SHA-256).",
    ),
    json_output: bool = typer.Option(False, "--json", help="Print the replay JSON (docs/replay.md) only."),
    plot: Path | None = typer.Option(None, "--plot", help="Write logged vs replayed headings per drone to a PNG."),
    tolerance: float | None = typer.Option(
        None,
        "--tolerance",
        min=0.0,
        help="Direction difference (unit-vector distance) above which a tick diverges "
        "(default 1e-6; 1e-5 for ONNX policies, their parity tolerance).",
    ),
) -> None:
    """Replay LOG's mocap poses through the planners, each drone on the view it had; report divergences."""
    from rpf_fly.flight.replay import ReplayError, replay_log, replay_setup

    data = read_log_or_fail(log)
    try:
        setup = replay_setup(data, planner, policy, tolerance)
        result = replay_log(
            data,
            setup.mission,
            setup.factory,
            tolerance=setup.tolerance,
            planner=setup.mission.planner.kind,
            policy=setup.mission.planner.policy,
            same_as_flown=setup.same_as_flown,
        )
    except ReplayError as err:
        raise fail(str(err)) from err
    result.warnings[:0] = setup.warnings
    if data.truncated:
        result.warnings.insert(
            0,
            f"the log ends before its footer ({data.stop_reason or 'writer killed?'}); "
            f"replaying the {result.ticks} planning ticks of its complete chunks",
        )
    for warning in result.warnings:
        typer.echo(f"{log}: warning: {warning}", err=True)
    for drone in result.drones.values():
        if drone.note:
            typer.echo(f"{log}: {drone.note}", err=True)
    if plot is not None:
        from rpf_fly.flight.replay_plot import plot_replay

        try:
            replayed_policy = f" ({result.policy.name})" if result.policy is not None else ""
            plot_replay(
                result,
                plot,
                title=f"{log.name}: {result.flown_planner or '?'} flown, {result.planner}{replayed_policy} replayed",
            )
        except OSError as err:
            raise fail(f"{plot}: cannot write the plot: {err.strerror or err}") from err
    if json_output:
        typer.echo(json.dumps(result.to_json()))
        return
    _print(result, log, plot)


def _print(result, log: Path, plot: Path | None) -> None:
    from rich.markup import escape
    from rich.table import Table

    from rpf_fly.cli.output import console as make_console

    console = make_console(highlight=False)  # piped: plain and wide, not wrapped at 80 columns
    flown = result.flown_planner or "?"
    what = "the flight's own planner" if result.same_as_flown else f"open loop against the flown {flown}"
    policy = f" ({result.policy})" if result.policy is not None else ""
    console.print(
        f"[bold]{escape(log.name)}[/bold]: replayed {result.planner}{escape(policy)}, {what}; "
        f"{result.ticks} planning ticks, {result.seconds_per_tick * 1e3:.2f} ms a tick"
    )
    # one line above the table, not its title: rich wraps a title to the table's width
    console.print(
        f"decisions: max diff = largest |d_replay - d_log| (unit vectors), diverging above "
        f"{result.tolerance:g}; max deg = largest angle; mode diffs = ticks whose mode differs"
    )
    table = Table()
    for column in ("drone", "ticks", "first div.", "max diff", "max deg", "mode diffs", "restarts"):
        table.add_column(column, justify="left" if column == "drone" else "right")
    for name, d in result.drones.items():
        first = d.first_divergence_tick
        table.add_row(
            name,
            str(len(d.ticks)),
            "-" if first is None else f"tick {first}",
            f"{d.max_direction_diff:.3g}",
            f"{d.max_angle_diff_rad * 57.29577951308232:.3g}",
            str(d.mode_changes),
            str(d.restarts),
        )
    console.print(table)
    diverged = [n for n, d in result.drones.items() if d.first_divergence_tick is not None]
    if not diverged:
        console.print(
            "[green]every decision reproduced[/green]"
            if result.same_as_flown
            else "[yellow]no decision differs from the flown planner's[/yellow]"
        )
    else:
        console.print(f"[{'red' if result.same_as_flown else 'yellow'}]diverged: {', '.join(diverged)}[/]")
    if plot is not None:
        console.print(f"plot: {escape(str(plot))}")
