"""``rpf-fly review``: summary, metrics, plots and CSV of a flight log (docs/log-format.md)."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from rpf_fly.cli import app
from rpf_fly.cli.errors import fail, read_log_or_fail


@app.command()
def review(
    log: Path = typer.Argument(..., help="Flight log (.mcap) written by `rpf-fly fly --log` or `rpf-fly sim --log`."),
    json_output: bool = typer.Option(
        False,
        "--json",
        help="Print the review as JSON: the metrics JSON (docs/metrics.md) and everything the summary says.",
    ),
    plot: Path | None = typer.Option(
        None,
        "--plot",
        help="Write the review figure (tracks, altitude, tracking, separation, battery, events) to a PNG.",
    ),
    csv_dir: Path | None = typer.Option(None, "--csv", help="Write one CSV per topic into this directory."),
    salvage_to: Path | None = typer.Option(
        None,
        "--salvage",
        help="Also write a finished copy of the log here: every complete chunk of a log cut short "
        "by a kill, with the summary and footer indexed readers need.",
    ),
) -> None:
    """Review a flight log: message rates and gaps per topic, events, the mission's metrics; plots and CSV."""
    from rpf_fly.log.reader import LogError, salvage
    from rpf_fly.log.review import export_csv
    from rpf_fly.log.review import review as compute_review

    data = read_log_or_fail(log)
    if salvage_to is not None:
        try:
            saved = salvage(log, salvage_to)
        except (LogError, ValueError) as err:
            raise fail(f"{salvage_to}: cannot salvage {log}: {err}") from err
        except OSError as err:
            raise fail(f"{salvage_to}: cannot write: {err.strerror or err}") from err
        typer.echo(f"{salvage_to}: {saved.messages} messages on {saved.channels} channels, finished", err=True)
    result = compute_review(data)
    if json_output and result.metrics is None:
        cut = " (the log is truncated)" if data.truncated else ""
        raise fail(f"{log}: cannot compute metrics: {result.metrics_error}{cut}")
    if data.truncated:
        typer.echo(
            f"{log}: warning: the log ends before its footer (writer killed?); reviewing the "
            f"{data.message_count} messages of its complete chunks"
            + ("" if salvage_to is not None else "; `--salvage FIXED.mcap` writes a finished copy"),
            err=True,
        )
    if plot is not None:
        from rpf_fly.log.review_plot import plot_review

        try:
            plot_review(data, result, plot)
        except OSError as err:
            raise fail(f"{plot}: cannot write the plot: {err.strerror or err}") from err
    if csv_dir is not None:
        try:
            export_csv(data, csv_dir)
        except OSError as err:
            raise fail(f"{csv_dir}: cannot write CSV: {err.strerror or err}") from err
    if json_output:
        assert result.metrics is not None
        typer.echo(json.dumps(result.to_json_dict()))
        return
    _print_summary(result, plot, csv_dir)


def _fmt(value, unit: str = "", digits: int = 2) -> str:
    return "-" if value is None else f"{value:.{digits}f}{unit}"


def _print_tracking_expected(console, result) -> None:
    """What tracking error to expect while cruising, each drone's against it, and a line for each drone outside."""
    from rich.markup import escape

    from rpf_fly.log.review import CRAZYFLIE_LAG_S

    if not result.tracking_expected:
        return
    lag_s, who = result.tracking_lag
    aside = (
        f" (a Crazyflie with the firmware's default gains: about {CRAZYFLIE_LAG_S:g} s)"
        if lag_s != CRAZYFLIE_LAG_S
        else ""
    )
    judged = {n: e for n, e in result.tracking_expected.items() if e.expected_m is not None}
    alike = {(f"{e.expected_m:.2f}", f"{e.speed_m_s:.2f}") for e in judged.values()}
    if not judged:
        said = "no drone cruised long enough to judge"
    elif len(alike) == 1:
        ((expected, speed),) = alike
        said = (
            f"{expected} m at the flown {speed} m/s; measured (median) "
            + ", ".join(f"{n} {e.measured_m:.2f}" for n, e in judged.items())
            + " m"
        )
    else:
        said = "measured (median) " + ", ".join(
            f"{n} {e.measured_m:.2f} m (expected {e.expected_m:.2f} at {e.speed_m_s:.2f} m/s)"
            for n, e in judged.items()
        )
    console.print(
        escape(
            f"expected while cruising: {who} trail a moving setpoint by about {lag_s:g} s x its speed{aside}: {said}"
        )
    )
    for name, e in judged.items():
        if e.outside:
            low, high = e.band_m
            console.print(
                f"  [yellow]{escape(name)}: {e.measured_m:.2f} m from its setpoint while cruising at "
                f"{e.speed_m_s:.2f} m/s, outside the expected {low:.2f}-{high:.2f} m"
                + escape(
                    " (pushed: a gust, a contact; late poses; other gains than expected)"
                    if e.measured_m > high
                    else " (other gains than expected, or a setpoint that waits for its drone)"
                )
                + "[/yellow]"
            )


