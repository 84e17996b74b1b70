"""``rpf-fly sim``: run a mission on the kinematic simulator and print its metrics (table or JSON), plot it."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from rpf_fly.cli import app
from rpf_fly.cli.errors import fail
from rpf_fly.mission.model import PLANNER_KINDS, POLICY_KINDS

POLICY_HELP = f"ONNX policy for {', '.join(POLICY_KINDS)}."


@app.command()
def sim(
    mission: Path = typer.Argument(..., help="Mission YAML file."),
    planner: str | None = typer.Option(
        None, "--planner", help=f"Override the mission's planner: {', '.join(PLANNER_KINDS)}."
    ),
    policy: Path | None = typer.Option(None, "--policy", help=POLICY_HELP),
    no_wall_following: bool = typer.Option(
        False, "--no-wall-following", help="Vanilla APF direction: no wall-following, no soft rule."
    ),
    guidance: str | None = typer.Option(
        None, "--guidance", help="Override planner.guidance: none, or path (global guidance around the obstacles)."
    ),
    margin: float | None = typer.Option(None, "--margin", help="Override planner.margin (m)."),
    seed: int = typer.Option(0, "--seed", help="Seed of the mission's start jitter (sim section)."),
    json_output: bool = typer.Option(False, "--json", help="Print the metrics JSON (docs/metrics.md) only."),
    plot: Path | None = typer.Option(
        None, "--plot", help="Write the XY tracks to a PNG: a colour per drone, the planner mode as the line style."
    ),
    log: Path | None = typer.Option(None, "--log", help="Write the run as an MCAP flight log (rpf-fly review)."),
) -> None:
    """Simulate MISSION with its planner (no radio, no mocap) and report success, collisions and path quality.

    Exit 0 when at least one drone reached its goal, 1 when none did (the table or JSON still printed), 2 for an
    invalid mission or option."""
    from rpf_fly.mission import MissionError, load_mission, with_planner
    from rpf_fly.planning.factory import UnsupportedPlanner, make_planner
    from rpf_fly.planning.onnx_policy import PolicyError
    from rpf_fly.sim import SimParams, compute_metrics, rollout, scenario_from_mission

    try:
        loaded = load_mission(mission)
        overrides: dict[str, object] = {"wall_following": False} if no_wall_following else {}
        if guidance is not None:
            overrides["guidance"] = guidance
        if margin is not None:
            overrides["margin"] = margin
        if planner is not None or policy is not None or overrides:
            loaded = with_planner(loaded, planner or loaded.planner.kind, policy, **overrides)
    except MissionError as err:
        raise fail(str(err)) from err
    scenario = scenario_from_mission(loaded, seed)
    try:
        chosen = make_planner(loaded.planner, scenario.obstacles, (scenario.arena_x, scenario.arena_y), scenario.goals)
    except (UnsupportedPlanner, PolicyError) as err:
        raise fail(f"{mission}:0: planner.policy: {err}") from err
    params = SimParams(loaded.flight.speed, loaded.flight.dt, loaded.flight.goal_tolerance, loaded.sim.time_limit_s)
    result = rollout(scenario, chosen, params)
    metrics = compute_metrics(
        result.positions,
        scenario.goals,
        params.dt,
        params.goal_tolerance,
        loaded.planner.safety_radius,
        scenario.obstacles,
        scenario.names,
        mission=loaded.name,
        planner=loaded.planner.kind,
        seed=seed,
        margin=loaded.planner.margin_m,
    )
    if log is not None:
        from rpf_fly.log.sim_log import write_sim_log

        try:
            write_sim_log(log, loaded, scenario, result, seed)
        except OSError as err:
            raise fail(f"{log}: cannot write the log: {err.strerror or err}") from err
    if plot is not None:
        from rpf_fly.sim.plot import plot_rollout

        plot_rollout(result, plot, metrics)
    if json_output:
        typer.echo(json.dumps(metrics.to_json_dict()))
    else:
        _print_table(metrics, result, plot, loaded.planner.guidance_mode)
    if metrics.reached == 0:
        raise typer.Exit(1)  # no drone reached: not a run to build on (docs: README, *Commands*)


def _print_table(metrics, result, plot: Path | None, guidance: str = "none") -> None:
    from rich.markup import escape
    from rich.table import Table

    from rpf_fly.cli.output import console as make_console

    console = make_console()
    table = Table(title=f"{metrics.mission}: {metrics.planner}, seed {metrics.seed}")
    for column in ("drone", "outcome", "collided", "travel [m]", "time to goal [s]", "smoothness"):
        table.add_column(escape(column), justify="left" if column in ("drone", "outcome") else "right")
    for row, outcome in zip(metrics.per_drone, result.outcomes):
        table.add_row(
            row.name,
            outcome.value,
            "yes" if row.collided else "no",
            f"{row.travel_distance_m:.2f}",
            "-" if row.time_to_goal_s is None else f"{row.time_to_goal_s:.1f}",
            f"{row.smoothness:.4f}",
        )
    console.print(table)

    def fmt(value, unit="", digits=2):
        return "-" if value is None else f"{value:.{digits}f}{unit}"

    verdict = "[green]success[/green]" if metrics.success else "[red]failure[/red]"
    console.print(
        f"{verdict}: {metrics.reached}/{metrics.drones} reached, collisions drone-drone "
        f"{metrics.collisions_drone_drone}, drone-obstacle {metrics.collisions_drone_obstacle}"
    )
    console.print(
        f"travel {fmt(metrics.travel_distance_m, ' m')}, smoothness {fmt(metrics.smoothness, '', 4)}, "
        f"makespan {fmt(metrics.makespan_s, ' s', 1)}, min separation {fmt(metrics.min_separation_m, ' m', 3)}, "
        f"min obstacle clearance {fmt(metrics.min_obstacle_clearance_m, ' m', 3)}"
    )
    if metrics.margin_m > 0:
        breaches = metrics.margin_breaches_drone_drone + metrics.margin_breaches_drone_obstacle
        console.print(
            f"guidance {guidance}, margin {metrics.margin_m:g} m: "
            + (
                "held"
                if metrics.margin_held
                else f"[yellow]broken {breaches} times[/yellow] "
                f"(pairs within 2r + margin {metrics.margin_breaches_drone_drone}, "
                f"obstacles within r + margin {metrics.margin_breaches_drone_obstacle})"
            )
        )
    else:
        console.print(f"guidance {guidance}, margin 0")
    clamped = [
        f"{name} ({count} steps)" for name, count in zip(metrics_names(metrics), result.geofence_clamps) if count
    ]
    if clamped:
        console.print(f"[yellow]geofence: held at the arena boundary: {', '.join(clamped)}[/yellow]")
    if plot is not None:
        console.print(f"plot: {plot}")


def metrics_names(metrics) -> list[str]:
    return [row.name for row in metrics.per_drone]
