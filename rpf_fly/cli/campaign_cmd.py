"""``rpf-fly campaign``: the fault campaign on a lab's own mission before its first flight (rpf_fly/campaign,
docs/fault-campaign.md). Exit 0 when every run passes, 1 when any fails, 2 for bad input."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from rpf_fly.cli import app
from rpf_fly.cli.errors import fail


@app.command()
def campaign(
    mission: Path = typer.Argument(..., help="Mission YAML file to fly the faults on (dry runs: nothing real flies)."),
    kinds: str | None = typer.Option(
        None, "--kinds", help="Comma-separated fault kinds (docs/faults.md; default: every kind)."
    ),
    random_runs: int = typer.Option(
        0,
        "--random",
        metavar="N",
        help="N runs of random compound faults (drones, "
        "times, parameters and the simulated world drawn from --seed) instead of each "
        "kind once.",
    ),
    seed: int = typer.Option(0, "--seed", help="The random runs' seed (the same seed flies the same draws)."),
    faults_per_run: int = typer.Option(
        2, "--faults-per-run", metavar="K", help="Faults of different kinds in each random run."
    ),
    out: Path | None = typer.Option(None, "--out", help="Write the report (markdown table) to this file."),
    keep: Path | None = typer.Option(
        None,
        "--keep",
        help="Fly in this folder and keep each run's schedule, mission copy and logs (to review a failed run).",
    ),
    json_out: bool = typer.Option(False, "--json", help="Print the verdicts as one JSON document."),
    dynamics: str | None = typer.Option(
        None,
        "--dynamics",
        metavar="first-order|firmware",
        help="How the "
        "simulated drones fly in every run: first-order (the emulator's lag) or "
        "firmware (the firmware's PID cascade; docs/dynamics.md). Default: the "
        "mission's dry_run.dynamics.",
    ),
) -> None:
    """Inject each fault kind into dry runs of MISSION and judge every run on the simulated truth."""
    from rpf_fly.campaign import CampaignError, mission_campaign
    from rpf_fly.campaign.judge import Verdict
    from rpf_fly.campaign.report import progress_line, summary

    def said(verdict: Verdict) -> None:  # each run's line as it ends: a campaign takes minutes
        typer.echo(progress_line(verdict), err=True)

    try:
        result = mission_campaign(
            mission,
            kinds.split(",") if kinds is not None else None,
            random_runs,
            seed,
            faults_per_run,
            out,
            keep,
            on_verdict=said,
            dynamics=dynamics,
        )
    except CampaignError as err:
        raise fail(str(err)) from err
    if json_out:
        typer.echo(json.dumps(result.json(), indent=1))
    else:
        typer.echo(result.markdown())
        typer.echo(summary(result.verdicts))
    if not result.passed:
        raise typer.Exit(1)