def _print_summary(result, plot: Path | None, csv_dir: Path | None) -> None:
    from rich.markup import escape
    from rich.table import Table

    from rpf_fly.cli.output import console as make_console

    console = make_console()
    head = f"{result.mission or result.path.name}: planner {result.planner or '?'}, seed {result.seed}"
    source = f", {result.source}" if result.source else ""
    console.print(
        f"[bold]{escape(head)}[/bold]  duration {result.duration_s:.1f} s, {len(result.drones)} drones"
        f"{source}" + ("  [yellow](truncated)[/yellow]" if result.truncated else "")
    )
    for cut in result.interruptions:
        at = f" at {cut.t_s:.1f} s" if cut.t_s is not None else ""
        console.print(f"[bold red]interrupted[/bold red] ({cut.how}){at}: {escape(cut.message)}")

    topics = Table(title="topics")
    for column in ("topic", "schema", "messages", "rate [Hz]", "gaps", "longest gap [s]", "missing"):
        topics.add_column(
            escape(column), justify="left" if column in ("topic", "schema") else "right", no_wrap=column == "topic"
        )
    for t in result.topics:
        topics.add_row(
            t.topic,
            t.schema,
            str(t.count),
            _fmt(t.rate_hz, "", 1),
            str(len(t.gaps)),
            _fmt(t.longest_gap_s, "", 2),
            str(t.missing),
        )
    console.print(topics)
    levels = ", ".join(f"{name} {count}" for name, count in result.events_by_level.items() if count)
    console.print(f"events: {levels or 'none'}")
    for event in result.events:
        if event.level >= 3:
            who = f"{event.name}: " if event.name and event.name not in ("flight", "sim") else ""
            console.print(
                f"  [{'red' if event.level >= 4 else 'yellow'}]{event.t_s:8.2f} s  {escape(who + event.message)}[/]"
            )
    if result.tracking:
        overall = result.tracking.get("all", (None, None))
        per = ", ".join(
            f"{name} {_fmt(rms, '', 3)}/{_fmt(peak, '', 3)}"
            for name, (rms, peak) in result.tracking.items()
            if name != "all"
        )
        console.print(
            f"setpoint tracking error |setpoint - pose|: RMS {_fmt(overall[0], ' m', 3)}, max "
            f"{_fmt(overall[1], ' m', 3)} (RMS/max per drone: {per})"
        )
        _print_tracking_expected(console, result)
    if result.battery:
        console.print(
            "battery: "
            + ", ".join(f"{name} {a:.2f} -> {c:.2f} V (lowest {b:.2f})" for name, (a, b, c) in result.battery.items())
        )

    for dongle in result.radio:
        console.print(escape(dongle.line()))

    m = result.metrics
    if m is None:
        console.print(f"[yellow]metrics: not available: {result.metrics_error}[/yellow]")
    else:
        drones = Table(title="metrics")
        for column in ("drone", "outcome", "reached", "collided", "travel [m]", "time to goal [s]", "smoothness"):
            drones.add_column(escape(column), justify="left" if column in ("drone", "outcome") else "right")
        for row in m.per_drone:
            drones.add_row(
                row.name,
                result.outcomes.get(row.name) or "-",
                "yes" if row.reached else "no",
                "yes" if row.collided else "no",
                f"{row.travel_distance_m:.2f}",
                _fmt(row.time_to_goal_s, "", 1),
                f"{row.smoothness:.4f}",
            )
        console.print(drones)
        verdict = "[green]success[/green]" if m.success else "[red]failure[/red]"
        console.print(
            f"{verdict}: {m.reached}/{m.drones} reached, collisions drone-drone {m.collisions_drone_drone}, "
            f"drone-obstacle {m.collisions_drone_obstacle}"
        )
        console.print(
            f"travel {_fmt(m.travel_distance_m, ' m')}, smoothness {_fmt(m.smoothness, '', 4)}, makespan "
            f"{_fmt(m.makespan_s, ' s', 1)}, min separation {_fmt(m.min_separation_m, ' m', 3)}, "
            f"min obstacle clearance {_fmt(m.min_obstacle_clearance_m, ' m', 3)}"
        )
    if plot is not None:
        console.print(f"plot: {plot}")
    if csv_dir is not None:
        console.print(f"csv: {csv_dir}")
